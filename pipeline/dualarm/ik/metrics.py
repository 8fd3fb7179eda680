"""``ik.*`` metrics of a JointPath (keys of DESIGN.md, units in the suffix)."""

from __future__ import annotations

import numpy as np

from dualarm.contracts.joint_path import JointPath
from dualarm.contracts.reference import CartesianReference, first_repetition_index
from dualarm.errors import NotSRSError
from dualarm.model.robot import Robot
from dualarm.model.srs import SrsKinematics

#: Slack allowed before a joint position or velocity counts as a violation [rad] / [rad/s].
VIOLATION_TOLERANCE = 1e-9
#: Largest hand pose difference [m, and rotation matrix entries] between repetition ends for a
#: path to count as closed.
CLOSED_TOLERANCE_M = 1e-9


def ik_metrics(path: JointPath, robot: Robot) -> dict[str, float]:
    """Hand position errors, limit violations, the largest joint step, solve times, failures.

    Hand position errors: norms over samples and hands; limit violations against the robot's position and velocity
    limits (a task's overrides applied).

    A violation is one (sample, joint) pair outside its limit by more than
    :data:`VIOLATION_TOLERANCE`. Orientation (when the path measured it, which every IK method's
    does): ``orientation_error_max_rad`` and ``_mean_rad`` over samples and hands, the angle of
    R_asked^T R_reached; ``orientation_solved`` 1.0 when the method solved the asked orientation,
    0.0 when it solved positions only (TV-GDD and pinv in ``position`` task space).
    """
    names = path.joint_names
    lower, upper = robot.lower_upper(names)
    vmax = robot.limit_array("velocity", names)
    error = path.hand_error_m
    steps = np.abs(np.diff(path.q, axis=0))
    return {
        "ik.position_error_max_m": float(error.max()),
        "ik.position_error_mean_m": float(error.mean()),
        "ik.position_error_rmse_m": float(np.sqrt((error**2).mean())),
        "ik.joint_limit_violations": float(
            ((path.q < lower - VIOLATION_TOLERANCE) | (path.q > upper + VIOLATION_TOLERANCE)).sum()
        ),
        "ik.velocity_limit_violations": float((np.abs(path.qd) > vmax + VIOLATION_TOLERANCE).sum()),
        "ik.max_joint_step_rad": float(steps.max()) if len(steps) else 0.0,
        "ik.solve_time_mean_s": float(path.solve_time_s.mean()),
        "ik.solve_time_median_s": float(np.median(path.solve_time_s)),
        "ik.solve_time_total_s": float(path.solve_time_s.sum()),
        "ik.failures": float((path.status != 0).sum()),
        **_orientation_metrics(path),
    }


def condition_metrics(path: JointPath, robot: Robot) -> dict[str, float]:
    """Where along the path the arms are: the least joint-limit margin and the least manipulability.

    ``ik.joint_limit_margin_min_rad``, the least distance of a joint to its nearer position limit over the samples
    and joints (negative beyond a limit; joints without limits left out), and ``ik.manipulability_min``, the least
    Yoshikawa manipulability sqrt(det(J J^T)), the product of J's singular values, over the samples and the hands
    whose arm joints are all in the path (J the arm chain's 6 x n geometric Jacobian, rows [v; w]: m^3 per rad^3
    of the linear rows). A study's report bins P(inconsistent) by both.
    """
    from dualarm.model.kinematics import ChainKinematics

    lower, upper = robot.lower_upper(path.joint_names)
    margin = np.minimum(path.q - lower, upper - path.q)
    bounded = np.isfinite(margin).all(axis=0)
    metrics = (
        {"ik.joint_limit_margin_min_rad": float(margin[:, bounded].min())} if bounded.any() and len(path.q) else {}
    )
    least = []
    for hand in path.hands:
        chain = robot.hand_chain(hand)
        if not set(chain.joint_names) <= set(path.joint_names):
            continue
        J = ChainKinematics.of(chain).jacobians(path.q[:, [path.joint_names.index(n) for n in chain.joint_names]])
        least.append(float(np.sqrt(np.clip(np.linalg.det(J @ J.transpose(0, 2, 1)), 0.0, None)).min()))
    if least:
        metrics["ik.manipulability_min"] = min(least)
    return metrics


def _orientation_metrics(path: JointPath) -> dict[str, float]:
    """``ik.orientation_*`` of :func:`ik_metrics`; the errors only when measured (not NaN)."""
    angle = path.hand_orientation_error_rad
    metrics = {"ik.orientation_solved": 1.0 if path.task_space == "pose" else 0.0}
    if angle.size and np.isfinite(angle).all():
        metrics |= {
            "ik.orientation_error_max_rad": float(angle.max()),
            "ik.orientation_error_mean_rad": float(angle.mean()),
        }
    return metrics


