"""The back half of the pipeline as stages: joint path -> retimed -> smoothed -> executed.

Each stage takes the previous stage's product and the task, hands its own product to the
recorder once, and returns it with its metrics (``<stage>.<name>`` keys, unit as suffix). Limit
ratios are always taken against the task's full limits (the robot's, or the task's own where it
tightens them).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from pipeline.ik.joint_path import JointPath
from pipeline.record.recorder import Recorder
from pipeline.retime.topp import limit_ratios as retime_ratios
from pipeline.retime.topp import retime
from pipeline.retime.trajectory import JointTrajectory
from pipeline.smooth.tracking import limit_ratios as smooth_ratios
from pipeline.smooth.tracking import smooth
from pipeline.tasks import Task

if TYPE_CHECKING:
    from pipeline.execute.simulate import ExecutionLog, ExecutionSettings

#: Sample period of the retimed trajectory and control period of the smooth stage [s].
CONTROL_PERIOD_S = 0.001


def hand_positions(task: Task, traj: JointTrajectory, q: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Each driven hand's position (M, 3) [m] by forward kinematics of ``q`` (default ``traj.q``)."""
    poses = task.hand_poses(traj.joint_names, traj.q if q is None else q, traj.fixed)
    return {hand: T[:, :3, 3] for hand, T in poses.items()}


def retime_stage(task: Task, path: JointPath, recorder: Recorder, timing: str | None = None) -> tuple[JointTrajectory, dict[str, float]]:
    """Time the joint path (``timing``: ``optimal`` or ``task``; default the task file's).

    Time-optimal retiming uses the task's ``retime.velocity_fraction`` and
    ``retime.acceleration_fraction`` of the limits (headroom for the smooth stage); the task's
    own timing is checked against the full limits.
    """
    settings = task.spec.retime
    timing = timing or settings.timing
    names = path.joint_names
    v, a = task.velocity_limits(names), task.acceleration_limits(names)
    if timing == "task":
        result = retime(path, v, a, sample_period_s=CONTROL_PERIOD_S, keep_timing=True)
    else:
        result = retime(path, settings.velocity_fraction * v, settings.acceleration_fraction * a, sample_period_s=CONTROL_PERIOD_S)
    traj = result.trajectory
    ratios = retime_ratios(traj, v, a)
    recorder.trajectory(traj, {"velocity": v, "acceleration": a}, hand_positions(task, traj))
    return traj, {
        "retime.duration_s": traj.duration_s,
        "retime.velocity_ratio_max": ratios.velocity_ratio_max,
        "retime.acceleration_ratio_max": ratios.acceleration_ratio_max,
        "retime.path_deviation_max_rad": result.path_deviation_max_rad,
        "retime.stretch": result.stretch,
    }


def smooth_stage(task: Task, retimed: JointTrajectory, recorder: Recorder) -> tuple[JointTrajectory, dict[str, float]]:
    """Track the retimed trajectory with jerk-limited motion (Ruckig, every :data:`CONTROL_PERIOD_S`).

    Besides the limit ratios, records how far it departs from the retimed trajectory at the same
    time: per joint [rad] and at the hands [m].
    """
    names = retimed.joint_names
    v, a, j = task.velocity_limits(names), task.acceleration_limits(names), task.jerk_limits(names)
    result = smooth(retimed, v, a, j, period_s=CONTROL_PERIOD_S)
    traj = result.trajectory
    ratios = smooth_ratios(traj, result.jerk, v, a, j)
    hands = hand_positions(task, traj)
    reference = hand_positions(task, traj, retimed.interpolate(traj.t)[0])
    hand_deviation = max((float(np.linalg.norm(hands[h] - reference[h], axis=1).max()) for h in hands), default=0.0)
    recorder.trajectory(traj, {"velocity": v, "acceleration": a, "jerk": j}, hands, {"jerk": result.jerk, "deviation_rad": result.deviation_rad})
    return traj, {
        "smooth.duration_s": traj.duration_s,
        **{f"smooth.{key}": value for key, value in ratios.items()},
        "smooth.path_deviation_max_rad": result.path_deviation_max_rad,
        "smooth.hand_deviation_max_m": hand_deviation,
        "smooth.lookahead_max_s": float(result.lookahead_s.max()),
        "smooth.fallbacks": float(result.fallbacks),
    }


def execute_stage(task: Task, traj: JointTrajectory, recorder: Recorder, settings: "ExecutionSettings") -> tuple["ExecutionLog", dict[str, float]]:
    """Play the trajectory on the robot in PyBullet, in the task's environment.

    The tracking error is the distance between each measured hand position (PyBullet) and the
    forward kinematics (this project's) of the commanded joints at the same time. Collisions are
    counted in physics steps with an unexpected contact.
    """
    from pipeline.execute.simulate import execute

    expected = {tuple(sorted(pair)) for pair in task.spec.expected_contacts}
    log = execute(traj, task.robot, task.spec.hands, task.spec.environment, expected, settings)
    command = task.hand_poses(log.joint_names, log.q_command, log.fixed)
    errors = {hand: np.linalg.norm(log.hand_poses[hand][:, :3, 3] - command[hand][:, :3, 3], axis=1) for hand in command}
    recorder.execution(log, errors, expected)
    all_errors = np.concatenate([np.zeros(0), *errors.values()])
    if not all_errors.size:  # a trajectory that does not move: no physics step
        all_errors = np.zeros(1)
    return log, {
        "execute.duration_s": float(log.t[-1]) if len(log.t) else 0.0,
        "execute.tracking_error_max_m": float(all_errors.max()),
        "execute.tracking_error_rmse_m": float(np.sqrt(np.mean(all_errors**2))),
        "execute.self_collisions": float((log.self_contacts > 0).sum()),
        "execute.environment_collisions": float((log.environment_contacts > 0).sum()),
        "execute.expected_contact_steps": float((log.expected_contacts > 0).sum()),
    }
