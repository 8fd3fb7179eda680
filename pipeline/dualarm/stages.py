"""The pipeline's stages, each of one shape: built from a task and its settings.

Each is called on the previous stage's product and a sink, returning its own product and its metrics.

    task -> [path] -> CartesianReference -> [ik | plan] -> JointPath -> [retime] -> JointTrajectory
         -> [smooth] -> JointTrajectory -> [execute] -> ExecutionLog

``stage(product, sink) -> (product, metrics)``: the stage tells the sink when it begins and hands
it its product once; metrics are ``<stage>.<name>`` keys with the unit as suffix. Limit ratios
are always against the task's full limits (the robot's, or the task's own where it sets them).
``stage.violations(product)`` judges the product against the checks of :mod:`dualarm.violations`;
the run's verdict is every stage's violations together.
Heavy libraries (toppra, ruckig, pybullet) are imported only by the stages that use them.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, ClassVar, Protocol, TypeVar

import numpy as np

from dualarm.contracts.joint_path import JointPath
from dualarm.contracts.reference import CartesianReference
from dualarm.contracts.trajectory import JointTrajectory
from dualarm.contracts.verdict import Checks, Violation
from dualarm.errors import StageError
from dualarm.limits import limit_ratios
from dualarm.method import Method
from dualarm.methods import refuse_unsuited
from dualarm.record.sink import Sink
from dualarm.settings import as_record
from dualarm.tasks.schema import Retime
from dualarm.violations import execution_violations, ik_violations, position_limit_violations, trajectory_violations

if TYPE_CHECKING:
    from dualarm.contracts.execution import ExecutionLog
    from dualarm.execute.simulate import ExecutionSettings
    from dualarm.plan.mcikrrt import PlanResult
    from dualarm.plan.problem import PlanningProblem
    from dualarm.tasks import Task

#: Sample period of the retimed trajectory and control period of the smooth stage [s].
CONTROL_PERIOD_S = 0.001


#: The product a stage takes (the task, for the path stage).
In = TypeVar("In", contravariant=True)
#: The product a stage makes and judges.
Out = TypeVar("Out")


class Stage(Protocol[In, Out]):
    """A stage: ``name``, the settings it records, and ``(product, sink) -> (product, metrics)``."""

    name: ClassVar[str]

    def settings_record(self) -> dict[str, Any]:
        """The stage's settings, JSON-ready (a run's manifest records them)."""
        ...

    def __call__(self, product: In, sink: Sink, /) -> tuple[Out, dict[str, float]]:
        """Run on the previous stage's product (the task, for the path stage)."""
        ...

    def violations(self, product: Out, /) -> list[Violation]:
        """The checks (:mod:`dualarm.violations`) this stage's own product fails."""
        ...


