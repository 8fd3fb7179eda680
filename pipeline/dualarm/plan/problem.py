"""A task's planning problem, and one planning query on it with either planner.

The planned joints are those of the hands that have WTAs, from the robot's root: with the waist
free, the 17-DOF model (waist and both arms); with it locked, the arms, the waist held at its
initial values. The start is the task's initial configuration; the collision checker holds the
task's fixed objects and allows its expected contacts.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from dualarm.errors import StageError
from dualarm.method import Method
from dualarm.model.kinematics import ChainKinematics
from dualarm.model.poses import invert
from dualarm.plan.collision import CollisionChecker
from dualarm.plan.goals import WtaGoalSampler
from dualarm.plan.mcikrrt import PlanResult, TreeSearchSettings, mcikrrt
from dualarm.plan.wta import Wta
from dualarm.settings import check_positive
from dualarm.tasks import Task

#: The planners :meth:`PlanningProblem.solve` runs (the registry's, :data:`dualarm.methods.PLANNERS`).
PLANNERS = ("mcikrrt", "ompl-rrtconnect")


@dataclass(frozen=True)
class PlanningSettings:
    """Settings of a planning query.

    Attributes:
        planner: the tree search's settings (:class:`~dualarm.plan.mcikrrt.TreeSearchSettings`).
        margin_m: the collision checker's safety margin [m].
        resolution_rad: the largest joint step between checked configurations of an edge [rad].
        ompl_goals: how many goal configurations OMPL is given (the first ones of the same
            goal sampler MCIKRRT uses).
    """

    planner: TreeSearchSettings = TreeSearchSettings()
    margin_m: float = 0.01
    resolution_rad: float = 0.02
    ompl_goals: int = 4

    def __post_init__(self) -> None:
        check_positive(self, "margin_m", zero=True)
        check_positive(self, "resolution_rad")
        check_positive(self, "ompl_goals", integer=True)

    def with_timeout(self, timeout_s: float | None) -> PlanningSettings:
        """The same settings with the planner's timeout [s] (unchanged for None)."""
        return self if timeout_s is None else replace(self, planner=replace(self.planner, timeout_s=timeout_s))


