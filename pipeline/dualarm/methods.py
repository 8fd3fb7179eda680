"""The IK methods and planners, in one registry: each method's name and where it lives.

Each method module exports its methods as ``METHODS`` (name -> :class:`~dualarm.method.Method`):
the solve function, the settings and their defaults, what the arm must be, what it records, how
the run command's options set it. The registry imports a module when one of its methods is first
used, so listing the names imports nothing heavy.

What an arm must be is checked here: :func:`refuse_unsuited` refuses a method that needs S-R-S
arms (or the SEW solver's families) on a robot whose driven arm is not one, naming the method,
the chain and the joints whose axes miss; :func:`suited_methods` lists those that run.

    >>> import dualarm
    >>> m = dualarm.METHODS["mc-inverse"]
    >>> m.kind, m.needs_srs, m.orientation
    ('ik', True, True)
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import TYPE_CHECKING, Any, Literal

from dualarm.errors import InvalidArgumentError, NotSRSError, excerpt
from dualarm.method import Method

if TYPE_CHECKING:
    from dualarm.model.robot import Robot

_VELOCITY, _ANALYTIC, _POSE = "dualarm.ik.velocity", "dualarm.ik.analytic", "dualarm.ik.pose_level"
#: The module of each IK method, in the order the CLI lists them.
_IK: Mapping[str, str] = {
    "tvgdd": f"{_VELOCITY}.tvgdd",
    "pinv": f"{_VELOCITY}.pinv",
    "mc-inverse": f"{_ANALYTIC}.mc_path",
    "sew": f"{_ANALYTIC}.sew_path",
    "trac-ik": f"{_POSE}.pointwise",
    "pybullet": f"{_POSE}.pointwise",
    "dls-svd": f"{_POSE}.pointwise",
    "ikfast-style": f"{_POSE}.pointwise",
}
#: The module of each planner.
_PLANNERS: Mapping[str, str] = {"mcikrrt": "dualarm.plan.problem", "ompl-rrtconnect": "dualarm.plan.problem"}

_MODULES: Mapping[str, str] = {**_IK, **_PLANNERS}

#: The IK methods' names.
IK_METHODS = tuple(_IK)
#: The planners' names.
PLANNERS = tuple(_PLANNERS)


class _Registry(Mapping[str, Method[Any]]):
    """Every method by name, its module imported when it is first asked for."""

    def __getitem__(self, name: str) -> Method[Any]:
        return importlib.import_module(_MODULES[name]).METHODS[name]

    def __iter__(self) -> Iterator[str]:
        return iter((*IK_METHODS, *PLANNERS))

    def __len__(self) -> int:
        return len(IK_METHODS) + len(PLANNERS)


#: Every method, by name, in the order the CLI lists them.
METHODS: Mapping[str, Method[Any]] = _Registry()


def method(name: str, kind: Literal["ik", "planner"] | None = None, argument: str = "method") -> Method[Any]:
    """The method called ``name`` (of ``kind`` when given); ``argument`` names it in errors.

    Raises:
        InvalidArgumentError: no such method, listing the valid names.
    """
    names = IK_METHODS if kind == "ik" else PLANNERS if kind == "planner" else tuple(METHODS)
    if name not in names:
        what = {"ik": "IK method", "planner": "planner", None: "method"}[kind]
        plural = {"ik": "methods", "planner": "planners", None: "methods"}[kind]
        raise InvalidArgumentError(argument, f"unknown {what} '{name}' ({plural}: {', '.join(names)})")
    return METHODS[name]


def _failing(robot: Robot, hands: Sequence[str], check: Callable[[Any], object]) -> dict[str, NotSRSError]:
    """The arms of ``hands`` whose chain ``check`` refuses: hand -> its one-line reason."""
    reasons = {}
    for hand in hands:
        try:
            check(robot.hand_chain(hand))
        except NotSRSError as exc:
            reasons[hand] = exc
    return reasons


def not_srs(robot: Robot, hands: Sequence[str]) -> dict[str, NotSRSError]:
    """The arms of ``hands`` (``left``/``right``) that are not S-R-S: hand -> why not.

    Why not: the chain and the joints whose axes miss, as :func:`dualarm.model.srs.srs_geometry` says.
    """
    from dualarm.model.srs import srs_geometry

    return _failing(robot, hands, srs_geometry)


def not_sew(robot: Robot, hands: Sequence[str]) -> dict[str, NotSRSError]:
    """The arms of ``hands`` that are not of the family the SEW solver solves: hand -> why not.

    The SEW solver is :mod:`dualarm.ik.analytic.sew`.
    """
    from dualarm.model.sew import sew_chain

    return _failing(robot, hands, sew_chain)


def suited_methods(robot: Robot, hands: Sequence[str], kind: Literal["ik", "planner"] = "ik") -> tuple[str, ...]:
    """The methods of ``kind`` that run on ``robot``'s arms of ``hands``.

    Those whose needs (S-R-S arms, the SEW solver's family) every arm meets.
    """
    names = IK_METHODS if kind == "ik" else PLANNERS
    srs = not not_srs(robot, hands)
    sew = not not_sew(robot, hands)
    return tuple(n for n in names if (srs or not METHODS[n].needs_srs) and (sew or not METHODS[n].needs_sew))


def refuse_unsuited(m: Method[Any], robot: Robot, hands: Sequence[str]) -> None:
    """Refuse method ``m`` when an arm of ``hands`` is not what it needs.

    That is, when it needs S-R-S arms (``needs_srs``) and an arm of ``hands`` is not one, or the SEW
    solver's family (``needs_sew``) and an arm is not of it.

    Raises:
        NotSRSError: one line naming the method, the robot, the chain and the joints whose axes
            miss, and the methods that do run on the robot.
    """
    if m.needs_sew:
        sew_reasons = not_sew(robot, hands)
        if sew_reasons:
            hand, reason = next(iter(sew_reasons.items()))
            usable = ", ".join(suited_methods(robot, hands, m.kind))
            raise NotSRSError(
                f"{m.name} does not run on the {hand} arm of robot '{excerpt(robot.name, 40)}': {reason}; "
                f"methods that run on it: {usable}",
                chain=robot.hand_chain(hand).name,
            )
    if not m.needs_srs:
        return
    reasons = not_srs(robot, hands)
    if reasons:
        hand, reason = next(iter(reasons.items()))
        chain = robot.hand_chain(hand).name
        usable = ", ".join(suited_methods(robot, hands, m.kind))
        raise NotSRSError(
            f"{m.name} needs S-R-S arms, and the {hand} arm of robot '{excerpt(robot.name, 40)}' is not: "
            f"{reason}; methods that run on it: {usable}",
            chain=chain,
        )
