"""``Method``: one IK method or planner as the pipeline runs it.

Each is exported by the module that implements it.

A method says everything the pipeline and the command line ask of it: its solve function, its
settings class and their defaults for a task, what the arm must be, whether it solves the
hands' orientation, what it records beyond the joint path, and how the run command's options set
its settings. :mod:`dualarm.methods` lists where each one lives.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Generic, Literal, TypeVar

from dualarm.settings import with_overrides

if TYPE_CHECKING:
    from dualarm.contracts.joint_path import JointPath
    from dualarm.model.robot import Robot
    from dualarm.tasks import Task

S = TypeVar("S")
#: What an arm must be for a method: any chain, an S-R-S arm, or a 7R arm of the SEW solver's families.
Arm = Literal["any", "srs", "sew"]


@dataclass(frozen=True)
class Recorded:
    """What a method chose along a path beyond the joints.

    Attributes:
        settings: JSON-ready entries the run's manifest records with the method's settings
            (MC-Inverse: ``arm_angle_profile``, per hand the mode, psi and the branch kept).
        metrics: ``ik.<name>`` -> value (units in the names).
        lines: one line each, printed after a run.
    """

    settings: Mapping[str, Any] = field(default_factory=dict)
    metrics: Mapping[str, float] = field(default_factory=dict)
    lines: tuple[str, ...] = ()


@dataclass(frozen=True)
class Method(Generic[S]):
    """One IK method or planner.

    Attributes:
        name: its name (``--ik NAME`` / ``--planner NAME``).
        kind: ``ik`` (a Cartesian reference -> a joint path) or ``planner`` (a task's WTAs -> a
            collision-free joint path).
        title: one line on what it is and where it comes from.
        solve: IK: ``(robot, reference, q0=None, settings=None) -> JointPath``; planners:
            :func:`dualarm.plan.problem.plan_task`.
        settings_type: its settings class (a frozen dataclass or a frozen pydantic model).
        defaults: its settings for a task, ``(task, **overrides) -> settings``; None when a task
            has no table for them (the class defaults).
        arm: what each driven arm must be: ``any``, ``srs`` (the shoulder's and the wrist's three
            axes meet) or ``sew`` (a 7R arm of a family :mod:`dualarm.ik.analytic.sew` solves).
        orientation: it solves the hands' orientation too (False: positions only, the
            orientation follows).
        recorded: what it chose along a joint path, ``(path, robot, settings) -> Recorded``.
        options: the run command's options applied to its settings, ``(settings, options) ->
            settings`` (``options``: option name -> value, e.g. ``scheme``, ``timeout``).
        clearance: its ``auto`` arm angle can keep each arm clear of collisions: ``solve`` takes a
            ``clearance`` keyword (:class:`dualarm.plan.clearance.ArmClearance`), which the IK stage gives it.
    """

    name: str
    kind: Literal["ik", "planner"]
    title: str
    solve: Callable[..., Any]
    settings_type: type[S]
    defaults: Callable[..., S] | None = None
    arm: Arm = "any"
    orientation: bool = True
    recorded: Callable[[JointPath, Robot, S], Recorded] | None = None
    options: Callable[[S, Mapping[str, Any]], S] | None = None
    clearance: bool = False

    @property
    def needs_srs(self) -> bool:
        """It works only on S-R-S arms."""
        return self.arm == "srs"

    @property
    def needs_sew(self) -> bool:
        """It works only on 7R arms of a family the SEW solver handles."""
        return self.arm == "sew"

    def settings_for(self, task: Task | None = None, **overrides: Any) -> S:
        """The method's settings: from ``task``'s tables if given, else the class defaults, with ``overrides``.

        ``overrides`` are fields of the settings class, on top.

        Raises:
            InvalidArgumentError: an unknown field or a value the settings class refuses.
        """
        if task is None or self.defaults is None:
            return with_overrides(self.settings_type(), overrides)
        return self.defaults(task, **overrides)

    def record(self, path: JointPath, robot: Robot, settings: S) -> Recorded:
        """What the method chose along ``path`` (nothing for most methods)."""
        return self.recorded(path, robot, settings) if self.recorded is not None else Recorded()

    def with_options(self, settings: S, options: Mapping[str, Any]) -> S:
        """``settings`` with the run command's ``options`` that this method takes applied."""
        return self.options(settings, options) if self.options is not None else settings
