"""``dualarm robot init`` and ``dualarm robot poses``: a robot directory written from any URDF, and the hands' poses at its home poses.

:func:`init_robot` reads a URDF and writes a robot directory: a copy of the URDF whose mesh paths
point into the directory's own ``meshes/`` folder (so the directory is self-contained: it works
when moved, when shipped in the wheel, and when a recording attaches the URDF), the meshes it uses,
and ``robot.toml`` (robots/README.md documents every key). Everything robot.toml needs is derived
from the URDF, and every choice is returned as a line of :attr:`RobotInit.notes` to be printed:

- the arm chains: from the tips given, else proposed from the tree. An arm's tip is the link below
  the last revolute joint of a branch, followed down through fixed joints while the branch does not
  split (so a Panda's tip is ``panda_hand``, above its prismatic fingers). Two tips whose branches
  below their common root each hold at least :data:`MIN_ARM_DOF` revolute joints make two arms (the
  pair with the most); ``left`` is the arm whose first joint lies further along +y of the root link
  (x forward, y left). Otherwise the URDF is one arm: the tip with the most revolute joints below
  the root, driving hand ``left`` (chain ``left_arm``), the hand single-arm tasks use.
- the torso: ``--torso``, else the arms' common root (one arm: the link its first movable joint
  hangs from). Each arm's chain starts at ``--left-base``/``--right-base``, else at the torso.
- the waist: the movable joints from the root link to the torso (a chain ``waist`` when there are any).
- locked joints: movable joints between the torso and an arm's base (a clavicle) belong to no chain
  and are held at :data:`lock_value` (0 clipped into the limits) by every home pose.
- S-R-S or not, per arm (:func:`dualarm.model.srs.srs_geometry`'s verdict, with the miss distance).
- limits: velocity from the URDF (:data:`DEFAULT_VELOCITY_RAD_S` where it gives none), acceleration
  and jerk from the caller or :data:`DEFAULT_ACCELERATION_RAD_S2` / :data:`DEFAULT_JERK_RAD_S3`,
  written with the comment ``# assumed``.
- home poses ``zero`` and ``ready`` (:func:`ready_pose`).
- collision pairs in contact at every sampled configuration. dualarm already skips the pairs that
  touch by construction (:func:`dualarm.execute.world.disable_touching_pairs`, a Panda's hand and
  link 7 among them) in the planners and the execution; robot.toml gets no key for them. A pair in
  contact everywhere that this rule does not skip is refused (:class:`RobotModelError` naming it).
"""

from __future__ import annotations

import os
import re
import shutil
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from itertools import combinations, product
from pathlib import Path
from types import MappingProxyType

import numpy as np
from scipy.spatial.transform import Rotation

from dualarm.errors import NotSRSError, OutputError, RobotModelError, excerpt
from dualarm.files import DIRECTORY, REGULAR_FILE, kind, listing
from dualarm.model.robot import Chain, Robot, load_robot
from dualarm.model.urdf import JointSpec, UrdfModel, load_urdf

#: Fewest revolute joints a branch needs to be proposed as an arm (6 place a hand anywhere in its workspace).
MIN_ARM_DOF = 6
#: Velocity written for a chain joint whose URDF gives none [rad/s] (marked ``# assumed``).
DEFAULT_VELOCITY_RAD_S = 1.0
#: Acceleration written for every chain joint when none is given [rad/s^2] (``# assumed``; the humanoid's are 4-12).
DEFAULT_ACCELERATION_RAD_S2 = 5.0
#: Jerk written for every chain joint when none is given [rad/s^3] (``# assumed``; the humanoid's are 40-150).
DEFAULT_JERK_RAD_S3 = 50.0
#: Configurations sampled (fixed seed) to find pairs in contact everywhere and the ``ready`` pose.
SAMPLES = 400
#: Seed of every sample.
SEED = 0
#: ``ready`` keeps this fraction of each joint's range from either limit.
READY_LIMIT_MARGIN = 0.05
#: ``ready`` puts each hand at least this fraction of its arm's length in front of the arm's first joint (+x of the root link).
READY_FORWARD = 0.25
#: ``ready`` keeps each hand at least this high above the root link's origin (a fixed base on the floor) [m].
READY_MIN_HEIGHT_M = 0.1
#: ``ready`` keeps each hand's distance from its arm's first joint within these fractions of the arm's length: elbow bent, room to move every way.
READY_REACH = (0.4, 0.8)
#: ``ready`` keeps each hand at most this fraction of its arm's length further out sideways (away from the root's x-z plane) than its arm's first joint.
READY_OUTWARD = 0.25
#: ``ready`` prefers the hand nearest this point, in arm lengths from the arm's first joint (forward, sideways, up): in front and a little below, as a person holds a tool.
READY_TARGET = (0.55, 0.0, -0.25)

