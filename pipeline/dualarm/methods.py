"""The IK methods and planners, in one registry: name -> what it is, what it needs, its settings class and its solve function.

What a method needs is stated here and nowhere else: :func:`refuse_unsuited` refuses a method
that needs S-R-S arms (``needs_srs``) on a robot whose driven arm is not one, naming the method,
the chain and the joints whose axes miss; :func:`suited_methods` lists those that run.

An IK method's solve function has one signature, ``solve(robot, reference, q0=None, settings=None)
-> JointPath``; its settings default from a task with ``settings_for(task, **overrides)``. A
planner is run by the plan stage (:func:`dualarm.plan.problem.plan_task`), on a task's Workspace
Target Areas. Nothing heavy is imported until a method is used.

    >>> import dualarm
    >>> m = dualarm.METHODS["mc-inverse"]
    >>> m.kind, m.needs_srs, m.orientation
    ('ik', True, True)
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, Literal

from dualarm.errors import InvalidArgumentError, NotSRSError, excerpt

if TYPE_CHECKING:
    from dualarm.model.robot import Robot
    from dualarm.tasks import Task


@dataclass(frozen=True)
class Method:
    """One IK method or planner.

    Attributes:
        name: its name (``--ik NAME`` / ``--planner NAME``).
        kind: ``ik`` (a Cartesian reference -> a joint path) or ``planner`` (a task's WTAs -> a
            collision-free joint path).
        title: one line on what it is and where it comes from.
        needs_srs: it works only on S-R-S arms (the shoulder's and the wrist's three axes meet).
        orientation: it solves the hands' orientation too (False: positions only, the
            orientation follows).
        module: the module that implements it.
        solver: the attribute of ``module`` that solves (IK: ``(robot, reference, q0, settings) ->
            JointPath``; planners: :func:`dualarm.plan.problem.plan_task`).
        settings_class: the attribute of ``module`` naming its settings class.
        defaults: the attribute of ``module`` giving its settings for a task,
            ``(task, **overrides) -> settings``; None when a task has no table for them.
        needs_sew: it works only on 7R arms of a family :mod:`dualarm.ik.analytic.sew` solves (joints 2-3
            and 5-7 meet: S-R-S arms and humanoid arms with an offset shoulder; or joints 1-3 and
            5-6: the Franka Panda's).
    """

    name: str
    kind: Literal["ik", "planner"]
    title: str
    needs_srs: bool
    orientation: bool
    module: str
    solver: str
    settings_class: str
    defaults: str | None = None
    needs_sew: bool = False

    def _get(self, attribute: str) -> Any:
        return getattr(importlib.import_module(self.module), attribute)

    @property
    def solve(self) -> Callable[..., Any]:
        """The solve function (imports the method's module)."""
        return self._get(self.solver)

    @property
    def settings_type(self) -> type:
        """The settings class (imports the method's module)."""
        return self._get(self.settings_class)

    def settings_for(self, task: Task | None = None, **overrides: Any) -> Any:
        """The method's settings: from ``task``'s tables when given, else the class defaults, with ``overrides`` (fields of the settings class) on top.

        Raises:
            InvalidArgumentError: an unknown field or a value the settings class refuses.
        """
        if task is None or self.defaults is None:
            from dualarm.settings import with_overrides

            return with_overrides(self.settings_type(), overrides)
        return self._get(self.defaults)(task, **overrides)


_POINTWISE = "dualarm.ik.pose_level.pointwise"

#: Every method, by name, in the order the CLI lists them.
METHODS: Mapping[str, Method] = MappingProxyType(
    {
        m.name: m
        for m in (
            Method(
                "tvgdd",
                "ik",
                "TV-GDD: velocity-level QP with time-varying gesture bounds (Zhang, Kong, Niu, eqs 15-27)",
                False,
                False,
                "dualarm.ik.velocity.tvgdd",
                "solve_tvgdd",
                "TvgddSettings",
                "settings_for",
            ),
            Method(
                "pinv",
                "ik",
                "pseudoinverse baseline of TV-GDD eqs (2)-(3), no bounds",
                False,
                False,
                "dualarm.ik.velocity.pinv",
                "solve_pinv",
                "PinvSettings",
                "settings_for",
            ),
            Method(
                "mc-inverse",
                "ik",
                "MC-Inverse: closed-form S-R-S IK at a chosen arm angle, one branch kept (Zou, Min, Xu)",
                True,
                True,
                "dualarm.ik.analytic.mc_path",
                "solve_mc_inverse",
                "ArmAngle",
                "settings_for",
            ),
            Method(
                "sew",
                "ik",
                "SEW angle (Elias, Wen): every solution at the SEW angle by a 1-D search, the one continuing the path kept; 7R arms with a spherical wrist and two meeting shoulder axes (S-R-S, offset humanoid shoulders) or a spherical shoulder and two meeting wrist axes (the Panda)",
                False,
                True,
                "dualarm.ik.analytic.sew_path",
                "solve_sew",
                "ArmAngle",
                "settings_for",
                needs_sew=True,
            ),
            Method(
                "trac-ik",
                "ik",
                "TRAC-IK (pytracik) pose by pose, seeded with the previous answer",
                False,
                True,
                _POINTWISE,
                "solve_trac_ik",
                "TracIkSettings",
            ),
            Method(
                "pybullet",
                "ik",
                "pybullet.calculateInverseKinematics pose by pose",
                False,
                True,
                _POINTWISE,
                "solve_pybullet",
                "PyBulletIkSettings",
            ),
            Method(
                "dls-svd",
                "ik",
                "damped least squares through the SVD, pose by pose (Li, Liang, eqs 12-20)",
                False,
                True,
                _POINTWISE,
                "solve_dls_svd",
                "DlsSettings",
            ),
            Method(
                "ikfast-style",
                "ik",
                "theta_3 discretised, the other six joints in closed form, nearest candidate",
                True,
                True,
                _POINTWISE,
                "solve_ikfast_style",
                "IkfastStyleSettings",
            ),
            Method(
                "mcikrrt",
                "planner",
                "MCIKRRT: bidirectional RRT to Workspace Target Areas (Li, Liang)",
                False,
                True,
                "dualarm.plan.problem",
                "plan_task",
                "PlanningSettings",
            ),
            Method(
                "ompl-rrtconnect",
                "planner",
                "OMPL's RRTConnect, same checker and goals",
                False,
                True,
                "dualarm.plan.problem",
                "plan_task",
                "PlanningSettings",
            ),
        )
    }
)

#: The IK methods' names.
IK_METHODS = tuple(n for n, m in METHODS.items() if m.kind == "ik")
#: The planners' names.
PLANNERS = tuple(n for n, m in METHODS.items() if m.kind == "planner")


def method(name: str, kind: Literal["ik", "planner"] | None = None, argument: str = "method") -> Method:
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
    """The arms of ``hands`` (``left``/``right``) that are not S-R-S: hand -> why not (the chain and the joints whose axes miss, as :func:`dualarm.model.srs.srs_geometry` says)."""
    from dualarm.model.srs import srs_geometry

    return _failing(robot, hands, srs_geometry)


def not_sew(robot: Robot, hands: Sequence[str]) -> dict[str, NotSRSError]:
    """The arms of ``hands`` that are not of the family :mod:`dualarm.ik.analytic.sew` solves: hand -> why not."""
    from dualarm.model.sew import sew_chain

    return _failing(robot, hands, sew_chain)


def suited_methods(robot: Robot, hands: Sequence[str], kind: Literal["ik", "planner"] = "ik") -> tuple[str, ...]:
    """The methods of ``kind`` that run on ``robot``'s arms of ``hands``: those whose needs (S-R-S arms, the SEW solver's family) every arm meets."""
    names = IK_METHODS if kind == "ik" else PLANNERS
    srs = not not_srs(robot, hands)
    sew = not not_sew(robot, hands)
    return tuple(n for n in names if (srs or not METHODS[n].needs_srs) and (sew or not METHODS[n].needs_sew))


def refuse_unsuited(m: Method, robot: Robot, hands: Sequence[str]) -> None:
    """Refuse method ``m`` when it needs S-R-S arms (``needs_srs``) and an arm of ``hands`` is not one, or the SEW solver's family (``needs_sew``) and an arm is not of it.

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
                f"{m.name} does not run on the {hand} arm of robot '{excerpt(robot.name, 40)}': {reason}; methods that run on it: {usable}",
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
            f"{m.name} needs S-R-S arms, and the {hand} arm of robot '{excerpt(robot.name, 40)}' is not: {reason}; methods that run on it: {usable}",
            chain=chain,
        )
