"""Forward kinematics and geometric Jacobians of a chain as CasADi Functions.

The chain's transforms are multiplied out symbolically from the URDF joint descriptions
(origin, then the joint's motion about or along its axis), so the Functions are exact to
rounding and can be embedded in larger CasADi graphs (the IK control step) or mapped over many
configurations at once.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache, cached_property

import casadi as cs
import numpy as np
from scipy.spatial.transform import Rotation

from dualarm.arrays import rigid_transforms
from dualarm.model.poses import invert
from dualarm.model.robot import Chain, Robot
from dualarm.model.urdf import JointSpec
from dualarm.numerics.batched import Batched
from dualarm.numerics.compiled import compiled


def origin_matrix(joint: JointSpec) -> np.ndarray:
    """Homogeneous transform of ``joint``'s frame in its parent link frame (URDF rpy: R = Rz Ry Rx)."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("xyz", joint.origin_rpy).as_matrix()
    T[:3, 3] = joint.origin_xyz
    return T


def _motion(joint: JointSpec, q: cs.SX) -> cs.SX:
    """Homogeneous transform of the joint's motion by ``q`` [rad or m] (Rodrigues for revolute)."""
    a = np.asarray(joint.axis)
    T = cs.SX.eye(4)
    if joint.type == "prismatic":
        T[:3, 3] = a * q
        return T
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    T[:3, :3] = np.eye(3) + cs.sin(q) * K + (1 - cs.cos(q)) * (K @ K)
    return T


@dataclass(frozen=True)
class ChainFrames:
    """Symbolic frames along a chain at the symbolic configuration ``q``.

    Attributes:
        q: the configuration symbol, shape (n, 1).
        before: for each movable joint, its frame in the chain base before its own motion (4x4 SX).
        after: for each movable joint, its child link frame after its motion (4x4 SX).
        tip: the tip frame in the chain base (4x4 SX).
    """

    q: cs.SX
    before: tuple[cs.SX, ...]
    after: tuple[cs.SX, ...]
    tip: cs.SX


def chain_frames(chain: Chain) -> ChainFrames:
    """Multiply out the chain symbolically."""
    q = cs.SX.sym("q", chain.dof)
    T = cs.SX.eye(4)
    before, after = [], []
    i = 0
    for joint in chain.joints:
        T = T @ origin_matrix(joint)
        if joint.movable:
            before.append(T)
            T = T @ _motion(joint, q[i])
            after.append(T)
            i += 1
    return ChainFrames(q=q, before=tuple(before), after=tuple(after), tip=T)


def link_frames(joints: tuple[JointSpec, ...], root: str, q: Mapping[str, cs.SX | float]) -> dict[str, cs.SX]:
    """Every link's frame in the ``root`` link's frame (4x4 SX).

    Each joint of the tree ``joints`` at ``q[name]`` (a symbol or a value [rad or m]; joints not named at 0).
    """
    frames = {root: cs.SX.eye(4)}
    children: dict[str, list[JointSpec]] = {}
    for joint in joints:
        children.setdefault(joint.parent, []).append(joint)
    pending = [root]
    while pending:
        parent = pending.pop()
        for joint in children.get(parent, []):
            T = frames[parent] @ origin_matrix(joint)
            frames[joint.child] = T @ _motion(joint, q.get(joint.name, 0.0)) if joint.movable else T
            pending.append(joint.child)
    return frames


def geometric_jacobian(frames: ChainFrames, chain: Chain) -> cs.SX:
    """6 x n geometric Jacobian of the tip origin.

    Rows [linear velocity; angular velocity] in the base frame.
    """
    p_tip = frames.tip[:3, 3]
    columns = []
    movable = [j for j in chain.joints if j.movable]
    for joint, T in zip(movable, frames.before, strict=True):
        z = T[:3, :3] @ np.asarray(joint.axis)
        if joint.type == "prismatic":
            columns.append(cs.vertcat(z, cs.SX.zeros(3)))
        else:
            columns.append(cs.vertcat(cs.cross(z, p_tip - T[:3, 3]), z))
    return cs.horzcat(*columns) if columns else cs.SX.zeros(6, 0)