REVOLUTE = ("revolute", "continuous")
MOVABLE = ("revolute", "continuous", "prismatic")


@dataclass(frozen=True)
class ArmPlan:
    """One arm chain as ``robot init`` chose it.

    Attributes:
        chain: chain name (``left_arm`` / ``right_arm``).
        hand: the hand it drives (``left`` / ``right``).
        base: base link (poses of the chain are in its frame).
        tip: tip link (the hand frame).
        srs: None when the arm is S-R-S, else why not (srs_geometry's message, with the miss [m]).
    """

    chain: str
    hand: str
    base: str
    tip: str
    srs: str | None


@dataclass(frozen=True)
class RobotInit:
    """What ``robot init`` wrote.

    Attributes:
        directory: the robot directory.
        robot: the robot as :func:`dualarm.model.robot.load_robot` reads the directory back.
        arms: the arm chains.
        waist: (base, tip) of the waist chain, or None.
        locked: joints in no chain held by the home poses [rad], by name.
        ready: the ``ready`` home pose [rad], by joint.
        touching_pairs: link pairs dualarm skips as touching by construction (sorted names).
        notes: the lines ``robot init`` prints: every choice and assumption.
    """

    directory: Path
    robot: Robot
    arms: tuple[ArmPlan, ...]
    waist: tuple[str, str] | None
    locked: Mapping[str, float]
    ready: Mapping[str, float]
    touching_pairs: frozenset[tuple[str, str]]
    notes: tuple[str, ...]


# ----------------------------------------------------------------------------- the URDF's tree


def _by_child(urdf: UrdfModel) -> dict[str, JointSpec]:
    return {j.child: j for j in urdf.joints}


def _children(urdf: UrdfModel) -> dict[str, list[JointSpec]]:
    out: dict[str, list[JointSpec]] = {link: [] for link in urdf.links}
    for j in urdf.joints:
        out.setdefault(j.parent, []).append(j)
    return out


def _ancestors(urdf: UrdfModel, link: str) -> list[str]:
    """``link`` and every link above it, up to the root."""
    by_child = _by_child(urdf)
    out = [link]
    while out[-1] in by_child:
        out.append(by_child[out[-1]].parent)
    return out


def _link(urdf: UrdfModel, link: str, option: str) -> str:
    if link not in urdf.links:
        raise RobotModelError(f"{option} '{excerpt(link, 40)}': no such link in {excerpt(urdf.path)} (links: {listing(urdf.links)})")
    return link


def _revolute_count(joints: Sequence[JointSpec]) -> int:
    return sum(j.type in REVOLUTE for j in joints)


def _zero_position(urdf: UrdfModel, link: str) -> np.ndarray:
    """Origin of ``link`` in the root link's frame at the zero configuration [m]."""
    from dualarm.model.kinematics import origin_matrix

    T = np.eye(4)
    for j in urdf.chain(urdf.root, link):
        T = T @ origin_matrix(j)
    return T[:3, 3]


def arm_tips(urdf: UrdfModel) -> list[str]:
    """Candidate arm tips: per leaf link, the link below the last revolute joint above it, followed down through fixed joints while the branch does not split."""
    children = _children(urdf)
    tips: list[str] = []
    for leaf in (link for link in urdf.links if not children.get(link)):
        path = urdf.chain(urdf.root, leaf)
        revolute = [i for i, j in enumerate(path) if j.type in REVOLUTE]
        if not revolute:
            continue
        tip = path[revolute[-1]].child
        while len(children.get(tip, [])) == 1 and children[tip][0].type == "fixed":
            tip = children[tip][0].child
        if tip not in tips:
            tips.append(tip)
    return tips


def _common_root(urdf: UrdfModel, a: str, b: str) -> str:
    above_b = set(_ancestors(urdf, b))
    return next(link for link in _ancestors(urdf, a) if link in above_b)


def propose_tips(urdf: UrdfModel) -> tuple[dict[str, str], str]:
    """The arms' tips by hand (``{"left": ..., "right": ...}`` or ``{"left": ...}``) proposed from the tree, and why (a line to print)."""
    tips = arm_tips(urdf)
    if not tips:
        raise RobotModelError(f"{excerpt(urdf.path)}: has no revolute joint, so no arm")
    pairs = []
    for a, b in combinations(tips, 2):
        root = _common_root(urdf, a, b)
        if root in (a, b):
            continue
        na, nb = _revolute_count(urdf.chain(root, a)), _revolute_count(urdf.chain(root, b))
        pairs.append((min(na, nb), na + nb, a, b, root))
    pairs = [p for p in pairs if p[0] >= MIN_ARM_DOF]
    if pairs:
        _, _, a, b, root = max(pairs, key=lambda p: (p[0], p[1]))
        ya, yb = (_zero_position(urdf, _first_movable(urdf, root, t).child)[1] for t in (a, b))
        left, right = (a, b) if ya >= yb else (b, a)
        return {"left": left, "right": right}, (
            f"arms proposed from the tree: the two branches below '{root}' with the most revolute joints; left = the one further along +y at the zero pose (give --left-tip/--right-tip to choose)"
        )
    tip = max(tips, key=lambda t: _revolute_count(urdf.chain(urdf.root, t)))
    return {"left": tip}, f"one arm proposed from the tree (no two branches with {MIN_ARM_DOF}+ revolute joints each): tip '{tip}', driving hand 'left' (give --left-tip to choose)"