def hand_positions(task: Task, traj: JointTrajectory, q: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Each driven hand's position (M, 3) [m] by forward kinematics of ``q`` (default ``traj.q``)."""
    poses = task.hand_poses(traj.joint_names, traj.q if q is None else q, traj.fixed)
    return {hand: T[:, :3, 3] for hand, T in poses.items()}


def _distance_max(hands: dict[str, np.ndarray], reference: dict[str, np.ndarray]) -> float:
    """The largest distance between each hand's positions (M, 3) [m] and its reference's [m].

    Over the hands (0 without hands).
    """
    return max((float(np.linalg.norm(hands[h] - reference[h], axis=1).max()) for h in hands), default=0.0)


@dataclass(frozen=True)
class PathStage:
    """The task's hand motions sampled at its control period (quintic time scaling)."""

    task: Task
    name: ClassVar[str] = "path"

    def settings_record(self) -> dict[str, Any]:
        """The path stage's settings: the control period [s], the time scaling, the repetitions."""
        spec = self.task.spec
        return {"control_period_s": spec.control_period_s, "time_scaling": "quintic", "repetitions": spec.repetitions}

    def __call__(self, task: Task, sink: Sink) -> tuple[CartesianReference, dict[str, float]]:
        """Sample the task's hand motions: task -> CartesianReference."""
        from dualarm.paths.build import build_reference

        sink.begin(self.name)
        sink.robot_state("path", 0.0, task.initial_q)
        sink.environment(task.spec.environment, task.spec.object)
        reference = build_reference(task)
        sink.reference(reference)
        return reference, path_metrics(reference)

    def violations(self, reference: CartesianReference) -> list[Violation]:
        """None: the reference is what the task asks."""
        return []


def path_metrics(ref: CartesianReference) -> dict[str, float]:
    """``path.*`` metrics of a reference.

    Samples, duration [s], repetitions, the longest hand path [m] and the highest hand speed [m/s].
    """
    lengths = [float(np.linalg.norm(np.diff(h.position, axis=0), axis=1).sum()) for h in ref.hands.values()]
    speeds = [float(np.linalg.norm(h.linear_velocity, axis=1).max()) for h in ref.hands.values()]
    return {
        "path.samples": float(len(ref)),
        "path.duration_s": ref.duration_s,
        "path.repetitions": float(ref.rep.max() + 1),
        "path.length_max_m": max(lengths),
        "path.speed_max_m_s": max(speeds),
    }


@dataclass(frozen=True)
class IkStage:
    """An IK method of the registry along the reference, from the task's initial configuration."""

    task: Task
    method: Method[Any]
    settings: Any
    checks: Checks = field(default_factory=Checks)
    retimed: bool = True
    executed: bool = True
    name: ClassVar[str] = "ik"

    def __post_init__(self) -> None:
        """Refuse a method whose arm the task's robot does not have (:func:`dualarm.methods.refuse_unsuited`)."""
        refuse_unsuited(self.method, self.task.robot, self.task.spec.hands)

    def settings_record(self) -> dict[str, Any]:
        """The IK method's name and settings (what it chose while running is the joint path's ``chosen``)."""
        return {"method": self.method.name, **as_record(self.settings)}

    def __call__(self, reference: CartesianReference, sink: Sink) -> tuple[JointPath, dict[str, float]]:
        """Solve the reference from the task's initial configuration: CartesianReference -> JointPath."""
        from dualarm.ik.metrics import arm_angles, condition_metrics, consistency_metrics, ik_metrics

        sink.begin(self.name)
        robot = self.task.robot
        if self.method.clearance and self.settings.mode == "auto":
            from dualarm.plan.clearance import ArmClearance

            with ArmClearance(self.task) as clearance:
                path = self.method.solve(robot, reference, self.task.initial_q, self.settings, clearance=clearance)
        else:
            path = self.method.solve(robot, reference, self.task.initial_q, self.settings)
        angles = arm_angles(path, robot, self.task.spec.arm_angle.vertical)
        sink.joint_path(path, robot.limit_array("velocity", path.joint_names), angles)
        if len(path.status) and (path.status != 0).all():  # nothing for the later stages to move along
            error = np.nanmin(path.hand_error_m.max(axis=1)) if path.hand_error_m.size else float("nan")
            raise StageError(
                f"ik ({self.method.name}): every one of the {len(path.status)} samples failed "
                f"(its hands came no closer than {error:.3g} m to the asked poses)",
                stage="ik",
            )
        recorded = self.method.record(path, robot, self.settings)
        metrics = {
            **ik_metrics(path, robot),
            **condition_metrics(path, robot),
            **consistency_metrics(path, reference, angles),
            **recorded.metrics,
        }
        return replace(path, chosen=recorded.settings), metrics

    def violations(self, path: JointPath) -> list[Violation]:
        """Failed IK, hands off the pose, position limits; velocity without retime, contacts without execute.

        Hands off the asked pose: the orientation too when the method solved it. Velocity limits when no
        retime stage follows (``retimed`` False). Collisions when no execute stage follows (``executed`` False), whose
        preflight would check the trajectory through these samples: at the solved samples, with the preflight's
        checker (:func:`dualarm.execute.preflight.path_collision_violations`).
        """
        found = ik_violations(path, self.task.robot, self.checks, retimed=self.retimed)
        if not self.executed:
            from dualarm.execute.preflight import path_collision_violations

            found += path_collision_violations(path, self.task)
        return found


@dataclass(frozen=True)
class PlanStage:
    """A planner of the registry from the task's initial configuration to its WTAs.

    The reference is not used.

    ``planned`` is a plan already made for the problem (``dualarm plan`` records its first
    successful trial so). The problem (and its PyBullet checker) is released by :meth:`close`.
    """

    problem: PlanningProblem
    planner: str
    seed: int = 0
    planned: PlanResult | None = None
    name: ClassVar[str] = "plan"

    def settings_record(self) -> dict[str, Any]:
        """The planner's name (``method``; ``planner`` holds its settings) and the query's settings."""
        return {"method": self.planner, **as_record(self.problem.settings)}

    def __call__(self, reference: CartesianReference, sink: Sink) -> tuple[JointPath, dict[str, float]]:
        """Plan (or take the plan already made): the reference (unused) -> JointPath."""
        from dualarm.plan.stage import plan_metrics, planned_joint_path

        sink.begin(self.name)
        result = self.planned or self.problem.solve(self.planner, self.seed)
        if not result.success:
            raise StageError(f"plan ({self.planner}): {result.reason}", stage="plan")
        path = planned_joint_path(self.problem, result, self.planner)
        sink.joint_path(path, self.problem.task.robot.limit_array("velocity", path.joint_names), {}, stage="plan")
        return path, {**plan_metrics(result), "plan.wta_position_distance_max_m": float(path.hand_error_m[-1].max())}

    def violations(self, path: JointPath) -> list[Violation]:
        """Position limits (the planner samples within them; this checks its output)."""
        return position_limit_violations("plan", path.t, path.joint_names, path.q, self.problem.task.robot)

    def close(self) -> None:
        """Release the planning problem."""
        self.problem.close()


@dataclass(frozen=True)
class RetimeStage:
    """Time the joint path (jerk-limited, TOPP-RA, or the task's own timing).

    The trajectory is sampled every :data:`CONTROL_PERIOD_S`.

    The jerk-limited timing (the default) uses the full velocity, acceleration and jerk limits;
    TOPP-RA (``optimal``) uses ``settings.velocity_fraction`` and ``acceleration_fraction`` of the
    velocity and acceleration limits (headroom for the smooth stage's tracking); the task's own
    timing is checked against the full three.
    """

    task: Task
    settings: Retime = field(default_factory=Retime)
    name: ClassVar[str] = "retime"

    def settings_record(self) -> dict[str, Any]:
        """The timing, the share of the limits it may use, the sample period and toppra's parametrizer."""
        return {
            **self.settings.model_dump(),
            "sample_period_s": CONTROL_PERIOD_S,
            "parametrizer": "ParametrizeConstAccel",
        }

    def __call__(self, path: JointPath, sink: Sink) -> tuple[JointTrajectory, dict[str, float]]:
        """Time the joint path: JointPath -> JointTrajectory (stage ``retime``)."""
        from dualarm.retime import retime_path

        sink.begin(self.name)
        settings, names = self.settings, path.joint_names
        robot = self.task.robot
        v, a = robot.limit_array("velocity", names), robot.limit_array("acceleration", names)
        j = robot.limit_array("jerk", names) if settings.timing != "optimal" else None
        if settings.timing == "optimal":
            result = retime_path(
                path,
                settings.velocity_fraction * v,
                settings.acceleration_fraction * a,
                sample_period_s=CONTROL_PERIOD_S,
            )
        else:
            result = retime_path(
                path,
                v,
                a,
                sample_period_s=CONTROL_PERIOD_S,
                keep_timing=settings.timing == "task",
                jerk=j,
                position=robot.lower_upper(names),
                assumed=robot.assumed,
            )
        traj = result.trajectory
        samples, limits = {"velocity": traj.qd, "acceleration": traj.qdd}, {"velocity": v, "acceleration": a}
        if j is not None:
            samples["jerk"], limits["jerk"] = traj.mean_jerk(), j
        ratios = limit_ratios(traj.t, names, samples, limits, self.name)
        sink.trajectory(
            traj, limits, hand_positions(self.task, traj), {"jerk": samples["jerk"]} if j is not None else {}
        )
        return traj, {
            "retime.duration_s": traj.duration_s,
            **{f"retime.{kind}_ratio_max": r.ratio for kind, r in ratios.items()},
            "retime.path_deviation_max_rad": result.path_deviation_max_rad,
            "retime.hand_deviation_max_m": _distance_max(
                hand_positions(self.task, traj, result.at_samples), hand_positions(self.task, traj, path.q)
            ),
            "retime.stretch": result.stretch,
            "retime.fallback_pieces": len(result.fallbacks),
            "retime.fallback_excess_s": sum(f.duration_s - f.bound_s for f in result.fallbacks),
        }

    def violations(self, traj: JointTrajectory) -> list[Violation]:
        """Position, velocity and acceleration limits, and the jerk's but for TOPP-RA.

        TOPP-RA's jerk is the smooth stage's to bound.
        """
        return trajectory_violations(traj, self.task.robot, jerk=self.settings.timing != "optimal")


@dataclass(frozen=True)
class SmoothStage:
    """Track a TOPP-RA trajectory with jerk-limited motion; pass any other through.

    The tracking is Ruckig's, every :data:`CONTROL_PERIOD_S`.

    Only the ``optimal`` timing (TOPP-RA) leaves the jerk unbounded; the ``jerk-limited`` and
    ``task`` timings are already checked within the jerk limits by the retime stage, so their
    trajectory passes unchanged (stage ``smooth``, deviation 0). Besides the limit ratios, it
    measures how far it departs from the retimed trajectory at the same time: per joint [rad] and
    at the hands [m].
    """

    task: Task
    timing: str = "jerk-limited"
    name: ClassVar[str] = "smooth"

    @property
    def tracks(self) -> bool:
        """Whether it tracks the retimed trajectory (the ``optimal`` timing) rather than passing it through."""
        return self.timing == "optimal"

    def settings_record(self) -> dict[str, Any]:
        """The tracking method (or ``pass-through``) and its control period [s]."""
        return {
            "method": "ruckig online tracking"
            if self.tracks
            else f"pass-through (the {self.timing} timing is within the jerk limits)",
            "control_period_s": CONTROL_PERIOD_S,
        }

    def __call__(self, retimed: JointTrajectory, sink: Sink) -> tuple[JointTrajectory, dict[str, float]]:
        """Track the retimed trajectory, or pass it through: JointTrajectory -> JointTrajectory.

        Stage ``smooth``.
        """
        from dualarm.smooth import Smoothed, smooth_trajectory

        sink.begin(self.name)
        names = retimed.joint_names
        v, a, j = (self.task.robot.limit_array(kind, names) for kind in ("velocity", "acceleration", "jerk"))
        if self.tracks:
            result = smooth_trajectory(retimed, v, a, j, period_s=CONTROL_PERIOD_S)
        else:
            result = Smoothed.unchanged(retimed)
        traj = result.trajectory
        ratios = limit_ratios(
            traj.t,
            names,
            {"velocity": traj.qd, "acceleration": traj.qdd, "jerk": result.jerk},
            {"velocity": v, "acceleration": a, "jerk": j},
            self.name,
        )
        hands = hand_positions(self.task, traj)
        hand_deviation = _distance_max(hands, hand_positions(self.task, traj, retimed.interpolate(traj.t)[0]))
        sink.trajectory(
            traj,
            {"velocity": v, "acceleration": a, "jerk": j},
            hands,
            {"jerk": result.jerk, "deviation_rad": result.deviation_rad},
        )
        return traj, {
            "smooth.duration_s": traj.duration_s,
            **{f"smooth.{kind}_ratio_max": r.ratio for kind, r in ratios.items()},
            "smooth.path_deviation_max_rad": result.path_deviation_max_rad,
            "smooth.hand_deviation_max_m": hand_deviation,
            "smooth.lookahead_max_s": float(result.lookahead_s.max()),
            "smooth.fallbacks": float(result.fallbacks),
        }

    def violations(self, traj: JointTrajectory) -> list[Violation]:
        """Position, velocity, acceleration and jerk limits."""
        return trajectory_violations(traj, self.task.robot, jerk=True)


@dataclass(frozen=True)
class ApproachStage:
    """The move from the task's initial configuration to the trajectory's start.

    It is jerk-limited within the task's full limits (:mod:`dualarm.smooth.approach`).

    Its product is the trajectory it was given, carrying the approach (``approach``) that the
    execute stage plays first; the approach is recorded on its own clock (``/approach``).
    """

    task: Task
    name: ClassVar[str] = "approach"

    def settings_record(self) -> dict[str, Any]:
        """The method, the limits it uses and its sample period [s]."""
        return {
            "method": (
                "straight line in joint space, jerk-limited timing (ruckig on the path parameter), "
                "time-optimal, rest to rest; where the line collides, through the waypoints of a "
                "collision-free path (RRT-Connect, seed 0), each segment so"
            ),
            "limits": "the task's full limits",
            "sample_period_s": CONTROL_PERIOD_S,
        }

    def __call__(self, traj: JointTrajectory, sink: Sink) -> tuple[JointTrajectory, dict[str, float]]:
        """Plan the approach: JointTrajectory -> the same JointTrajectory with its ``approach``."""
        from dualarm.smooth.approach import approach_trajectory, approach_waypoints

        sink.begin(self.name)
        names, robot = traj.joint_names, self.task.robot
        initial = np.array([self.task.initial_q[n] for n in names])
        limits = {kind: robot.limit_array(kind, names) for kind in ("velocity", "acceleration", "jerk")}
        waypoints = approach_waypoints(self.task, names, initial, traj.q[0], dict(traj.fixed))
        approach = approach_trajectory(
            names,
            initial,
            traj.q[0],
            limits["velocity"],
            limits["acceleration"],
            limits["jerk"],
            CONTROL_PERIOD_S,
            dict(traj.fixed),
            via=list(waypoints[1:-1]),
        )
        sink.trajectory(approach, limits, hand_positions(self.task, approach), {"jerk": approach.mean_jerk()})
        return replace(traj, approach=approach), {
            "approach.duration_s": approach.duration_s,
            "approach.joint_distance_max_rad": float(np.abs(traj.q[0] - initial).max()) if len(names) else 0.0,
        }

    def violations(self, traj: JointTrajectory) -> list[Violation]:
        """Position, velocity, acceleration and jerk limits of the approach."""
        return trajectory_violations(traj.approach, self.task.robot, jerk=True) if traj.approach is not None else []


@dataclass(frozen=True)
class ExecuteStage:
    """Validate the trajectory, then play it on the robot in PyBullet, in the task's environment.

    Before anything moves, the trajectory is checked against every limit and for collisions
    (:mod:`dualarm.execute.preflight`); a trajectory that fails is refused (a StageError naming
    the first violation) unless ``settings.execute_anyway``, in which case it is played and its
    violations count in the verdict. The tracking error is the distance between each measured hand
    position (PyBullet) and the forward kinematics (this project's) of the commanded joints at the
    same time. Collisions are counted in physics steps with an unexpected contact.
    """

    task: Task
    settings: ExecutionSettings
    checks: Checks = field(default_factory=Checks)
    name: ClassVar[str] = "execute"

    def settings_record(self) -> dict[str, Any]:
        """The simulation's settings and the bounds it is judged against."""
        return {**as_record(self.settings), "simulator": "pybullet", "tracking_bound_m": self.checks.tracking_bound_m}

    def __call__(self, traj: JointTrajectory, sink: Sink) -> tuple[ExecutionLog, dict[str, float]]:
        """Validate and play the trajectory in PyBullet: JointTrajectory -> ExecutionLog."""
        from dualarm.execute.preflight import preflight
        from dualarm.execute.simulate import execute_trajectory

        sink.begin(self.name)
        task = self.task
        found = preflight(traj, task)
        if found and not self.settings.execute_anyway:
            more = f" (and {len(found) - 1} more)" if len(found) > 1 else ""
            raise StageError(
                f"execute: refused to play the trajectory: {found[0].message}{more}; "
                "--execute-anyway plays it for diagnosis",
                stage=self.name,
                t_s=found[0].t_s,
                violations=tuple(found),
            )
        log = execute_trajectory(
            traj, task.robot, task.spec.hands, task.spec.environment, task.spec.expected_contacts, self.settings
        )
        approach = (
            replace(log.approach, hand_error_m=hand_errors(task, log.approach)) if log.approach is not None else None
        )
        log = replace(log, preflight=tuple(found), approach=approach, hand_error_m=hand_errors(task, log))
        sink.execution(log)
        all_errors = np.concatenate([np.zeros(0), *log.hand_error_m.values()])
        if not all_errors.size:  # a trajectory that does not move: no physics step
            all_errors = np.zeros(1)
        return log, {
            "execute.duration_s": float(log.t[-1]) if len(log.t) else 0.0,
            "execute.tracking_error_max_m": float(all_errors.max()),
            "execute.tracking_error_rmse_m": float(np.sqrt(np.mean(all_errors**2))),
            "execute.self_collisions": float((log.self_contacts > 0).sum()),
            "execute.environment_collisions": float((log.environment_contacts > 0).sum()),
            "execute.expected_contact_steps": float((log.expected_contacts > 0).sum()),
            "execute.contact_depth_max_m": max((c.depth_max_m for c in log.contacts if not c.expected), default=0.0),
            "execute.preflight_violations": float(len(found)),
        }

    def violations(self, log: ExecutionLog) -> list[Violation]:
        """What the preflight found, unexpected contacts and hands beyond the tracking bound.

        The preflight's findings are there for a trajectory played anyway.
        """
        approach = execution_violations(log.approach, self.checks, "approach") if log.approach is not None else []
        return [*log.preflight, *approach, *execution_violations(log, self.checks)]


def hand_errors(task: Task, log: ExecutionLog) -> dict[str, np.ndarray]:
    """Each hand's distance between its measured position and the commanded joints' forward kinematics [m].

    One distance per sample, (K,), for each hand.
    """
    if not len(log.t):  # nothing was played (a trajectory, or an approach, of no duration)
        return {hand: np.zeros(0) for hand in log.hand_poses}
    command = task.hand_poses(log.joint_names, log.q_command, log.fixed)
    return {hand: np.linalg.norm(log.hand_poses[hand][:, :3, 3] - command[hand][:, :3, 3], axis=1) for hand in command}


if TYPE_CHECKING:

    def _products(
        path: PathStage,
        ik: IkStage,
        plan: PlanStage,
        retime: RetimeStage,
        smooth: SmoothStage,
        approach: ApproachStage,
        execute: ExecuteStage,
    ) -> tuple[
        Stage[Task, CartesianReference],
        Stage[CartesianReference, JointPath],
        Stage[CartesianReference, JointPath],
        Stage[JointPath, JointTrajectory],
        Stage[JointTrajectory, JointTrajectory],
        Stage[JointTrajectory, JointTrajectory],
        Stage[JointTrajectory, ExecutionLog],
    ]:
        """Each stage is a :class:`Stage` of the products it takes and makes.

        Checked by mypy; never defined at run time.
        """
        return path, ik, plan, retime, smooth, approach, execute
