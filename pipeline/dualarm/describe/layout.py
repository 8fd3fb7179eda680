"""How ``robot init`` lays a URDF out: the arm chains, the torso, the waist and the locked joints."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from dualarm.describe.tips import _ancestors, _common_root, _first_movable, _link, propose_tips
from dualarm.errors import NotSRSError, RobotModelError, excerpt
from dualarm.model.robot import Chain
from dualarm.model.urdf import JointSpec, UrdfModel


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
class _Layout:
    arms: tuple[tuple[str, str, str], ...]  # (hand, base, tip)
    torso: str
    waist: tuple[str, str] | None
    locked: tuple[JointSpec, ...]
    notes: tuple[str, ...]


def _layout(
    urdf: UrdfModel, tips: Mapping[str, str | None], bases: Mapping[str, str | None], torso: str | None
) -> _Layout:
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
            raise RobotModelError(
                f"tips '{excerpt(a, 40)}' and '{excerpt(b, 40)}' are not on separate branches below a common root "
                "(one is above the other)"
            )
    else:
        root = _first_movable(urdf, urdf.root, given[hands[0]]).parent
    torso_link = _link(urdf, torso, "--torso") if torso else root
    arms = []
    for hand in hands:
        base = _link(urdf, bases[hand], f"--{hand}-base") if bases.get(hand) else torso_link  # type: ignore[arg-type]
        if torso_link not in _ancestors(urdf, base):
            raise RobotModelError(
                f"--{hand}-base '{excerpt(base, 40)}' is not below the torso '{excerpt(torso_link, 40)}'"
            )
        if base not in _ancestors(urdf, given[hand]):
            raise RobotModelError(
                f"--{hand}-tip '{excerpt(given[hand], 40)}' is not below its base '{excerpt(base, 40)}'"
            )
        _first_movable(urdf, base, given[hand])
        if not bases.get(hand):
            base, note = _seven_nearest_the_hand(urdf, hand, base, given[hand])
            notes += [note] if note else []
        arms.append((hand, base, given[hand]))
    if len(arms) == 2:
        shared = {j.name for j in urdf.chain(arms[0][1], arms[0][2]) if j.movable} & {
            j.name for j in urdf.chain(arms[1][1], arms[1][2]) if j.movable
        }
        if shared:
            raise RobotModelError(
                f"the arms share joint '{excerpt(sorted(shared)[0], 40)}': "
                f"give --torso at or below their common root '{excerpt(root, 40)}'"
            )
    waist_joints = [j for j in urdf.chain(urdf.root, torso_link) if j.movable]
    waist = (waist_joints[0].parent, torso_link) if waist_joints else None
    locked = tuple(j for _, base, _ in arms for j in urdf.chain(torso_link, base) if j.movable)
    return _Layout(arms=tuple(arms), torso=torso_link, waist=waist, locked=locked, notes=tuple(notes))


def _seven_nearest_the_hand(urdf: UrdfModel, hand: str, base: str, tip: str) -> tuple[str, str | None]:
    """The base of an arm of over 7 movable joints: where its 7 nearest the hand start, if S-R-S or SEW.

    A clavicle above a 7-joint arm. Else ``base``. With the line to print, or None.
    """
    from dualarm.model.sew import sew_chain

    movable = [j for j in urdf.chain(base, tip) if j.movable]
    if len(movable) <= 7:
        return base, None
    sub = movable[-7].parent
    chain = Chain(name=f"{hand}_arm", base=sub, tip=tip, joints=urdf.chain(sub, tip))
    if _srs_verdict(urdf, chain.name, sub, tip) is None:
        family = "S-R-S"
    else:
        try:
            family = f"SEW family {sew_chain(chain).family}"
        except NotSRSError:
            return base, None
    held = ", ".join(j.name for j in movable[:-7])
    return sub, (
        f"chain {hand}_arm: {len(movable)} movable joints from '{base}'; the 7 nearest the hand are {family}, so the "
        f"arm starts at '{sub}' and {held} are held like a clavicle (give --{hand}-base to choose)"
    )


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
