"""A run's verdict: ``complete``, ``violated`` or ``failed``.

``complete`` (every check passed), ``violated`` (the run finished, but a check failed) or ``failed`` (a stage
could not produce its output).

The checks, each naming where and when it failed (a :class:`Violation`):

- IK (the ``ik`` stage's joint path): a sample the method failed; a hand off the asked position
  by more than :attr:`Checks.ik_position_tolerance_m`, or off the asked orientation by more than
  :attr:`Checks.ik_orientation_tolerance_rad` when the method was asked for it (TV-GDD and pinv
  in a task's ``position`` task space are not); a joint outside its position limits; when no
  retime stage follows (the joint path is the motion), a joint velocity above its limit.
- Limits of the trajectories (retime: position, velocity, acceleration; smooth and whatever is
  executed: jerk too): a ratio above 1 + :data:`~dualarm.limits.LIMIT_TOLERANCE`, naming the
  joint, the quantity and the time.
- Execution: an unexpected contact (not in the task's ``expected_contacts``), naming the pair,
  the first time and the deepest penetration; a hand whose measured position departs from the
  commanded one by more than :attr:`Checks.tracking_bound_m`.

Exit codes of the command line follow the verdict (:data:`EXIT_CODES`): 0 complete, 3 violated,
1 failed; 2 is a user's mistake, found before anything runs.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np

from dualarm.contracts.joint_path import JointPath
from dualarm.contracts.trajectory import JointTrajectory
from dualarm.contracts.verdict import Checks, Violation
from dualarm.limits import LIMIT_TOLERANCE, limit_ratios
from dualarm.model.robot import Robot

if TYPE_CHECKING:
    from dualarm.contracts.execution import ExecutionLog


def _at(t: float, rep: int | None = None) -> str:
    return f"t = {t:.3f} s" + (f" (rep {rep})" if rep is not None else "")


def position_limit_violations(
    stage: str, t: np.ndarray, names: Sequence[str], q: np.ndarray, robot: Robot
) -> list[Violation]:
    """The first sample of ``q`` (M, n) [rad] outside a joint's position limits, if any.

    Outside by more than :data:`LIMIT_TOLERANCE` of its range.
    """
    lower, upper = robot.lower_upper(tuple(names))
    slack = LIMIT_TOLERANCE * (upper - lower)
    outside = (q < lower - slack) | (q > upper + slack)
    if not outside.any():
        return []
    k, j = np.argwhere(outside)[0]
    beyond = max(lower[j] - q[k, j], q[k, j] - upper[j])
    return [
        Violation(
            "limit",
            stage,
            f"{stage}: position of {names[j]} {beyond:.3g} rad beyond its limits [{lower[j]:.4g}, {upper[j]:.4g}] "
            f"at {_at(t[k])}",
            float(t[k]),
        )
    ]


def ratio_violations(
    stage: str,
    t: np.ndarray,
    names: Sequence[str],
    samples: Mapping[str, np.ndarray],
    limits: Mapping[str, np.ndarray],
    robot: Robot | None = None,
) -> list[Violation]:
    """A violation for each kind whose largest limit ratio exceeds 1 + :data:`LIMIT_TOLERANCE`.

    The kinds: velocity, acceleration, jerk. With ``robot``, a limit it assumed says so (:meth:`Robot.assumed`).
    """
    ratios = limit_ratios(t, names, samples, limits, stage)
    return [
        Violation(
            "limit",
            stage,
            f"{stage}: {r.kind} of {r.joint} at {r.ratio:.4g}x its limit at {_at(r.t_s)}"
            + (robot.assumed(r.kind) if robot else ""),
            r.t_s,
        )
        for r in ratios.values()
        if r.exceeded
    ]


def trajectory_violations(traj: JointTrajectory, robot: Robot, *, jerk: bool) -> list[Violation]:
    """Position, velocity, acceleration and (with ``jerk``) jerk limits of a trajectory.

    The jerk is the mean jerk over each sample period.
    """
    names = traj.joint_names
    samples = {
        "velocity": traj.qd,
        "acceleration": traj.qdd,
        **({"jerk": traj.mean_jerk()} if jerk else {}),
    }  # the jerk as the smooth stage reports it
    limits = {kind: robot.limit_array(kind, names) for kind in samples}
    return position_limit_violations(traj.stage, traj.t, names, traj.q, robot) + ratio_violations(
        traj.stage, traj.t, names, samples, limits, robot
    )


def ik_violations(path: JointPath, robot: Robot, checks: Checks, *, retimed: bool) -> list[Violation]:
    """The IK checks of the module docstring on a joint path.

    Its orientation error counts when the method solved the pose (``task_space`` ``pose``) and measured it.
    """
    stage = "ik"
    out = []
    failed = np.flatnonzero(path.status != 0)
    if len(failed):
        k = int(failed[0])
        out.append(
            Violation(
                "ik",
                stage,
                f"ik ({path.method}): {len(failed)} of {len(path)} samples failed, "
                f"the first at {_at(path.t[k], int(path.rep[k]))}",
                float(path.t[k]),
            )
        )
    errors = [("position", path.hand_error_m, checks.ik_position_tolerance_m, 1e3, "mm")]
    if path.task_space == "pose":  # NaN where it was not measured: never beyond the tolerance
        errors.append(("orientation", path.hand_orientation_error_rad, checks.ik_orientation_tolerance_rad, 1.0, "rad"))
    ok = path.status == 0
    for what, error, tolerance, scale, unit in errors:
        beyond = (error > tolerance) & ok[:, None]
        if beyond.any():
            k, h = np.argwhere(beyond)[0]
            worst = float(np.nanmax(error[ok]))
            out.append(
                Violation(
                    "ik",
                    stage,
                    f"ik ({path.method}): {path.hands[h]} hand {error[k, h] * scale:.3g} {unit} off the asked {what} "
                    f"at {_at(path.t[k], int(path.rep[k]))} "
                    f"(tolerance {tolerance * scale:.3g} {unit}; worst {worst * scale:.3g} {unit}; "
                    f"{int(beyond.any(axis=1).sum())} samples)",
                    float(path.t[k]),
                )
            )
    out += position_limit_violations(
        stage, path.t[ok], path.joint_names, path.q[ok], robot
    )  # a failed sample holds its last solution
    if not retimed and len(path) > 1:
        out += ratio_violations(
            stage,
            path.t,
            path.joint_names,
            {"velocity": path.qd},
            {"velocity": robot.limit_array("velocity", path.joint_names)},
            robot,
        )
    return out


def execution_violations(log: ExecutionLog, checks: Checks, part: str = "execute") -> list[Violation]:
    """Unexpected contacts and hands beyond the tracking bound.

    Each contact pair: its first time, its deepest penetration, its steps. ``part`` names what was played
    (``execute``, or ``approach`` for the approach's log).
    """
    out = []
    for c in log.contacts:
        if not c.expected:
            out.append(
                Violation(
                    "contact",
                    part,
                    f"{part}: {c.first} touched {c.second} at {_at(c.first_t_s)}, "
                    f"{c.depth_max_m * 1e3:.3g} mm deep at most, in {c.steps} steps",
                    c.first_t_s,
                )
            )
    for hand, error in log.hand_error_m.items():
        beyond = np.flatnonzero(error > checks.tracking_bound_m)
        if len(beyond):
            k = int(beyond[0])
            out.append(
                Violation(
                    "tracking",
                    part,
                    f"{part}: {hand} hand {error[k] * 1e3:.3g} mm from its command at {_at(log.t[k], int(log.rep[k]))} "
                    f"(bound {checks.tracking_bound_m * 1e3:.3g} mm; worst {error.max() * 1e3:.3g} mm; "
                    f"{len(beyond)} steps)",
                    float(log.t[k]),
                )
            )
    return sorted(out, key=lambda v: v.t_s if v.t_s is not None else np.inf)
