"""``dualarm robot init`` and ``dualarm robot poses``.

A robot directory written from any URDF, and the hands' poses at its home poses.

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
- limits: velocity from the URDF (:data:`DEFAULT_VELOCITY_RAD_S` where it gives none, or 0 or less), acceleration
  and jerk from the caller or else :data:`ACCELERATION_PER_S` times the velocity limit and
  :data:`JERK_PER_S` times that, written with the comment ``# assumed`` and listed in
  ``[limits] assumed`` (so that every message a limit causes says it was assumed).
- collision meshes: each concave one decomposed into convex parts (:mod:`dualarm.describe.convex`), since
  PyBullet collides a mesh as its convex hull.
- home poses ``zero`` and ``ready`` (:func:`ready_pose`).
- the collision matrix (:mod:`dualarm.describe.collisions`): pairs joined through no chain's joint,
  pairs in contact at every sampled configuration and the pairs of ``--allow`` are written to
  robot.toml's ``[collision] disabled`` with their reasons. dualarm already skips the pairs that
  touch by construction (:func:`dualarm.sim.world.disable_unchecked_pairs`, a Panda's hand and
  link 7 among them) in the planners and the execution; robot.toml lists them as a comment.
"""

from __future__ import annotations

import contextlib
import shutil
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType

import numpy as np

from dualarm.describe.collisions import allowed_pairs, disabled_pairs
from dualarm.describe.convex import CONVEX_DIR, convex_collisions
from dualarm.describe.layout import ArmPlan, _Layout, _layout, _srs_verdict, lock_value
from dualarm.describe.meshes import check_meshes, copy_urdf
from dualarm.describe.ready import SAMPLES, _collision_world, held_values, ready_pose
from dualarm.describe.robot_toml import ACCELERATION_PER_S, DEFAULT_VELOCITY_RAD_S, JERK_PER_S, robot_toml
from dualarm.describe.tips import _first_movable, _zero_position
from dualarm.describe.up import TURNED_JOINT, TURNED_ROOT, looks_turned, turn_root, turning
from dualarm.errors import OutputError, RobotModelError, excerpt
from dualarm.files import DIRECTORY, kind
from dualarm.isolation import CrashedError, isolated
from dualarm.model.robot import Robot, load_robot
from dualarm.model.urdf import UrdfModel, load_urdf
from dualarm.sim.world import loads


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
        disabled_pairs: the pairs robot.toml's ``[collision] disabled`` lists, with their reasons.
        notes: the lines ``robot init`` prints: every choice and assumption.
    """

    directory: Path
    robot: Robot
    arms: tuple[ArmPlan, ...]
    waist: tuple[str, str] | None
    locked: Mapping[str, float]
    ready: Mapping[str, float]
    touching_pairs: frozenset[tuple[str, str]]
    disabled_pairs: Mapping[tuple[str, str], str]
    notes: tuple[str, ...]


def _limits(
    urdf: UrdfModel, joints: Sequence[str], acceleration: float | None, jerk: float | None
) -> dict[str, dict[str, tuple[float, bool]]]:
    """Kind -> joint -> (limit, assumed) for ``joints``: given, from the URDF, or scaled from the velocity."""
    from dualarm.model.robot import LIMIT_RANGES

    limits: dict[str, dict[str, tuple[float, bool]]] = {"velocity": {}, "acceleration": {}, "jerk": {}}
    for joint in joints:
        v = urdf.joint(joint).velocity
        if not np.isfinite(v) or v <= 0:  # none, or 0 or less: no limit a motion could keep (was clipped to 1e-6)
            v = DEFAULT_VELOCITY_RAD_S
            limits["velocity"][joint] = (v, True)
        v = float(np.clip(v, *LIMIT_RANGES["velocity"]))
        a = (
            (acceleration, False)
            if acceleration is not None
            else (_scaled("acceleration", ACCELERATION_PER_S * v), True)
        )
        limits["acceleration"][joint] = a
        limits["jerk"][joint] = (jerk, False) if jerk is not None else (_scaled("jerk", JERK_PER_S * a[0]), True)
    return limits


def _scaled(kind: str, value: float) -> float:
    """A scaled limit within robot.toml's range, to 3 decimals."""
    from dualarm.model.robot import LIMIT_RANGES

    return round(float(np.clip(value, *LIMIT_RANGES[kind])), 3)


