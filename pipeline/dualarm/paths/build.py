"""Task -> :class:`CartesianReference`.

Every move lasts a whole number of control periods and uses the quintic time scaling
s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5, tau = t / T, whose velocity and acceleration vanish at both
ends, so the hands stop at every waypoint. Lines interpolate the position linearly in s and the
orientation by slerp, R(s) = R0 exp(s log(R0^T R1)); arcs turn the position about an axis through a
centre with the orientation fixed. Repetitions repeat the moves; each sample carries its
repetition index. For a carried object the slave hand follows the master by MC-Inverse eq (11).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from dualarm.contracts.reference import CartesianReference, HandReference
from dualarm.errors import TaskFileError, UnreachablePoseError
from dualarm.model.poses import invert, pose_matrix
from dualarm.tasks.reach import arm_reach
from dualarm.tasks.schema import HandMove
from dualarm.tasks.task import Task

#: Largest gap between a repeated path's end and its start [m] and [rad].
CLOSURE_TOLERANCE = 1e-9


def quintic(tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Time scaling s(tau) and ds/dtau for tau in [0, 1]."""
    s = tau**3 * (10 - 15 * tau + 6 * tau**2)
    ds = 30 * tau**2 * (1 - tau) ** 2
    return s, ds


def _segment(move: HandMove | None, T0: np.ndarray, task: Task, tau: np.ndarray, duration: float):
    """Positions, rotations and velocities of one hand over one move, at normalised times tau."""
    n = len(tau)
    s, ds = quintic(tau)
    sdot = ds / duration
    p0, R0 = T0[:3, 3], T0[:3, :3]
    position = np.repeat(p0[None], n, axis=0)
    rotation = np.repeat(R0[None], n, axis=0)
    velocity = np.zeros((n, 3))
    omega = np.zeros((n, 3))
    if move is None or move.kind == "hold":
        return position, rotation, velocity, omega
    if move.to is not None or move.by is not None:
        if move.to is not None:
            T1 = task.waypoint_pose(move.to)
            p1, R1 = T1[:3, 3], T1[:3, :3]
        else:
            p1, R1 = p0 + np.asarray(move.by), R0
        position = p0 + s[:, None] * (p1 - p0)
        velocity = sdot[:, None] * (p1 - p0)
        phi = Rotation.from_matrix(R0.T @ R1).as_rotvec()
        rotation = R0 @ Rotation.from_rotvec(s[:, None] * phi).as_matrix()
        omega = sdot[:, None] * (R0 @ phi)  # R0 exp(s phi) turns about R0 phi at rate s'
        return position, rotation, velocity, omega
    arc_center, arc_angle = move.arc_center, move.arc_angle_rad
    assert arc_center is not None and arc_angle is not None  # HandMove validates an arc whole
    axis = np.asarray(move.arc_unit_axis)  # normalised without overflow, whatever the axis's length
    centre = np.asarray(arc_center)
    turn = Rotation.from_rotvec((s * arc_angle)[:, None] * axis)
    position = centre + turn.apply(p0 - centre)
    rate = sdot * arc_angle
    velocity = rate[:, None] * np.cross(axis, position - centre)
    return position, rotation, velocity, omega


def _slave_from_master(task: Task, master: HandReference) -> HandReference:
    """MC-Inverse eq (11): B_T_Tl Tl_T_obj = B_T_Tr Tr_T_obj, so T_r = T_l Tl_T_obj (Tr_T_obj)^-1."""
    obj = task.spec.object
    assert obj is not None  # called only for a task that carries an object
    relative = pose_matrix(obj.master_to_object.position, obj.master_to_object.rpy) @ invert(
        pose_matrix(obj.slave_to_object.position, obj.slave_to_object.rpy)
    )
    T = master.poses @ relative
    offset = T[:, :3, 3] - master.position
    return HandReference(
        position=T[:, :3, 3],
        rotation=T[:, :3, :3],
        linear_velocity=master.linear_velocity + np.cross(master.angular_velocity, offset),
        angular_velocity=master.angular_velocity,
    )


def _check_closed(task: Task, hand: str, ref: HandReference) -> None:
    gap = float(np.linalg.norm(ref.position[-1] - ref.position[0]))
    angle = float(np.linalg.norm(Rotation.from_matrix(ref.rotation[0].T @ ref.rotation[-1]).as_rotvec()))
    if gap > CLOSURE_TOLERANCE or angle > CLOSURE_TOLERANCE:
        raise TaskFileError(
            f"{task.where('moves')}: the {hand} hand ends {gap:.3g} m / {angle:.3g} rad away from its start, "
            f"so the path cannot be repeated {task.spec.repetitions} times (end each repetition where it starts)"
        )


def build_reference(task: Task) -> CartesianReference:
    """Sample the task's hand motions at its control period.

    The moves once, then again for each further repetition, the same samples bit for bit (a method that moves
    differently in one repetition does so on the very same targets).

    Raises:
        TaskFileError: a repeated path does not close on itself.
        UnreachablePoseError: a sample leaves a hand's workspace (names the move and time).
    """
    spec = task.spec
    period = spec.control_period_s
    driven = [h for h in spec.hands if not (spec.object is not None and h == spec.object.slave)]
    current = {h: task.start_pose(h) for h in driven}
    # per hand, a list of (position, rotation, linear velocity, angular velocity) pieces
    pieces = {h: [(T[None, :3, 3], T[None, :3, :3], np.zeros((1, 3)), np.zeros((1, 3)))] for h, T in current.items()}
    segment = []
    for i, move in enumerate(spec.moves):  # one repetition: the others are copies of it, the same targets bit for bit
        steps = int(round(move.duration_s / period))
        tau = np.arange(1, steps + 1) / steps
        for h in driven:
            piece = _segment(move.for_hand(h), current[h], task, tau, move.duration_s)
            pieces[h].append(piece)
            current[h] = np.eye(4)
            current[h][:3, :3], current[h][:3, 3] = piece[1][-1], piece[0][-1]
        segment.append(np.full(steps, i))
    reps = spec.repetitions
    hands = {
        h: HandReference(*(np.concatenate([start, *(moves * reps)]) for start, *moves in zip(*pieces[h], strict=True)))
        for h in driven
    }
    if spec.object is not None:
        hands[spec.object.slave] = _slave_from_master(task, hands[spec.object.master])
    once = np.concatenate(segment) if segment else np.zeros(0, int)  # a task without moves: its start alone
    rep_index = np.r_[0, np.repeat(np.arange(reps), len(once))]
    seg_index = np.r_[0, np.tile(once, reps)]
    n = len(rep_index)
    if spec.repetitions > 1:
        for h in driven:
            _check_closed(task, h, hands[h])
    for h, ref in hands.items():
        reach = arm_reach(task, h)
        ok = reach.within(ref.poses)
        if not ok.all():
            k = int(np.argmin(ok))
            raise UnreachablePoseError(
                f"{task.where(f'moves[{seg_index[k]}]')}: at t = {k * period:.3f} s (repetition {rep_index[k]}) "
                f"{reach.explain(ref.poses[k])}"
            )
    return CartesianReference(
        task=task.name,
        frame=task.robot.urdf.root,
        period_s=period,
        t=np.arange(n) * period,
        rep=rep_index,
        segment=seg_index,
        hands={h: hands[h] for h in spec.hands},
    )