def _first_movable(urdf: UrdfModel, base: str, tip: str) -> JointSpec:
    joints = [j for j in urdf.chain(base, tip) if j.type in MOVABLE]
    if not joints:
        raise RobotModelError(f"{excerpt(urdf.path)}: no movable joint between '{excerpt(base, 40)}' and '{excerpt(tip, 40)}'")
    return joints[0]


# ----------------------------------------------------------------------------- meshes


def _package_candidates(package: str, rest: str, urdf: Path) -> list[Path]:
    """Where ``package://package/rest`` may be: under each ``ROS_PACKAGE_PATH`` entry, then under the URDF's own folders."""
    out = []
    for entry in filter(None, os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep)):
        root = Path(entry)
        out += [root / package / rest] + ([root / rest] if root.name == package else [])
    for folder in urdf.resolve().parents:
        out += [folder / rest] if folder.name == package else []
        out.append(folder / package / rest)
    return out


def resolve_mesh(filename: str, urdf: Path) -> Path:
    """The file a URDF's ``<mesh filename>`` names: ``package://PKG/path`` (through ``ROS_PACKAGE_PATH``, then the URDF's own folders, each as PKG or holding PKG), ``file://``, absolute, or relative to the URDF.

    Raises:
        RobotModelError: no such file (one line naming the URDF and the path).
    """
    if filename.startswith("package://"):
        package, _, rest = filename[len("package://") :].partition("/")
        candidates = _package_candidates(package, rest, urdf)
        where = "in ROS_PACKAGE_PATH nor in the URDF's folders"
    else:
        path = Path(filename[len("file://") :] if filename.startswith("file://") else filename)
        candidates = [path if path.is_absolute() else urdf.parent / path]
        where = "" if path.is_absolute() else "relative to the URDF"
    for candidate in candidates:
        if kind(candidate) == REGULAR_FILE:
            return candidate.resolve()
    raise RobotModelError(f"{excerpt(urdf)}: mesh '{excerpt(filename)}' not found{' ' + where if where else ''}")


def _companions(mesh: Path) -> list[Path]:
    """Files a mesh needs beside it: an .obj's ``mtllib`` files and their texture maps (those that exist)."""
    out = []
    if mesh.suffix.lower() == ".obj":
        for line in mesh.read_text(errors="replace").splitlines():
            if line.startswith("mtllib "):
                mtl = mesh.parent / line.split(maxsplit=1)[1].strip()
                if mtl.is_file():
                    out.append(mtl.resolve())
                    for entry in mtl.read_text(errors="replace").splitlines():
                        parts = entry.split()
                        if parts and parts[0].startswith("map_") and (mtl.parent / parts[-1]).is_file():
                            out.append((mtl.parent / parts[-1]).resolve())
    return out