def _turning(source: Path, urdf: UrdfModel, layout: _Layout, up: str | None) -> np.ndarray | None:
    """The rotation turning the root z-up for ``up``, or None (the root already is)."""
    shoulders = [_zero_position(urdf, _first_movable(urdf, base, tip).child) for _, base, tip in layout.arms]
    left, right = (shoulders[0], shoulders[1]) if len(shoulders) == 2 else (None, None)
    if up is None:
        why = looks_turned(left, right) if left is not None and right is not None else None
        if why:
            raise RobotModelError(
                f"{excerpt(source)}: its root link '{excerpt(urdf.root, 40)}' does not look z-up (x forward, y left): "
                f"{why}"
            )
        return None
    return None if up == "z" else turning(up, left, right)


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
    allow: Sequence[tuple[str, str]] = (),
    up: str | None = None,
    progress: Callable[[str], None] | None = None,
) -> RobotInit:
    """Write a robot directory ``out`` (robot.toml, the URDF and its meshes) for ``urdf_path``.

    See the module docstring for every choice.

    Args:
        urdf_path: the URDF.
        out: the robot directory to write (new, or empty).
        left_tip, right_tip: the arms' tip links (None: proposed from the tree).
        left_base, right_base: the arms' base links (None: the torso).
        torso: the link the arms hang from (None: their common root).
        acceleration: every chain joint's acceleration limit [rad/s^2] (None: :data:`ACCELERATION_PER_S` times its
            velocity limit, assumed).
        jerk: every chain joint's jerk limit [rad/s^3] (None: :data:`JERK_PER_S` times its acceleration limit,
            assumed).
        name: the robot's name (None: the directory's name).
        allow: link pairs never to check for collision (written with the reason ``user``).
        up: the axis of the URDF's root frame that points up (:data:`dualarm.describe.up.AXES`); other than ``z``,
            the copy gets a root turned z-up (:func:`dualarm.describe.up.turn_root`). None: z, refused when the
            shoulders say otherwise (:func:`dualarm.describe.up.looks_turned`).
        progress: told what init is doing while it decomposes collision meshes (the long part, minutes on a
            robot of many meshes the first time; :mod:`dualarm.describe.convex`).

    Raises:
        RobotModelError: not a URDF, an unknown link, tips that are not on separate branches below a
            common root, a mesh not found, an ``allow`` link the URDF does not have.
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
    allowed_pairs(urdf, allow)
    turn = _turning(source, urdf, layout, up)
    check_meshes(source)  # refused before anything is written
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:  # /proc/x, a path through a file, no permission, ...
        why = exc.strerror or type(exc).__name__
        raise OutputError(f"--out {excerpt(out)}: cannot create the directory ({why})", str(out)) from None
    try:
        return _write(source, out, urdf, layout, acceleration, jerk, name or out.resolve().name, allow, turn, progress)
    except BaseException:
        shutil.rmtree(out, ignore_errors=True)
        raise


@contextlib.contextmanager
def _naming(source: Path, copy: Path) -> Iterator[None]:
    """Inside, a RobotModelError names the user's ``source``, not its ``copy`` (deleted with the output)."""
    try:
        yield
    except RobotModelError as exc:
        raise RobotModelError(str(exc).replace(excerpt(copy), excerpt(source))) from None


