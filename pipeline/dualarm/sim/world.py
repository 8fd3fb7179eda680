"""A PyBullet physics client holding one robot, with name-based access to joints and links.

PyBullet writes banners and URDF warnings straight to the process's stdout from C; they are
silenced while it loads, so the CLI's stdout stays machine-readable. PyBullet reports link
poses in single precision (about 1e-7 m), which bounds every comparison against it.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from dualarm.errors import StageError
from dualarm.model.poses import pose_matrix
from dualarm.quiet import c_output_silenced

with c_output_silenced():
    import pybullet as pb


@dataclass
class PyBulletRobot:
    """One robot loaded into its own PyBullet DIRECT client.

    Attributes:
        client: the physics client id (passed to every PyBullet call).
        body: the robot's body id.
        joint_index: joint name -> PyBullet joint index.
        link_index: link name -> PyBullet link index (-1 for the root link).
    """

    client: int
    body: int
    joint_index: dict[str, int]
    link_index: dict[str, int]

    def set_positions(self, names: Sequence[str], q: Sequence[float] | np.ndarray) -> None:
        """Teleport joints ``names`` to positions ``q`` [rad] (no dynamics)."""
        for name, value in zip(names, q, strict=True):
            pb.resetJointState(self.body, self.joint_index[name], float(value), physicsClientId=self.client)

    def link_pose(self, link: str) -> np.ndarray:
        """World pose of ``link``'s URDF frame (not its centre of mass) as a 4x4 array [m]."""
        index = self.link_index[link]
        if index == -1:  # PyBullet places the base at its centre of mass: undo the inertial offset
            com_pos, com_quat = pb.getBasePositionAndOrientation(self.body, physicsClientId=self.client)
            local_pos, local_quat = pb.getDynamicsInfo(self.body, -1, physicsClientId=self.client)[3:5]
            inv_pos, inv_quat = pb.invertTransform(local_pos, local_quat, physicsClientId=self.client)
            pos, quat = pb.multiplyTransforms(com_pos, com_quat, inv_pos, inv_quat, physicsClientId=self.client)
        else:
            state = pb.getLinkState(self.body, index, computeForwardKinematics=True, physicsClientId=self.client)
            pos, quat = state[4], state[5]
        T = np.eye(4)
        T[:3, :3] = np.asarray(pb.getMatrixFromQuaternion(quat, physicsClientId=self.client)).reshape(3, 3)
        T[:3, 3] = pos
        return T

    def collision_links(self) -> set[int]:
        """Indices of the robot's links that have collision geometry."""
        return {
            i for i in self.link_index.values() if pb.getCollisionShapeData(self.body, i, physicsClientId=self.client)
        }

    def solid_parents(self) -> dict[int, tuple[int, bool]]:
        """For each link with collision geometry below another such link: that nearest ancestor with geometry.

        And whether the way up passes through links without geometry.
        """
        parent = {
            i: pb.getJointInfo(self.body, i, physicsClientId=self.client)[16]
            for i in range(pb.getNumJoints(self.body, physicsClientId=self.client))
        }
        solid = self.collision_links()
        out = {}
        for link in solid:
            up, through_bare = parent.get(link), False
            while up is not None and up != -1 and up not in solid:
                up, through_bare = parent.get(up), True
            if up is not None and up in solid:
                out[link] = (up, through_bare)
        return out

    def close(self) -> None:
        """Disconnect the client."""
        if pb.isConnected(physicsClientId=self.client):
            pb.disconnect(physicsClientId=self.client)

    def __enter__(self) -> PyBulletRobot:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def in_contact(point: Sequence) -> bool:
    """Whether a point of ``pb.getContactPoints`` is a contact: its shapes overlap (distance < 0).

    PyBullet also returns points up to its contact breaking threshold apart (speculative contacts,
    e.g. a wrist's convex hulls 1.6 mm apart); those are gaps, not contacts. The planners' checker
    and the execution judge by this one rule.
    """
    return point[8] < 0.0


#: Two links joined only through links without collision geometry and closer than this at the zero
#: configuration touch by construction and are not checked [m] (see :func:`disable_touching_pairs`).
TOUCHING_M = 1e-3