class PlanningProblem:
    """A task's planning problem (module docstring).

    Attributes:
        task: the task.
        settings: the query settings.
        joint_names: the planned joints.
        fixed: every other joint's value [rad].
        start: the start configuration [rad].
        lower, upper: the planned joints' position limits [rad].
        checker: the collision checker.
    """

    def __init__(self, task: Task, settings: PlanningSettings = PlanningSettings()):
        if not task.spec.wta:
            raise StageError(f"{task.file}: the task has no [[wta]] to plan to")
        robot = task.robot
        self.task, self.settings = task, settings
        hands = tuple(h for h in ("left", "right") if any(w.hand == h for w in task.spec.wta))
        self.areas = {h: [Wta.of(w) for w in task.spec.wta if w.hand == h] for h in hands}
        tips = [robot.hand_chain(h).tip for h in hands]
        self._base_pose = np.eye(4)
        base = robot.urdf.root
        if task.spec.waist == "locked":
            base = robot.hand_chain(hands[0]).base
            chain = robot.chain_between(robot.urdf.root, base)
            self._base_pose = (
                ChainKinematics.of(chain).pose(np.array([task.initial_q[n] for n in chain.joint_names]))
                if chain.dof
                else np.eye(4)
            )
        self.solver = WtaGoalSampler.ik_solver(robot, base, tips)
        self.joint_names = self.solver.joint_names
        self.fixed = {n: v for n, v in task.initial_q.items() if n not in self.joint_names}
        self.start = np.array([task.initial_q[n] for n in self.joint_names])
        self.lower, self.upper = self.solver.lower, self.solver.upper
        self.checker = CollisionChecker(
            robot,
            self.joint_names,
            self.fixed,
            task.spec.environment,
            task.spec.expected_contacts,
            settings.margin_m,
            settings.resolution_rad,
        )
        contacts = self.checker.contacts(self.start)
        if contacts:
            worst = contacts[0]
            self.close()
            raise StageError(
                f"{task.file}: the start configuration is in collision: {worst.a} with {worst.b} "
                f"({worst.depth_m * 1e3:.1f} mm deep, the {settings.margin_m * 1e3:g} mm safety margin included)"
            )

    def goal_sampler(self, seed: int) -> WtaGoalSampler:
        """A goal sampler whose WTA samples are drawn from ``seed``'s own stream."""
        areas = {h: [self._in_base(a) for a in areas] for h, areas in self.areas.items()}
        return WtaGoalSampler(areas, self.solver, self.checker, self.start, np.random.default_rng([seed, 0]))

    def _in_base(self, area: Wta) -> Wta:
        """``area`` with its reference in the IK base frame (the torso when the waist is locked)."""
        if np.array_equal(self._base_pose, np.eye(4)):
            return area
        return Wta(
            area.name, area.hand, invert(self._base_pose) @ area.reference, area.offset, area.bounds, area.weight
        )

    def solve(self, planner: str, seed: int) -> PlanResult:
        """One query with ``planner`` (:data:`PLANNERS`) from ``seed``.

        Raises:
            StageError: an unknown planner.
        """
        settings = self.settings
        sampler = self.goal_sampler(seed)
        if planner == "mcikrrt":
            result = mcikrrt(
                self.start,
                self.lower,
                self.upper,
                self.checker,
                sampler,
                np.random.default_rng([seed, 1]),
                settings.planner,
            )
        elif planner == "ompl-rrtconnect":
            from dualarm.plan.ompl_rrtconnect import ompl_rrtconnect  # imports OMPL only when used

            started = time.perf_counter()
            checks = self.checker.checks
            while (
                len(sampler.goals) < settings.ompl_goals and time.perf_counter() - started < settings.planner.timeout_s
            ):
                sampler()
            goal_time = time.perf_counter() - started
            if sampler.goals:  # the goals' collision checks count too
                result = ompl_rrtconnect(
                    self.start, self.lower, self.upper, self.checker, sampler.goals, seed, settings.planner, goal_time
                )
                result = replace(result, collision_checks=self.checker.checks - checks)
            else:
                result = PlanResult(
                    False, np.empty((0, len(self.start))), 0.0, goal_time, 0, 0, self.checker.checks - checks
                )
        else:
            raise StageError(f"unknown planner '{planner}' (planners: {', '.join(PLANNERS)})")
        if not result.success and not sampler.goals:
            reason = (
                f"no goal configuration within the timeout of {settings.planner.timeout_s:g} s: {sampler.explain()}"
            )
            result = replace(result, reason=reason)
        return result

    def close(self) -> None:
        """Release the collision checker."""
        self.checker.close()

    def __enter__(self) -> PlanningProblem:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def plan_task(task: Task, planner: str, settings: PlanningSettings = PlanningSettings(), seed: int = 0) -> PlanResult:
    """One planning query of ``task`` with ``planner`` from ``seed``.

    The query is of the task's WTAs, scene and initial configuration; ``planner`` is ``mcikrrt`` or
    ``ompl-rrtconnect``.

    Raises:
        StageError: the task has no WTA, its start is in collision, or the planner is unknown.
    """
    with PlanningProblem(task, settings) as problem:
        return problem.solve(planner, seed)


def _options(settings: PlanningSettings, options: Mapping[str, Any]) -> PlanningSettings:
    """The run command's ``--timeout`` [s] on a planner's settings (unchanged without one)."""
    return settings.with_timeout(options.get("timeout"))


#: The planners in the registry (:data:`dualarm.methods.METHODS`).
METHODS: Mapping[str, Method[PlanningSettings]] = {
    m.name: m
    for m in (
        Method(
            "mcikrrt",
            "planner",
            "MCIKRRT: bidirectional RRT to Workspace Target Areas (Li, Liang)",
            plan_task,
            PlanningSettings,
            options=_options,
        ),
        Method(
            "ompl-rrtconnect",
            "planner",
            "OMPL's RRTConnect, same checker and goals",
            plan_task,
            PlanningSettings,
            options=_options,
        ),
    )
}
