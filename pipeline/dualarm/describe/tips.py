"""The arms of a URDF's tree: where an arm ends (its tip) and which two tips make a robot's arms."""

from __future__ import annotations

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


def arm_tips(urdf: UrdfModel) -> list[str]:
    """Candidate arm tips: per leaf link, the link below the last revolute joint above it.

    Followed down through fixed joints while the branch does not split.
    """
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