def copy_urdf(urdf: Path, directory: Path) -> Path:
    """Write ``urdf`` into ``directory`` with every mesh copied under ``directory/meshes/`` (relative layout kept) and its path rewritten relative; comments (a licence) are kept. Returns the copy.

    Raises:
        RobotModelError: a mesh that cannot be found (see :func:`resolve_mesh`).
    """
    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    root = ET.fromstring(urdf.read_text(), parser=parser)
    meshes = [(element, resolve_mesh(element.get("filename", ""), urdf)) for element in root.iter("mesh")]
    files = sorted({p for _, p in meshes} | {c for _, p in meshes for c in _companions(p)})
    if files:
        common = Path(os.path.commonpath([p.parent for p in files]))
        for source in files:
            target = directory / "meshes" / source.relative_to(common)
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(source, target)
        for element, source in meshes:
            element.set("filename", (Path("meshes") / source.relative_to(common)).as_posix())
    copy = directory / urdf.name
    copy.write_text('<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n")
    return copy


# ----------------------------------------------------------------------------- the plan


@dataclass(frozen=True)
class _Layout:
    arms: tuple[tuple[str, str, str], ...]  # (hand, base, tip)
    torso: str
    waist: tuple[str, str] | None
    locked: tuple[JointSpec, ...]
    notes: tuple[str, ...]


def _layout(urdf: UrdfModel, tips: Mapping[str, str | None], bases: Mapping[str, str | None], torso: str | None) -> _Layout:
    """Arms, torso, waist and locked joints from the options (see the module docstring)."""
    notes: list[str] = []
    given = {hand: _link(urdf, tip, f"--{hand}-tip") for hand, tip in tips.items() if tip}
    if not given:
        if any(bases.values()):
            raise RobotModelError("--left-base/--right-base need the arm's tip: give --left-tip/--right-tip too")
        given, why = propose_tips(urdf)
        notes.append(why)
    hands = list(given)
    for hand in bases:
        if bases[hand] and hand not in given:
            raise RobotModelError(f"--{hand}-base needs --{hand}-tip")
    if len(hands) == 2:
        a, b = given["left"], given["right"]
        root = _common_root(urdf, a, b)
        if root in (a, b):
            raise RobotModelError(f"tips '{excerpt(a, 40)}' and '{excerpt(b, 40)}' are not on separate branches below a common root (one is above the other)")
    else:
        root = _first_movable(urdf, urdf.root, given[hands[0]]).parent
    torso_link = _link(urdf, torso, "--torso") if torso else root
    arms = []
    for hand in hands:
        base = _link(urdf, bases[hand], f"--{hand}-base") if bases.get(hand) else torso_link  # type: ignore[arg-type]
        if torso_link not in _ancestors(urdf, base):
            raise RobotModelError(f"--{hand}-base '{excerpt(base, 40)}' is not below the torso '{excerpt(torso_link, 40)}'")
        if base not in _ancestors(urdf, given[hand]):
            raise RobotModelError(f"--{hand}-tip '{excerpt(given[hand], 40)}' is not below its base '{excerpt(base, 40)}'")
        _first_movable(urdf, base, given[hand])
        arms.append((hand, base, given[hand]))
    if len(arms) == 2:
        shared = {j.name for j in urdf.chain(arms[0][1], arms[0][2]) if j.movable} & {j.name for j in urdf.chain(arms[1][1], arms[1][2]) if j.movable}
        if shared:
            raise RobotModelError(f"the arms share joint '{excerpt(sorted(shared)[0], 40)}': give --torso at or below their common root '{excerpt(root, 40)}'")
    waist_joints = [j for j in urdf.chain(urdf.root, torso_link) if j.movable]
    waist = (waist_joints[0].parent, torso_link) if waist_joints else None
    locked = tuple(j for _, base, _ in arms for j in urdf.chain(torso_link, base) if j.movable)
    return _Layout(arms=tuple(arms), torso=torso_link, waist=waist, locked=locked, notes=tuple(notes))


def lock_value(joint: JointSpec) -> float:
    """The value a locked joint is held at [rad]: 0 clipped into its limits."""
    return float(np.clip(0.0, joint.lower, joint.upper))


def _srs_verdict(urdf: UrdfModel, name: str, base: str, tip: str) -> str | None:
    from dualarm.model.srs import srs_geometry

    try:
        srs_geometry(Chain(name=name, base=base, tip=tip, joints=urdf.chain(base, tip)))
    except NotSRSError as exc:
        return str(exc)
    return None


# ----------------------------------------------------------------------------- robot.toml


_BARE = re.compile(r"^[A-Za-z0-9_-]+$")


def _key(name: str) -> str:
    return name if _BARE.match(name) else _string(name)


def _string(text: str) -> str:
    """A TOML basic string (JSON's escapes are TOML's)."""
    import json

    return json.dumps(text, ensure_ascii=False)


def _number(value: float) -> str:
    return repr(float(value))


def robot_toml(
    name: str,
    urdf_file: str,
    source: Path,
    layout: _Layout,
    urdf: UrdfModel,
    srs: Mapping[str, str | None],
    limits: Mapping[str, Mapping[str, tuple[float, bool]]],
    homes: Mapping[str, Mapping[str, float]],
    touching: frozenset[tuple[str, str]],
) -> str:
    """The text of robot.toml: ``limits`` is kind -> joint -> (value, assumed), ``homes`` name -> joint -> value [rad]."""
    lines = [
        f"# {name}: written by `dualarm robot init` from {excerpt(source.name, 60)}; robots/README.md documents every key.",
        f"# Units: rad, rad/s, rad/s^2, rad/s^3. The robot base frame is the URDF's root link '{urdf.root}' (x forward, y left, z up).",
        "# Position and velocity limits live in the URDF (<limit>) unless [limits.velocity] replaces them; acceleration and jerk live here.",
        "",
        f"name = {_string(name)}",
        f"urdf = {_string(urdf_file)}",
        f'description = """\nMade by dualarm robot init from {excerpt(source.name, 60)} ({len([j for j in urdf.joints if j.movable])} movable joints)."""',
        "",
        "# A chain is the joints from `base` down to `tip`. `hand` names the hand a task drives with it.",
    ]
    for hand, base, tip in layout.arms:
        verdict = "S-R-S" if srs[hand] is None else f"not S-R-S: {srs[hand]}"
        lines += [f"[chains.{hand}_arm]  # {verdict}", f"base = {_string(base)}", f"tip = {_string(tip)}", f"hand = {_string(hand)}", ""]
    if layout.waist:
        lines += [f"[chains.waist]  # the joints between the root link and the torso '{layout.torso}'", f"base = {_string(layout.waist[0])}", f"tip = {_string(layout.waist[1])}", ""]
    if layout.locked:
        lines += [f"# Locked: {', '.join(f'{j.name} = {lock_value(j):g}' for j in layout.locked)} (between the torso and an arm's base, in no chain; every home pose holds them)", ""]
    for kind_, unit in (("velocity", "rad/s"), ("acceleration", "rad/s^2"), ("jerk", "rad/s^3")):
        table = limits.get(kind_, {})
        if not table:
            continue
        assumed = any(a for _, a in table.values())
        lines.append(f"[limits.{kind_}]  # [{unit}]" + ("; '# assumed': a default of dualarm robot init, not the robot's data: replace it" if assumed else ""))
        lines += [f"{_key(joint)} = {_number(value)}" + ("  # assumed" if a else "") for joint, (value, a) in table.items()]
        lines.append("")
    lines.append("# Home poses: joint values in rad; joints not named are 0.")
    for home, values in homes.items():
        comment = "  # inside the limits, clear of self-collision in PyBullet, hands in front" if home == "ready" else ""
        lines.append(f"[home.{home}]{comment}")
        lines += [f"{_key(joint)} = {_number(value)}" for joint, value in values.items()]
        lines.append("")
    if touching:
        lines.append("# Link pairs dualarm never checks for collision (touching by construction, see dualarm.execute.world.disable_touching_pairs; no key needed):")
        lines += [f"#   {a} - {b}" for a, b in sorted(touching)]
    return "\n".join(lines).rstrip() + "\n"


# ----------------------------------------------------------------------------- collision and ready


def _collision_world(robot: Robot):
    """PyBullet with self-collision and dualarm's touching pairs off; (sim, the skipped pairs)."""
    from dualarm.execute.world import disable_touching_pairs, load_pybullet_robot

    sim = load_pybullet_robot(robot.urdf.path, self_collision=True)
    return sim, disable_touching_pairs(sim)


def contact_pairs(sim, q: Mapping[str, float]) -> set[tuple[str, str]]:
    """Link pairs of ``sim``'s robot (sorted names) that penetrate at ``q`` [rad] (the pairs PyBullet checks)."""
    from dualarm.execute.world import pb

    sim.set_positions(list(q), list(q.values()))
    pb.performCollisionDetection(physicsClientId=sim.client)
    name = {i: n for n, i in sim.link_index.items()}
    pairs = set()
    for point in pb.getContactPoints(bodyA=sim.body, bodyB=sim.body, physicsClientId=sim.client):
        if point[8] < 0:
            a, b = sorted((name[point[3]], name[point[4]]))
            pairs.add((a, b))
    return pairs


def _samples(robot: Robot, joints: Sequence[str], n: int, seed: int, margin: float = 0.0) -> np.ndarray:
    lower, upper = robot.lower_upper(tuple(joints))
    lower, upper = np.where(np.isfinite(lower), lower, -np.pi), np.where(np.isfinite(upper), upper, np.pi)
    span = upper - lower
    return np.random.default_rng(seed).uniform(lower + margin * span, upper - margin * span, size=(n, len(joints)))


def held_values(robot: Robot, sim, chain_joints: Sequence[str]) -> dict[str, float]:
    """The value every movable joint in no chain is held at [rad]: :func:`lock_value`, or else (when the links below it touch another link at the zero pose, as a Panda's closed fingers do) its upper limit, lower limit or middle, the first at which they do not."""
    urdf = robot.urdf
    held = {j.name: lock_value(j) for j in urdf.joints if j.movable and j.name not in chain_joints}
    for joint in list(held):
        below = {link for link in urdf.links if urdf.joint(joint).child in _ancestors(urdf, link)}
        j = urdf.joint(joint)
        options = [held[joint]] + [v for v in (j.upper, j.lower, (j.lower + j.upper) / 2) if np.isfinite(v)]
        for value in options:
            if not any(a in below or b in below for a, b in contact_pairs(sim, {**dict.fromkeys(chain_joints, 0.0), **held, joint: value})):
                held[joint] = float(value)
                break
    return held


def always_in_contact(robot: Robot, sim, base: Mapping[str, float], samples: int = SAMPLES, seed: int = SEED) -> set[tuple[str, str]]:
    """Link pairs PyBullet finds penetrating at every one of ``samples`` random configurations of the chains' joints (the others at ``base``), after dualarm's touching pairs are skipped."""
    joints = sorted({n for c in robot.chains.values() for n in c.joint_names})
    always: set[tuple[str, str]] | None = None
    for q in _samples(robot, joints, samples, seed):
        pairs = contact_pairs(sim, {**base, **dict(zip(joints, q))})
        always = pairs if always is None else always & pairs
        if not always:
            break
    return always or set()


def ready_pose(robot: Robot, sim, base: Mapping[str, float], samples: int = SAMPLES * 10, seed: int = SEED) -> dict[str, float]:
    """A ``ready`` home pose [rad] by joint: for each arm, random configurations within the limits (:data:`READY_LIMIT_MARGIN` in from each) whose hand is :data:`READY_FORWARD` of the arm's length in front of its first joint, :data:`READY_MIN_HEIGHT_M` above the root, at :data:`READY_REACH` of the arm's length from its first joint and at most :data:`READY_OUTWARD` of it further out sideways, the hand nearest :data:`READY_TARGET` first; the first combination of the arms clear of self-collision in PyBullet.

    Raises:
        RobotModelError: no such configuration among the samples (naming the arm).
    """
    from dualarm.model.kinematics import ChainKinematics

    candidates = []
    for k, arm in enumerate(c for c in robot.chains.values() if c.hand):
        to_tip = robot.chain_between(robot.urdf.root, arm.tip)
        shoulder = _zero_position(robot.urdf, arm.joints[[j.movable for j in arm.joints].index(True)].child)
        length = float(np.linalg.norm(ChainKinematics.of(to_tip).pose(np.array([base.get(n, 0.0) for n in to_tip.joint_names]))[:3, 3] - shoulder))
        Q = np.round(_samples(robot, arm.joint_names, samples, seed + k, READY_LIMIT_MARGIN), 3)
        full = np.array([[base.get(n, 0.0) for n in to_tip.joint_names]] * len(Q))
        columns = [to_tip.joint_names.index(n) for n in arm.joint_names]
        full[:, columns] = Q
        p = ChainKinematics.of(to_tip).poses(full)[:, :3, 3]
        reach = np.linalg.norm(p - shoulder, axis=1) / length
        outward = np.abs(p[:, 1]) - abs(shoulder[1])
        ok = (
            (p[:, 0] >= shoulder[0] + READY_FORWARD * length)
            & (p[:, 0] > 0)
            & (p[:, 2] >= READY_MIN_HEIGHT_M)
            & (reach >= READY_REACH[0])
            & (reach <= READY_REACH[1])
            & (outward <= READY_OUTWARD * length)
        )
        score = np.linalg.norm(p - (shoulder + length * np.array(READY_TARGET)), axis=1) / length + 0.01 * np.linalg.norm(Q, axis=1)
        order = [i for i in np.argsort(score, kind="stable") if ok[i]]
        free = []
        for i in order:
            q = dict(zip(arm.joint_names, Q[i]))
            if not contact_pairs(sim, {**base, **q}):
                free.append(q)
            if len(free) == 8:
                break
        if not free:
            raise RobotModelError(f"robot init: no configuration of '{arm.name}' among {samples} samples has the hand in front and is clear of self-collision; write [home.ready] by hand")
        candidates.append(free)
    for combination in sorted(product(*candidates), key=lambda qs: sum(np.linalg.norm(list(q.values())) for q in qs)):
        q = {k: v for part in combination for k, v in part.items()}
        if not contact_pairs(sim, {**base, **q}):
            return {**base, **q}
    raise RobotModelError("robot init: the arms' candidate ready poses collide with each other; write [home.ready] by hand")


# ----------------------------------------------------------------------------- init


def _out_directory(out: Path) -> None:
    k = kind(out)
    if k is None:
        return
    if k != DIRECTORY:
        raise OutputError(f"--out {excerpt(out)}: is {k}, not a directory", str(out))
    if any(out.iterdir()):
        raise OutputError(f"--out {excerpt(out)}: exists and is not empty; give a new or empty directory", str(out))


def init_robot(
    urdf_path: str | Path,
    out: str | Path,
    *,
    left_tip: str | None = None,
    right_tip: str | None = None,
    left_base: str | None = None,
    right_base: str | None = None,
    torso: str | None = None,
    acceleration: float | None = None,
    jerk: float | None = None,
    name: str | None = None,
) -> RobotInit:
    """Write a robot directory ``out`` (robot.toml, the URDF and its meshes) for ``urdf_path``; see the module docstring for every choice.

    Args:
        urdf_path: the URDF.
        out: the robot directory to write (new, or empty).
        left_tip, right_tip: the arms' tip links (None: proposed from the tree).
        left_base, right_base: the arms' base links (None: the torso).
        torso: the link the arms hang from (None: their common root).
        acceleration: every chain joint's acceleration limit [rad/s^2] (None: :data:`DEFAULT_ACCELERATION_RAD_S2`, assumed).
        jerk: every chain joint's jerk limit [rad/s^3] (None: :data:`DEFAULT_JERK_RAD_S3`, assumed).
        name: the robot's name (None: the directory's name).

    Raises:
        RobotModelError: not a URDF, an unknown link, tips that are not on separate branches below a
            common root, a mesh not found, a pair in contact everywhere that dualarm does not skip.
        OutputError: ``out`` exists and is not an empty directory.
    """
    from dualarm.model.robot import LIMIT_RANGES

    source, out = Path(urdf_path), Path(out)
    for kind_, value in (("acceleration", acceleration), ("jerk", jerk)):
        low, high = LIMIT_RANGES[kind_]
        if value is not None and not low <= value <= high:
            raise RobotModelError(f"--{kind_} {value:g}: outside the allowed range [{low:g}, {high:g}]")
    _out_directory(out)
    urdf = load_urdf(source)
    layout = _layout(urdf, {"left": left_tip, "right": right_tip}, {"left": left_base, "right": right_base}, torso)
    for filename in (e.get("filename", "") for e in ET.fromstring(urdf.kinematic_xml).iter("mesh")):
        resolve_mesh(filename, source)  # refused before anything is written (collision meshes are checked by copy_urdf)
    out.mkdir(parents=True, exist_ok=True)
    try:
        return _write(source, out, urdf, layout, acceleration, jerk, name or out.resolve().name)
    except BaseException:
        shutil.rmtree(out, ignore_errors=True)
        raise


def _write(source: Path, out: Path, urdf: UrdfModel, layout: _Layout, acceleration: float | None, jerk: float | None, name: str) -> RobotInit:
    notes = list(layout.notes)
    copy = copy_urdf(source, out)
    notes.append(f"URDF copied to {copy} with its meshes under {out / 'meshes'} (the directory is self-contained: it works when moved or shipped)")
    urdf = load_urdf(copy)
    srs = {hand: _srs_verdict(urdf, f"{hand}_arm", base, tip) for hand, base, tip in layout.arms}
    for hand, base, tip in layout.arms:
        notes.append(f"chain {hand}_arm: {base} -> {tip}, hand '{hand}': " + ("S-R-S" if srs[hand] is None else f"not S-R-S ({srs[hand]})"))
    if layout.waist:
        notes.append(f"chain waist: {layout.waist[0]} -> {layout.waist[1]}")
    for j in layout.locked:
        notes.append(f"locked: {j.name} = {lock_value(j):g} rad (between the torso and an arm's base; name a base above it to move it)")
    chain_joints = [j.name for hand, base, tip in layout.arms for j in urdf.chain(base, tip) if j.movable]
    if layout.waist:
        chain_joints = [j.name for j in urdf.chain(*layout.waist) if j.movable] + chain_joints
    limits: dict[str, dict[str, tuple[float, bool]]] = {"velocity": {}, "acceleration": {}, "jerk": {}}
    for joint in chain_joints:
        if not np.isfinite(urdf.joint(joint).velocity):
            limits["velocity"][joint] = (DEFAULT_VELOCITY_RAD_S, True)
        limits["acceleration"][joint] = (acceleration, False) if acceleration is not None else (DEFAULT_ACCELERATION_RAD_S2, True)
        limits["jerk"][joint] = (jerk, False) if jerk is not None else (DEFAULT_JERK_RAD_S3, True)
    for kind_, default, unit in (("velocity", DEFAULT_VELOCITY_RAD_S, "rad/s"), ("acceleration", DEFAULT_ACCELERATION_RAD_S2, "rad/s^2"), ("jerk", DEFAULT_JERK_RAD_S3, "rad/s^3")):
        assumed = [j for j, (_, a) in limits[kind_].items() if a]
        if assumed:
            notes.append(
                f"assumed {kind_} limit {default:g} {unit} for {len(assumed)} joints ({'the URDF gives none' if kind_ == 'velocity' else f'give --{kind_}'}); marked '# assumed' in robot.toml"
            )
    homes: dict[str, Mapping[str, float]] = {"zero": {j.name: lock_value(j) for j in layout.locked}}
    (out / "robot.toml").write_text(robot_toml(name, copy.name, source, layout, urdf, srs, limits, homes, frozenset()))
    robot = load_robot(out)
    sim, touching = _collision_world(robot)
    with sim:
        held = held_values(robot, sim, chain_joints)
        for joint, value in held.items():
            if value != lock_value(urdf.joint(joint)):
                notes.append(f"held: {joint} = {value:g} (in no chain; at {lock_value(urdf.joint(joint)):g} its links touch another link)")
        everywhere = always_in_contact(robot, sim, held)
        if everywhere:
            a, b = sorted(everywhere)[0]
            raise RobotModelError(
                f"{excerpt(copy)}: links '{excerpt(a, 40)}' and '{excerpt(b, 40)}' collide at every sampled configuration and do not touch by construction (dualarm checks them): fix their collision shapes"
            )
        ready = ready_pose(robot, sim, held)
    homes["zero"] = {k: v for k, v in held.items() if v != 0.0 or k in homes["zero"]}
    homes["ready"] = {k: v for k, v in ready.items() if v != 0.0 or k in homes["zero"]}
    notes.append("home ready: " + ", ".join(f"{k} = {v:g}" for k, v in homes["ready"].items()))
    notes.append(
        f"collision: {len(touching)} link pairs touch by construction and are skipped by dualarm itself (execute.world.disable_touching_pairs); no other pair is in contact at all {SAMPLES} sampled configurations, so robot.toml needs no key for them"
    )
    (out / "robot.toml").write_text(robot_toml(name, copy.name, source, layout, urdf, srs, limits, homes, touching))
    robot = load_robot(out)
    arms = tuple(ArmPlan(chain=f"{hand}_arm", hand=hand, base=base, tip=tip, srs=srs[hand]) for hand, base, tip in layout.arms)
    return RobotInit(
        directory=out,
        robot=robot,
        arms=arms,
        waist=layout.waist,
        locked=MappingProxyType({j.name: lock_value(j) for j in layout.locked}),
        ready=MappingProxyType(dict(robot.home("ready"))),
        touching_pairs=touching,
        notes=tuple(notes),
    )


# ----------------------------------------------------------------------------- poses


@dataclass(frozen=True)
class HandPose:
    """A hand's pose at a home pose.

    Attributes:
        home: the home pose's name.
        hand: the hand.
        position_m: position in the robot base frame (the URDF's root link) [m], (3,).
        rpy_rad: extrinsic x-y-z roll, pitch, yaw in that frame [rad] (as task files), (3,).
        arm_angle_rad: the arm angle psi of MC-Inverse eq (1) (V = +z of the arm's base frame) [rad], None where the arm is not S-R-S or psi is undefined (shoulder-wrist line vertical or elbow straight).
    """

    home: str
    hand: str
    position_m: tuple[float, float, float]
    rpy_rad: tuple[float, float, float]
    arm_angle_rad: float | None


#: Below this sine between the shoulder-wrist line and the vertical (or between upper arm and forearm) the arm angle is undefined.
SINGULAR_SINE = 1e-6


def _arm_angle(srs_kinematics, chain: Chain, q: np.ndarray) -> float | None:
    """Psi of eq (1) at ``q`` [rad]; None when ``chain`` is not S-R-S, or its shoulder-wrist line is vertical or its elbow straight (psi undefined)."""
    try:
        kin = srs_kinematics.of(chain)
    except NotSRSError:
        return None
    S, E, W = (np.asarray(v).ravel() for v in kin.points(q))
    sw = (W - S) / np.linalg.norm(W - S)
    se = (E - S) / np.linalg.norm(E - S)
    if np.linalg.norm(np.cross(sw, kin.vertical)) < SINGULAR_SINE or np.linalg.norm(np.cross(se, sw)) < SINGULAR_SINE:
        return None
    return float(kin.arm_angles(q[None, :])[0])


def hand_poses(robot: Robot, home: str | None = None) -> tuple[HandPose, ...]:
    """Every hand's pose at each home pose of ``robot`` (or at ``home`` only).

    Raises:
        RobotModelError: ``home`` is not a home pose of the robot.
    """
    from dualarm.model.kinematics import hand_pose
    from dualarm.model.srs import SrsKinematics

    if home is not None:
        robot.home(home)  # refuses an unknown name, listing the homes
    names = [home] if home is not None else list(robot.homes)
    out = []
    for name in names:
        q = robot.home(name)
        for hand in robot.hands:
            T = hand_pose(robot, hand, q)
            chain = robot.hand_chain(hand)
            psi = _arm_angle(SrsKinematics, chain, np.array([q[n] for n in chain.joint_names]))
            rpy = Rotation.from_matrix(T[:3, :3]).as_euler("xyz")
            out.append(HandPose(home=name, hand=hand, position_m=tuple(float(v) for v in T[:3, 3]), rpy_rad=tuple(float(v) for v in rpy), arm_angle_rad=psi))  # type: ignore[arg-type]
    return tuple(out)
