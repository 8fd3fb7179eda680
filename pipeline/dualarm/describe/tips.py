"""The arms of a URDF's tree: where an arm ends (its tip) and which two tips make a robot's arms."""

from __future__ import annotations

import re
from collections.abc import Sequence
from itertools import combinations

import numpy as np

from dualarm.errors import RobotModelError, excerpt
from dualarm.files import listing
from dualarm.model.urdf import JointSpec, UrdfModel

#: Fewest revolute joints a branch needs to be proposed as an arm (6 place a hand anywhere in its workspace).
MIN_ARM_DOF = 6
REVOLUTE = ("revolute", "continuous")
MOVABLE = ("revolute", "continuous", "prismatic")


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
        raise RobotModelError(
            f"{option} '{excerpt(link, 40)}': no such link in {excerpt(urdf.path)} (links: {listing(urdf.links)})"
        )
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


#: Link or joint names of a branch that is no arm: legs, wheels, fingers, heads (matched as words of the name).
NOT_ARM = re.compile(
    r"(^|[^a-z])(leg|foot|feet|ankle|knee|hip|toe|sole|wheel|caster|finger|thumb|knuckle|index|middle|ring|"
    r"pinky|little|head|neck|camera|eye)",
    re.IGNORECASE,
)
#: Names of the joints of a hand (its fingers, a gripper's jaw): an arm ends above the first of them.
HAND_JOINT = re.compile(r"gripper|finger|thumb|knuckle|claw|jaw", re.IGNORECASE)
#: Names of frames that end an arm: a tool frame below the hand is preferred to the hand.
TOOL_FRAME = re.compile(r"tool|tcp|eef|end_?effector|ee_link|grasp", re.IGNORECASE)


def _moving_below(urdf: UrdfModel) -> dict[str, bool]:
    """Per link: whether a movable joint hangs anywhere below it."""
    children = _children(urdf)
    out: dict[str, bool] = {}

    def visit(link: str) -> bool:
        if link not in out:
            out[link] = any(j.movable or visit(j.child) for j in children.get(link, []))
        return out[link]

    for link in urdf.links:
        visit(link)
    return out


def arm_tips(urdf: UrdfModel) -> list[str]:
    """Candidate arm tips, one per leaf link: where the leaf's longest serial run of revolute joints ends.

    The path from the root to the leaf, up to its first hand joint (:data:`HAND_JOINT`: a gripper's jaw),
    is cut at every link below which two or more branches move (a torso, a gripper's palm); the arm is the
    piece with the most revolute joints. It ends at the link where
    the path next splits (the palm, above its fingers), or else at the link below its last revolute joint,
    followed down through fixed joints while the branch does not split; in both cases a tool frame hung by
    fixed joints below it (:data:`TOOL_FRAME`) is preferred. Leaves whose piece, down to the tip, names a
    leg, wheel, finger or head (:data:`NOT_ARM`) give none.
    """
    children = _children(urdf)
    moving = _moving_below(urdf)

    def splits(link: str) -> bool:
        return sum(j.movable or moving[j.child] for j in children.get(link, [])) >= 2

    tips: list[str] = []
    for leaf in (link for link in urdf.links if not children.get(link)):
        path = urdf.chain(urdf.root, leaf)
        hand = [i for i, j in enumerate(path) if j.movable and HAND_JOINT.search(j.name)]
        path = path[: hand[0]] if hand else path
        pieces: list[list[JointSpec]] = [[]]
        for j in path:
            pieces[-1].append(j)
            if splits(j.child):
                pieces.append([])
        piece = max(pieces, key=_revolute_count)
        revolute = [j for j in piece if j.type in REVOLUTE]
        if not revolute:
            continue
        tip = piece[-1].child if splits(piece[-1].child) else revolute[-1].child
        while not splits(tip) and len(children.get(tip, [])) == 1 and children[tip][0].type == "fixed":
            tip = children[tip][0].child
        arm = urdf.chain(piece[0].parent, tip)
        if any(NOT_ARM.search(j.name) or NOT_ARM.search(j.child) for j in arm):
            continue
        tip = _tool_frame(urdf, tip) or tip
        if tip not in tips:
            tips.append(tip)
    return tips


def _tool_frame(urdf: UrdfModel, link: str) -> str | None:
    """The first link named like a tool frame hung below ``link`` by fixed joints (breadth first), or None."""
    children = _children(urdf)
    queue = [j.child for j in children.get(link, []) if j.type == "fixed"]
    while queue:
        child = queue.pop(0)
        if TOOL_FRAME.search(child):
            return child
        queue += [j.child for j in children.get(child, []) if j.type == "fixed"]
    return None


def _common_root(urdf: UrdfModel, a: str, b: str) -> str:
    above_b = set(_ancestors(urdf, b))
    return next(link for link in _ancestors(urdf, a) if link in above_b)


def propose_tips(urdf: UrdfModel) -> tuple[dict[str, str], str]:
    """The arms' tips by hand proposed from the tree, and why (a line to print).

    By hand: ``{"left": ..., "right": ...}`` or ``{"left": ...}``.
    """
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
            f"arms proposed from the tree: the two branches below '{root}' with the most revolute joints; "
            "left = the one further along +y at the zero pose (give --left-tip/--right-tip to choose)"
        )
    tip = max(tips, key=lambda t: _revolute_count(urdf.chain(urdf.root, t)))
    return (
        {"left": tip},
        (
            f"one arm proposed from the tree (no two branches with {MIN_ARM_DOF}+ revolute joints each): "
            f"tip '{tip}', driving hand 'left' (give --left-tip to choose)"
        ),
    )


def _first_movable(urdf: UrdfModel, base: str, tip: str) -> JointSpec:
    joints = [j for j in urdf.chain(base, tip) if j.type in MOVABLE]
    if not joints:
        raise RobotModelError(
            f"{excerpt(urdf.path)}: no movable joint between '{excerpt(base, 40)}' and '{excerpt(tip, 40)}'"
        )
    return joints[0]
