"""The hands of a task stacked over the task's active joints.

The active joints are the arm joints of every hand the task drives, plus the waist when the task
frees it; locked joints keep their initial values. Hand positions are in the robot base frame, so
a free waist is shared by both hands' Jacobians (Li-Liang's 17-DOF model); with the waist locked
the Jacobian is block diagonal, as in TV-GDD eq (13).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType

import casadi as cs
import numpy as np

from dualarm.arrays import frozen
from dualarm.errors import StageError
from dualarm.model.kinematics import ChainKinematics
from dualarm.model.robot import Robot
from dualarm.paths.reference import CartesianReference


@dataclass(frozen=True)
class HandStack:
    """Stacked hand kinematics.

    Attributes:
        joint_names: the active joints, the order of the vector theta.
        hands: the hands, the order of the stacked rows.
        fixed: values of the locked joints [rad].
        initial: the task's initial values of the active joints [rad], (n,).
        theta: the CasADi symbol of the active joints, (n, 1).
        position: SX expression of the stacked hand positions, (3 h, 1) [m].
        jacobian: SX expression of d position / d theta, (3 h, n).
        positions: Function ``theta -> position``.
    """

    joint_names: tuple[str, ...]
    hands: tuple[str, ...]
    fixed: Mapping[str, float]
    initial: np.ndarray
    theta: cs.SX
    position: cs.SX
    jacobian: cs.SX
    positions: cs.Function

    @property
    def n(self) -> int:
        """Number of active joints."""
        return len(self.joint_names)

    @property
    def m(self) -> int:
        """Number of stacked task rows (3 per hand)."""
        return 3 * len(self.hands)


def active_joints(robot: Robot, hands: Sequence[str], frame: str, free_waist: bool) -> tuple[str, ...]:
    """The active joints: the joints from ``frame`` to each hand's tip that belong to its arm chain, plus the others on the way (the waist) when ``free_waist``, in URDF order."""
    names: list[str] = []
    for hand in hands:
        arm = set(robot.hand_chain(hand).joint_names)
        for name in robot.chain_between(frame, robot.hand_chain(hand).tip).joint_names:
            if name not in names and (name in arm or free_waist):
                names.append(name)
    return tuple(names)


def hand_stack(robot: Robot, hands: Sequence[str], q0: Mapping[str, float], *, frame: str | None = None, free_waist: bool = False) -> HandStack:
    """The stacked position kinematics of ``hands`` in ``frame`` (default the robot's root link), the joints that are not active at their values in ``q0`` [rad]."""
    frame = frame or robot.urdf.root
    names = active_joints(robot, hands, frame, free_waist)
    fixed = {n: v for n, v in q0.items() if n not in names}
    theta = cs.SX.sym("theta", len(names))
    index = {n: i for i, n in enumerate(names)}
    rows = []
    for hand in hands:
        chain = robot.chain_between(frame, robot.hand_chain(hand).tip)
        q = cs.vertcat(*[theta[index[n]] if n in index else fixed[n] for n in chain.joint_names])
        rows.append(ChainKinematics.of(chain).fk(q)[:3, 3])
    position = cs.vertcat(*rows)
    jacobian = cs.jacobian(position, theta)
    return HandStack(
        joint_names=names,
        hands=tuple(hands),
        fixed=MappingProxyType(fixed),
        initial=frozen([q0[n] for n in names], (len(names),), "initial"),
        theta=theta,
        position=position,
        jacobian=jacobian,
        positions=cs.Function("hand_positions", [theta], [position], ["theta"], ["r"]),
    )


def reference_stack(robot: Robot, reference: CartesianReference, q0: Mapping[str, float] | str | None, free_waist: bool) -> HandStack:
    """The stack of the reference's hands in its frame, ``q0`` resolved by :meth:`Robot.configuration`."""
    return hand_stack(robot, tuple(reference.hands), robot.configuration(q0, "q0"), frame=reference.frame_in(robot), free_waist=free_waist)


def stacked_reference(stack: HandStack, reference: CartesianReference) -> tuple[np.ndarray, np.ndarray]:
    """Stacked hand positions (N, 3 h) [m] and velocities (N, 3 h) [m/s] of a CartesianReference."""
    position = np.hstack([reference.hands[h].position for h in stack.hands])
    velocity = np.hstack([reference.hands[h].linear_velocity for h in stack.hands])
    return position, velocity


#: Largest hand-position gap [m] between the initial configuration and the path start left as is.
START_TOLERANCE_M = 1e-9


def start_configuration(stack: HandStack, reference: CartesianReference, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Where a velocity-level method starts [rad], (n,): the task's initial values if they put the hands on the reference's first sample (within :data:`START_TOLERANCE_M`), otherwise the configuration nearest to them, within ``lower``/``upper`` [rad], that does — the least-squares problem min |theta - initial|^2 s.t. f(theta) = r_0 solved by IPOPT through CasADi.

    Raises:
        StageError: IPOPT finds no such configuration.
    """
    r0 = stacked_reference(stack, reference)[0][0]
    if np.abs(np.asarray(stack.positions(stack.initial)).ravel() - r0).max() <= START_TOLERANCE_M:
        return stack.initial
    nlp = {"x": stack.theta, "f": cs.sumsqr(stack.theta - stack.initial), "g": stack.position - r0}
    options = {"print_time": False, "ipopt": {"print_level": 0, "sb": "yes", "tol": 1e-12, "constr_viol_tol": 1e-12}}
    solver = cs.nlpsol("start_configuration", "ipopt", nlp, options)
    theta = np.asarray(solver(x0=stack.initial, lbx=lower, ubx=upper, lbg=0, ubg=0)["x"]).ravel()
    gap = np.abs(np.asarray(stack.positions(theta)).ravel() - r0).max()
    if not solver.stats()["success"] or gap > START_TOLERANCE_M:
        raise StageError(f"no configuration within the joint limits puts the hands on the path start (IPOPT: {solver.stats()['return_status']}, gap {gap:.3g} m)", stage="ik", sample=0, t_s=0.0)
    return frozen(theta, (stack.n,), "start")


def stack_joint_path(method: str, stack: HandStack, reference: CartesianReference, q: np.ndarray, qd: np.ndarray, solve_time_s: np.ndarray, extras=None):
    """The JointPath of a velocity-level method on ``stack``: hand errors |r - f(q)| from q (N, n)."""
    from dualarm.ik.joint_path import JointPath

    R, _ = stacked_reference(stack, reference)
    N = len(reference)
    positions = np.asarray(stack.positions.map(N)(q.T)).T
    return JointPath(
        method=method,
        joint_names=stack.joint_names,
        t=reference.t,
        rep=reference.rep,
        q=q,
        qd=qd,
        status=np.zeros(N, int),
        solve_time_s=solve_time_s,
        hand_error_m=np.linalg.norm((R - positions).reshape(N, -1, 3), axis=2),
        hands=stack.hands,
        fixed=stack.fixed,
        extras=extras or {},
    )
