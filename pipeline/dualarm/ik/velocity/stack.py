"""The hands of a task stacked over the task's active joints.

The active joints are the arm joints of every hand the task drives, plus the waist when the task
frees it; locked joints keep their initial values. Hand positions are in the robot base frame, so
a free waist is shared by both hands' Jacobians (Li-Liang's 17-DOF model); with the waist locked
the Jacobian is block diagonal, as in TV-GDD eq (13).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType

import casadi as cs
import numpy as np

from dualarm.arrays import frozen
from dualarm.contracts.joint_path import JointPath, TaskSpace, check_task_space
from dualarm.contracts.reference import CartesianReference
from dualarm.errors import StageError
from dualarm.ik.orientation import angular_jacobian, orientation_error, orientation_errors
from dualarm.model.kinematics import ChainKinematics
from dualarm.model.robot import Robot


@dataclass(frozen=True)
class HandStack:
    """Stacked hand kinematics and the task the velocity-level methods solve on them.

    The task rows are the hands' positions (3 per hand) and, in ``pose`` task space, under them
    their orientations (3 per hand): the equality of TV-GDD eq (24) and of the pseudoinverse's
    eqs (2)-(3) reads J thetadot = rdot + K e with

        J = [J_p; J_omega],  rdot = [v_d; omega_d],  e = [r_d - f(theta); log(R_d R(theta)^T)],

    the angular velocities and the orientation errors (rotation vectors) in the stack's frame.

    Attributes:
        joint_names: the active joints, the order of the vector theta.
        hands: the hands, the order of the stacked rows.
        fixed: values of the locked joints [rad].
        initial: the task's initial values of the active joints [rad], (n,).
        task_space: ``pose`` (positions and orientations) or ``position`` (positions only, the
            TV-GDD paper's m = 3 per hand, eq 13).
        theta: the CasADi symbol of the active joints, (n, 1).
        target: the CasADi symbol of one reference sample, (:attr:`reference_size`, 1): the hands'
            positions [m], then (pose) their rotation matrices, row by row.
        position: SX expression of the stacked hand positions, (3 h, 1) [m].
        rotation: SX expression of the stacked hand rotation matrices, (3 h, 3).
        error: SX expression of the task error e(theta, target), (m, 1) [m; rad].
        jacobian: SX expression of the task Jacobian [J_p; J_omega], (m, n).
        positions: Function ``theta -> position``.
        rotations: Function ``theta -> rotation``.
        errors: Function ``(theta, target) -> error``.
    """

    joint_names: tuple[str, ...]
    hands: tuple[str, ...]
    fixed: Mapping[str, float]
    initial: np.ndarray
    task_space: TaskSpace
    theta: cs.SX
    target: cs.SX
    position: cs.SX
    rotation: cs.SX
    error: cs.SX
    jacobian: cs.SX
    positions: cs.Function
    rotations: cs.Function
    errors: cs.Function

    @functools.cached_property
    def start_solver(self) -> cs.Function:
        """IPOPT's problem of :func:`start_configuration`, built once per stack.

        min |theta - initial|^2 s.t. e(theta, p) = 0, the first reference sample p its parameter.
        """
        nlp = {"x": self.theta, "p": self.target, "f": cs.sumsqr(self.theta - self.initial), "g": self.error}
        options = {
            "print_time": False,
            "ipopt": {"print_level": 0, "sb": "yes", "tol": 1e-12, "constr_viol_tol": 1e-12},
        }
        return cs.nlpsol("start_configuration", "ipopt", nlp, options)

    @property
    def n(self) -> int:
        """Number of active joints."""
        return len(self.joint_names)

    @property
    def m(self) -> int:
        """Number of stacked task rows: 3 per hand, 6 per hand in pose task space."""
        return (6 if self.task_space == "pose" else 3) * len(self.hands)

    @property
    def reference_size(self) -> int:
        """Length of one reference sample (:attr:`target`): 3 per hand, 12 per hand in pose task space."""
        return (12 if self.task_space == "pose" else 3) * len(self.hands)


def active_joints(robot: Robot, hands: Sequence[str], frame: str, free_waist: bool) -> tuple[str, ...]:
    """The active joints, in URDF order.

    The joints from ``frame`` to each hand's tip that belong to its arm chain, plus the others on the way (the
    waist) when ``free_waist``.
    """
    names: list[str] = []
    for hand in hands:
        arm = set(robot.hand_chain(hand).joint_names)
        for name in robot.chain_between(frame, robot.hand_chain(hand).tip).joint_names:
            if name not in names and (name in arm or free_waist):
                names.append(name)
    return tuple(names)


#: Most hand stacks a process keeps (:func:`hand_stack`).
KEPT_STACKS = 32


def hand_stack(
    robot: Robot,
    hands: Sequence[str],
    q0: Mapping[str, float],
    *,
    frame: str | None = None,
    free_waist: bool = False,
    task_space: TaskSpace = "position",
) -> HandStack:
    """The stacked kinematics of ``hands`` in ``frame`` (default the robot's root link).

    The joints that are not active at their values in ``q0`` [rad], with the task rows of ``task_space``
    (``position`` or ``pose``).

    Built once per robot and arguments in a process, then kept (a study's worker builds it once, not per trial).

    Raises:
        InvalidArgumentError: an unknown task space.
    """
    check_task_space(task_space)
    return _stack(robot, tuple(hands), tuple(q0.items()), frame or robot.urdf.root, free_waist, task_space)


@functools.lru_cache(maxsize=KEPT_STACKS)
def _stack(
    robot: Robot,
    hands: tuple[str, ...],
    q0_items: tuple[tuple[str, float], ...],
    frame: str,
    free_waist: bool,
    task_space: TaskSpace,
) -> HandStack:
    """Build :func:`hand_stack`'s stack."""
    q0 = dict(q0_items)
    names = active_joints(robot, hands, frame, free_waist)
    fixed = {n: v for n, v in q0.items() if n not in names}
    theta = cs.SX.sym("theta", len(names))
    index = {n: i for i, n in enumerate(names)}
    poses = []
    for hand in hands:
        chain = robot.chain_between(frame, robot.hand_chain(hand).tip)
        q = cs.vertcat(*[theta[index[n]] if n in index else fixed[n] for n in chain.joint_names])
        poses.append(ChainKinematics.of(chain).fk(q))
    h = len(hands)
    position = cs.vertcat(*[T[:3, 3] for T in poses])
    rotations = [T[:3, :3] for T in poses]
    pose = task_space == "pose"
    target = cs.SX.sym("target", (12 if pose else 3) * h)
    error = target[: 3 * h] - position  # eq (16)
    jacobian = cs.jacobian(position, theta)
    if pose:
        asked = [cs.reshape(target[3 * h + 9 * j : 3 * h + 9 * (j + 1)], 3, 3).T for j in range(h)]  # row by row
        error = cs.vertcat(error, *[orientation_error(Rd, R) for Rd, R in zip(asked, rotations, strict=True)])
        jacobian = cs.vertcat(jacobian, *[angular_jacobian(R, theta) for R in rotations])
    rotation = cs.vertcat(*rotations)
    return HandStack(
        joint_names=names,
        hands=tuple(hands),
        fixed=MappingProxyType(fixed),
        initial=frozen([q0[n] for n in names], (len(names),), "initial"),
        task_space=task_space,
        theta=theta,
        target=target,
        position=position,
        rotation=rotation,
        error=error,
        jacobian=jacobian,
        positions=cs.Function("hand_positions", [theta], [position], ["theta"], ["r"]),
        rotations=cs.Function("hand_rotations", [theta], [rotation], ["theta"], ["R"]),
        errors=cs.Function("task_errors", [theta, target], [error], ["theta", "target"], ["e"]),
    )


def reference_stack(
    robot: Robot,
    reference: CartesianReference,
    q0: Mapping[str, float] | str | None,
    free_waist: bool,
    task_space: TaskSpace = "position",
) -> HandStack:
    """The stack of the reference's hands in its frame, with the task rows of ``task_space``.

    ``q0`` resolved by :meth:`Robot.configuration`.
    """
    return hand_stack(
        robot,
        tuple(reference.hands),
        robot.configuration(q0, "q0"),
        frame=reference.frame_in(robot),
        free_waist=free_waist,
        task_space=task_space,
    )


def stacked_reference(stack: HandStack, reference: CartesianReference) -> tuple[np.ndarray, np.ndarray]:
    """A CartesianReference as the stack's targets (N, reference_size) and task velocities (N, m).

    Targets: the hands' positions [m], then (pose) their rotation matrices row by row.
    Velocities: the hands' linear velocities [m/s], then (pose) their angular velocities [rad/s].
    """
    hands = [reference.hands[h] for h in stack.hands]
    N = len(reference)
    target = [h.position for h in hands]
    velocity = [h.linear_velocity for h in hands]
    if stack.task_space == "pose":
        target += [h.rotation.reshape(N, 9) for h in hands]
        velocity += [h.angular_velocity for h in hands]
    return np.hstack(target), np.hstack(velocity)


#: Largest hand-position gap [m] between the initial configuration and the path start left as is.
START_TOLERANCE_M = 1e-9
#: Largest hand-orientation gap [rad] left as is (pose task space).
START_TOLERANCE_RAD = 1e-9
#: IPOPT starts drawn uniformly within the limits when the one from the initial configuration fails, and their seed.
START_SEEDS = 8
START_SEED = 0


def start_configuration(
    stack: HandStack, reference: CartesianReference, lower: np.ndarray, upper: np.ndarray
) -> np.ndarray:
    """Where a velocity-level method starts [rad], (n,).

    The task's initial values if they put the hands on the reference's first sample (within
    :data:`START_TOLERANCE_M`, and :data:`START_TOLERANCE_RAD` in pose task space), otherwise the configuration
    nearest to them, within ``lower``/``upper`` [rad], that does — the least-squares problem
    min |theta - initial|^2 s.t. e(theta) = 0 (the stack's task error at the first sample) solved by IPOPT through
    CasADi, from the initial values. IPOPT is local: where it fails from there (a start far from the path's, on a
    robot the task was not written for), it is run from :data:`START_SEEDS` configurations drawn within the limits
    (seed :data:`START_SEED`), and the solution nearest the initial values is kept.

    Raises:
        StageError: IPOPT finds no such configuration from any start.
    """
    r0 = stacked_reference(stack, reference)[0][0]
    if _on_start(stack, stack.initial, r0):
        return stack.initial
    solver = stack.start_solver

    def solve(x0: np.ndarray) -> tuple[np.ndarray, bool, str]:
        theta = np.asarray(solver(x0=x0, p=r0, lbx=lower, ubx=upper, lbg=0, ubg=0)["x"]).ravel()
        return theta, bool(solver.stats()["success"]) and _on_start(stack, theta, r0), solver.stats()["return_status"]

    theta, solved, status = solve(stack.initial)
    if not solved:  # a local solver from one start: IPOPT from START_SEEDS more, the solution nearest the initial kept
        low, high = np.clip(lower, -np.pi, np.pi), np.clip(upper, -np.pi, np.pi)  # continuous joints: one turn
        starts = np.random.default_rng(START_SEED).uniform(low, high, (START_SEEDS, stack.n))
        found = [theta for theta, ok, _ in map(solve, starts) if ok]
        if found:
            theta, solved = min(found, key=lambda t: float(np.sum((t - stack.initial) ** 2))), True
    if not solved:
        e = np.abs(np.asarray(stack.errors(theta, r0)).ravel())
        p = 3 * len(stack.hands)
        gap = f"gap {e[:p].max():.3g} m" + (f", {e[p:].max():.3g} rad" if len(e) > p else "")
        what = "the hands on the path start" + (" in position and orientation" if stack.task_space == "pose" else "")
        raise StageError(
            f"no configuration within the joint limits puts {what} (IPOPT from the initial configuration and "
            f"{START_SEEDS} more starts; from the initial: {status}, {gap})",
            stage="ik",
            sample=0,
            t_s=0.0,
        )
    return frozen(theta, (stack.n,), "start")


def _on_start(stack: HandStack, theta: np.ndarray, target: np.ndarray) -> bool:
    """Whether the task error at ``theta`` is within the start tolerances.

    :data:`START_TOLERANCE_M` (positions) and :data:`START_TOLERANCE_RAD` (orientations).
    """
    e = np.abs(np.asarray(stack.errors(theta, target)).ravel())
    p = 3 * len(stack.hands)
    return bool(e[:p].max() <= START_TOLERANCE_M and e[p:].max(initial=0.0) <= START_TOLERANCE_RAD)


def stack_joint_path(
    method: str,
    stack: HandStack,
    reference: CartesianReference,
    q: np.ndarray,
    qd: np.ndarray,
    solve_time_s: np.ndarray,
    extras=None,
):
    """The JointPath of a velocity-level method on ``stack``.

    Hand errors |r - f(q)| [m] and orientation errors (:func:`~dualarm.ik.orientation.orientation_errors`, [rad])
    from q (N, n) by the stack's forward kinematics.
    """
    N, h = len(reference), len(stack.hands)
    asked = np.hstack([reference.hands[hand].position for hand in stack.hands])
    positions = np.asarray(stack.positions.map(N)(q.T)).T
    rotations = np.asarray(stack.rotations.map(N)(q.T)).reshape(3 * h, N, 3).transpose(1, 0, 2).reshape(N, h, 3, 3)
    asked_rotations = np.stack([reference.hands[hand].rotation for hand in stack.hands], axis=1)
    return JointPath(
        method=method,
        joint_names=stack.joint_names,
        t=reference.t,
        rep=reference.rep,
        q=q,
        qd=qd,
        status=np.zeros(N, int),
        solve_time_s=solve_time_s,
        hand_error_m=np.linalg.norm((asked - positions).reshape(N, -1, 3), axis=2),
        hand_orientation_error_rad=orientation_errors(asked_rotations, rotations),
        task_space=stack.task_space,
        hands=stack.hands,
        fixed=stack.fixed,
        extras=extras or {},
    )