@dataclass(frozen=True)
class ChainKinematics:
    """Kinematics of one chain.

    Attributes:
        chain: the chain.
        fk: CasADi Function ``q (n) -> T (4x4)``, tip pose in the base frame [m].
        jacobian: CasADi Function ``q (n) -> J (6xn)``, geometric Jacobian of the tip origin,
            rows [v; w] in the base frame [m/rad; 1].
    """

    chain: Chain
    fk: cs.Function
    jacobian: cs.Function

    @classmethod
    def of(cls, chain: Chain) -> ChainKinematics:
        """The Functions for ``chain`` (built once per chain and kept)."""
        return _chain_kinematics(chain)

    @classmethod
    def _build(cls, chain: Chain) -> ChainKinematics:
        frames = chain_frames(chain)
        fk = cs.Function(f"fk_{chain.tip}", [frames.q], [frames.tip], ["q"], ["T"])
        jac = cs.Function(f"jac_{chain.tip}", [frames.q], [geometric_jacobian(frames, chain)], ["q"], ["J"])
        return cls(chain=chain, fk=fk, jacobian=jac)

    @cached_property
    def _fk_many(self) -> Batched:
        """The tip pose as a column (16, column-major), compiled and mapped (:mod:`dualarm.numerics.batched`)."""
        q = cs.SX.sym("q", self.chain.dof)
        return Batched(compiled(cs.Function(f"fk_flat_{self.chain.tip}", [q], [cs.reshape(self.fk(q), 16, 1)])))

    def pose(self, q: np.ndarray) -> np.ndarray:
        """Tip pose at one configuration ``q`` (n,) [rad] as a 4x4 array."""
        return np.asarray(self.fk(np.asarray(q, dtype=float)))

    def poses(self, Q: np.ndarray) -> np.ndarray:
        """Tip poses at N configurations ``Q`` (N, n) [rad], evaluated with ``Function.map``; (N, 4, 4)."""
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        if self.chain.dof == 0:  # a fixed chain: one pose
            return np.repeat(self.pose(np.zeros(0))[None], len(Q), axis=0)
        (flat,) = self._fk_many(Q)  # (N, 16), column-major 4x4 per row
        return flat.reshape(-1, 4, 4).transpose(0, 2, 1)

    def jacobians(self, Q: np.ndarray) -> np.ndarray:
        """Geometric Jacobians at N configurations (N, n) [rad]; (N, 6, n)."""
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        n = self.chain.dof
        flat = np.asarray(self.jacobian.map(Q.shape[0])(Q.T))  # (6, N*n)
        return flat.reshape(6, Q.shape[0], n).transpose(1, 0, 2)


@cache
def _chain_kinematics(chain: Chain) -> ChainKinematics:
    return ChainKinematics._build(chain)


def _values(robot: Robot, chain: Chain, q: Mapping[str, float] | str | None) -> np.ndarray:
    configuration = robot.configuration(q)
    return np.array([configuration[n] for n in chain.joint_names])


def hand_pose(robot: Robot, hand: str, q: Mapping[str, float] | str | None = None) -> np.ndarray:
    """The pose of ``hand``'s frame in the robot's base frame [m], 4x4, at configuration ``q``.

    The robot's base frame is its root link. ``q``: a home pose's name, a mapping joint -> value [rad] (others at
    0), or None (all at 0).

    Task poses are given in this frame.
    """
    chain = robot.chain_between(robot.urdf.root, robot.hand_chain(hand).tip)
    return ChainKinematics.of(chain).pose(_values(robot, chain, q))


def arm_base_pose(robot: Robot, hand: str, q: Mapping[str, float] | str | None = None) -> np.ndarray:
    """The pose of the base frame of ``hand``'s arm chain in the robot's base frame [m], 4x4.

    The arm chain's base is the torso, for the humanoid; the joints between them (a waist) at ``q`` (as
    :func:`hand_pose`).
    """
    chain = robot.chain_between(robot.urdf.root, robot.hand_chain(hand).base)
    return ChainKinematics.of(chain).pose(_values(robot, chain, q))


def to_arm_frame(robot: Robot, hand: str, pose: np.ndarray, q: Mapping[str, float] | str | None = None) -> np.ndarray:
    """A hand pose (4x4, or (N, 4, 4)) [m] given in the robot's base frame, in the arm's base frame.

    Expressed in the base frame of ``hand``'s arm chain, the frame analytic arm solvers work in (``dualarm ik srs``
    takes poses in it); the waist at ``q`` (as :func:`hand_pose`).

    Raises:
        InvalidArgumentError: ``pose`` is not a rigid transform.
    """
    many = np.ndim(pose) == 3
    T = rigid_transforms(pose, "pose", many=many)
    return invert(arm_base_pose(robot, hand, q)) @ T


def motion_matrix(joint: JointSpec, q: float | np.ndarray) -> np.ndarray:
    """Homogeneous transforms (numpy) of a joint's motion by ``q`` [rad or m].

    A number or (K,) values -> (4, 4) or (K, 4, 4); identity if fixed.
    """
    q = np.asarray(q, dtype=float)
    T = np.broadcast_to(np.eye(4), (*q.shape, 4, 4)).copy()
    if joint.type == "prismatic":
        T[..., :3, 3] = np.asarray(joint.axis) * q[..., None]
    elif joint.movable:
        T[..., :3, :3] = (
            Rotation.from_rotvec((np.asarray(joint.axis) * q[..., None]).reshape(-1, 3))
            .as_matrix()
            .reshape(*q.shape, 3, 3)
        )
    return T


def joint_transforms(
    joints: tuple[JointSpec, ...], q: Mapping[str, float | np.ndarray]
) -> list[tuple[str, str, np.ndarray]]:
    """(parent link, child link, child-in-parent transform) of every joint at configuration ``q``.

    ``q``: joint name -> a value, or (K,) values for K configurations; joints not named are at 0.

    The transforms are (4, 4), or (K, 4, 4) when any value is an array of K.
    """
    shape = np.broadcast_shapes(*(np.shape(v) for v in q.values()))
    return [
        (j.parent, j.child, origin_matrix(j) @ motion_matrix(j, np.broadcast_to(q.get(j.name, 0.0), shape)))
        for j in joints
    ]