def disable_touching_pairs(sim: PyBulletRobot, margin_m: float = 0.0) -> frozenset[tuple[str, str]]:
    """Turn off the self-collision pairs that touch by construction; returns them by name (sorted pairs).

    The one list of pairs not checked, shared by the planners' checker and the execute stage: a
    link and its nearest ancestor with collision geometry when they are joined directly (PyBullet's
    own rule for a parent), or when they are joined through links without geometry and are within
    :data:`TOUCHING_M` of each other at the zero configuration, ``margin_m`` aside (the shapes of
    ``sim`` grown by ``margin_m``; the pelvis and the torso through the waist's yaw and pitch links,
    the forearm and the palm through the wrist links). Every other pair is checked: the upper arms
    keep 45 mm from the torso at rest, and an arm swung across the chest does hit it.

    The robot must be at the zero configuration (as loaded).
    """
    body, client = sim.body, sim.client
    name = {i: n for n, i in sim.link_index.items()}
    skipped: set[tuple[str, str]] = set()
    for link, (up, through_bare) in sim.solid_parents().items():
        points = pb.getClosestPoints(body, body, 1.0, link, up, physicsClientId=client)
        touching = (
            bool(points) and min(p[8] for p in points) + 2 * margin_m < TOUCHING_M
        )  # the distance before the margin
        if through_bare and not touching:
            continue
        pb.setCollisionFilterPair(body, body, link, up, enableCollision=0, physicsClientId=client)
        first, second = sorted((name[link], name[up]))
        skipped.add((first, second))
    return frozenset(skipped)


def load_pybullet_robot(urdf: str | Path, *, self_collision: bool = False, gui: bool = False) -> PyBulletRobot:
    """Start a client (DIRECT, or a window with ``gui``) and load ``urdf`` with a fixed base at the origin.

    Raises:
        StageError: ``gui`` on a Linux machine without a display.
    """
    if (
        gui
        and sys.platform.startswith("linux")
        and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    ):
        raise StageError("execute: --gui needs a display, and this machine has none (DISPLAY is not set)")
    with c_output_silenced():
        client = pb.connect(pb.GUI if gui else pb.DIRECT)
        if client < 0:
            raise StageError("execute: PyBullet could not open its window")
        flags = pb.URDF_USE_INERTIA_FROM_FILE | (pb.URDF_USE_SELF_COLLISION if self_collision else 0)
        body = pb.loadURDF(str(urdf), useFixedBase=True, flags=flags, physicsClientId=client)
    joint_index: dict[str, int] = {}
    link_index: dict[str, int] = {pb.getBodyInfo(body, physicsClientId=client)[0].decode(): -1}
    for i in range(pb.getNumJoints(body, physicsClientId=client)):
        info = pb.getJointInfo(body, i, physicsClientId=client)
        joint_index[info[1].decode()] = i
        link_index[info[12].decode()] = i
    return PyBulletRobot(client=client, body=body, joint_index=joint_index, link_index=link_index)


def add_environment(sim: PyBulletRobot, objects) -> dict[int, str]:
    """Static bodies in ``sim``'s client for a task's fixed objects; body id -> object name.

    The objects: :class:`~dualarm.tasks.schema.EnvironmentObject`.
    """
    bodies = {}
    for obj in objects:
        if obj.shape == "box":
            shape = pb.createCollisionShape(
                pb.GEOM_BOX, halfExtents=[s / 2 for s in obj.size_m], physicsClientId=sim.client
            )
        elif obj.shape == "cylinder":
            shape = pb.createCollisionShape(
                pb.GEOM_CYLINDER, radius=obj.radius_m, height=obj.height_m, physicsClientId=sim.client
            )
        else:
            shape = pb.createCollisionShape(pb.GEOM_SPHERE, radius=obj.radius_m, physicsClientId=sim.client)
        T = pose_matrix(obj.pose.position, obj.pose.rpy)
        body = pb.createMultiBody(
            0.0,
            shape,
            basePosition=T[:3, 3].tolist(),
            baseOrientation=Rotation.from_matrix(T[:3, :3]).as_quat().tolist(),
            physicsClientId=sim.client,
        )
        bodies[body] = obj.name
    return bodies