def _write(
    source: Path,
    out: Path,
    urdf: UrdfModel,
    layout: _Layout,
    acceleration: float | None,
    jerk: float | None,
    name: str,
    allow: Sequence[tuple[str, str]],
    turn: np.ndarray | None,
    progress: Callable[[str], None] | None,
) -> RobotInit:
    notes = list(layout.notes)
    copy = copy_urdf(source, out)
    notes.append(
        f"URDF copied to {copy} with its meshes under {out / 'meshes'} "
        "(the directory is self-contained: it works when moved or shipped)"
    )
    try:
        decomposed, convex = convex_collisions(copy, progress)
    except RobotModelError as exc:  # name the user's file: the copy goes with the directory
        raise RobotModelError(f"{excerpt(source)}: {exc}") from None
    if decomposed:
        notes.append(
            f"collision meshes: {decomposed} concave ones decomposed into convex parts (CoACD) under "
            f"{out / 'meshes' / CONVEX_DIR}, as PyBullet would collide their convex hulls; {convex} convex kept"
        )
    if turn is not None:
        turn_root(copy, urdf.root, turn)
        notes.append(
            f"root turned: a new root link '{TURNED_ROOT}' (x forward, y left, z up) holds '{urdf.root}' by the fixed "
            f"joint '{TURNED_JOINT}'; task poses are in '{TURNED_ROOT}'"
        )
    urdf = load_urdf(copy)
    try:  # before PyBullet reads it here: a crash in its loader is then a line, not the end of the command
        with _naming(source, copy):
            isolated(loads, str(copy))
    except CrashedError as exc:
        raise RobotModelError(f"{excerpt(source)}: PyBullet crashed loading it ({exc.why})") from None
    srs = {hand: _srs_verdict(urdf, f"{hand}_arm", base, tip) for hand, base, tip in layout.arms}
    for hand, base, tip in layout.arms:
        notes.append(
            f"chain {hand}_arm: {base} -> {tip}, hand '{hand}': "
            + ("S-R-S" if srs[hand] is None else f"not S-R-S ({srs[hand]})")
        )
    if layout.waist:
        notes.append(f"chain waist: {layout.waist[0]} -> {layout.waist[1]}")
    for j in layout.locked:
        notes.append(
            f"locked: {j.name} = {lock_value(j):g} rad "
            "(between the torso and an arm's base; name a base above it to move it)"
        )
    chain_joints = [j.name for hand, base, tip in layout.arms for j in urdf.chain(base, tip) if j.movable]
    if layout.waist:
        chain_joints = [j.name for j in urdf.chain(*layout.waist) if j.movable] + chain_joints
    limits = _limits(urdf, chain_joints, acceleration, jerk)
    for kind_, rule, unit in (
        ("velocity", f"{DEFAULT_VELOCITY_RAD_S:g} rad/s (the URDF gives none, or 0 or less)", "rad/s"),
        ("acceleration", f"{ACCELERATION_PER_S:g}/s times the velocity limit (give --acceleration)", "rad/s^2"),
        ("jerk", f"{JERK_PER_S:g}/s times the acceleration limit (give --jerk)", "rad/s^3"),
    ):
        assumed = [value for value, a in limits[kind_].values() if a]
        if assumed:
            notes.append(
                f"assumed {kind_} limits for {len(assumed)} joints: {rule}, {min(assumed):.3g} to {max(assumed):.3g} "
                f"{unit}; marked '# assumed' in robot.toml, and every message they cause says so"
            )
    homes: dict[str, Mapping[str, float]] = {"zero": {j.name: lock_value(j) for j in layout.locked}}
    (out / "robot.toml").write_text(
        robot_toml(name, copy.name, source, layout, urdf, srs, limits, homes, frozenset(), {})
    )
    robot = load_robot(out)
    if progress is not None:
        progress("sampling configurations")
    with _naming(source, copy):
        sim, touching = _collision_world(robot)
    with sim:
        held = held_values(robot, sim, chain_joints)
        for joint, value in held.items():
            if value != lock_value(urdf.joint(joint)):
                notes.append(
                    f"held: {joint} = {value:g} "
                    f"(in no chain; at {lock_value(urdf.joint(joint)):g} its links touch another link)"
                )
        disabled = disabled_pairs(robot, sim, touching, held, allow)
        ready = ready_pose(robot, sim, held)
    homes["zero"] = {k: v for k, v in held.items() if v != 0.0 or k in homes["zero"]}
    homes["ready"] = {k: v for k, v in ready.items() if v != 0.0 or k in homes["zero"]}
    notes.append("home ready: " + ", ".join(f"{k} = {v:g}" for k, v in homes["ready"].items()))
    counts = {reason: list(disabled.values()).count(reason) for reason in ("rigid", "always", "user")}
    notes.append(
        f"collision: {len(touching)} link pairs touch by construction (skipped by dualarm itself); "
        f"robot.toml [collision] disables {counts['rigid']} joined through no chain's joint, "
        f"{counts['always']} in contact at all {SAMPLES} sampled configurations"
        + (f", {counts['user']} given by --allow" if counts["user"] else "")
        + "; every other pair is checked"
    )
    (out / "robot.toml").write_text(
        robot_toml(name, copy.name, source, layout, urdf, srs, limits, homes, touching, disabled)
    )
    robot = load_robot(out)
    arms = tuple(
        ArmPlan(chain=f"{hand}_arm", hand=hand, base=base, tip=tip, srs=srs[hand]) for hand, base, tip in layout.arms
    )
    return RobotInit(
        directory=out,
        robot=robot,
        arms=arms,
        waist=layout.waist,
        locked=MappingProxyType({j.name: lock_value(j) for j in layout.locked}),
        ready=MappingProxyType(dict(robot.home("ready"))),
        touching_pairs=touching,
        disabled_pairs=MappingProxyType(disabled),
        notes=tuple(notes),
    )