def arm_angles(
    path: JointPath, robot: Robot, vertical: tuple[float, float, float] = (0.0, 0.0, 1.0)
) -> dict[str, np.ndarray]:
    """The arm angle per hand of the path along it (N,) [rad].

    psi of eq (1) of MC-Inverse, with V = ``vertical`` in each arm's base frame, on an S-R-S arm; on another arm of
    a SEW family the stereographic SEW angle that ``--ik sew`` holds or schedules
    (:func:`dualarm.ik.analytic.sew.SewAngle.stereographic` of ``vertical``). Hands whose arm joints are not all in
    the path, or whose arm has neither, are left out.
    """
    return joint_arm_angles(robot, path.hands, path.joint_names, path.q, vertical)


def joint_arm_angles(
    robot: Robot,
    hands: tuple[str, ...],
    joint_names: tuple[str, ...],
    q: np.ndarray,
    vertical: tuple[float, float, float] = (0.0, 0.0, 1.0),
) -> dict[str, np.ndarray]:
    """The arm angles of :func:`arm_angles` at configurations ``q`` (N, len(joint_names)) [rad], per hand."""
    from dualarm.ik.analytic.sew import SewAngle
    from dualarm.model.sew import sew_chain

    v = np.asarray(vertical, dtype=float) / np.linalg.norm(vertical)
    angles = {}
    for hand in hands:
        chain = robot.hand_chain(hand)
        if not set(chain.joint_names) <= set(joint_names):
            continue
        q_arm = q[:, [joint_names.index(n) for n in chain.joint_names]]
        try:
            angles[hand] = SrsKinematics.of(chain, tuple(v)).arm_angles(q_arm)
        except NotSRSError:
            try:
                angles[hand] = SewAngle.stereographic(v).angle(*sew_chain(chain).points(q_arm))
            except NotSRSError:
                continue
    return angles


def consistency_metrics(
    path: JointPath, reference: CartesianReference, angles: dict[str, np.ndarray]
) -> dict[str, float]:
    """``ik.*`` consistency across repetitions (DESIGN.md; rep 0 is the reference).

    For a path of two or more repetitions, with the hands' arm angles ``angles`` (see :func:`arm_angles`) [rad].

    - ``failed_reps``: repetitions with a failed sample.
    - ``rep_joint_deviation_max_rad``: largest |q_r - q_0| between samples at the same place of
      repetition r and the first, where both succeeded.
    - ``rep_arm_angle_deviation_max_rad``: the same for every hand's arm angle (wrapped).
    - ``closure_error_max_rad``: when the hands' path ends each repetition where it began, the
      largest joint difference between a repetition's last sample and its first (the previous
      repetition's last).
    """
    reps = np.unique(path.rep)
    if len(reps) < 2:
        return {}
    index = first_repetition_index(path.t, path.rep, reference.period_s)
    first = np.flatnonzero(path.rep == reps[0])
    later = np.flatnonzero(path.rep != reps[0])
    match = first[np.clip(index[later], 0, len(first) - 1)]
    both = (path.status[later] == 0) & (path.status[match] == 0)
    a, b = later[both], match[both]
    metrics = {"ik.failed_reps": float(sum(bool((path.status[path.rep == r] != 0).any()) for r in reps))}
    if a.size:
        metrics["ik.rep_joint_deviation_max_rad"] = float(np.abs(path.q[a] - path.q[b]).max())
        if angles:
            metrics["ik.rep_arm_angle_deviation_max_rad"] = float(
                max(np.abs(np.angle(np.exp(1j * (psi[a] - psi[b])))).max() for psi in angles.values())
            )
    ends = np.array([0, *[np.flatnonzero(path.rep == r)[-1] for r in reps]])
    poses = np.stack([h.poses[ends] for h in reference.hands.values()])
    if np.abs(poses - poses[:, :1]).max() < CLOSED_TOLERANCE_M:
        metrics["ik.closure_error_max_rad"] = float(np.abs(np.diff(path.q[ends], axis=0)).max())
    return metrics


def repetition_deviation(path: JointPath, reference: CartesianReference) -> float:
    """The largest change of any joint between a repetition and the first, at the same place [rad].

    ``ik.rep_joint_deviation_max_rad`` of :func:`consistency_metrics` (what ``dualarm run`` records and the MC-Inverse
    paper's consistency claims compare): over the samples solved in both; NaN for fewer than two repetitions or
    when no sample was solved in two.
    """
    return consistency_metrics(path, reference, {}).get("ik.rep_joint_deviation_max_rad", float("nan"))
