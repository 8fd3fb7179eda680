"""A PyBullet physics client holding one robot, with name-based access to joints and links.

PyBullet writes banners and URDF warnings straight to the process's stdout from C; they are
silenced while it loads, so the CLI's stdout stays machine-readable. PyBullet reports link
poses in single precision (about 1e-7 m), which bounds every comparison against it.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from dualarm.errors import RobotModelError, StageError, excerpt
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
        link_index: link name -> PyBullet link index (-1 for the root link); a link merged into an ancestor
            (see :func:`load_pybullet_robot`) has the ancestor's.
        link_name: PyBullet link index -> the name of the link PyBullet holds there.
        merged: a link merged into an ancestor -> (that ancestor, the link's pose in its frame (4, 4)).
    """

    client: int
    body: int
    joint_index: dict[str, int]
    link_index: dict[str, int]
    link_name: dict[int, str]
    merged: dict[str, tuple[str, np.ndarray]] = field(default_factory=dict)

    def set_positions(self, names: Sequence[str], q: Sequence[float] | np.ndarray) -> None:
        """Teleport joints ``names`` to positions ``q`` [rad] (no dynamics)."""
        for name, value in zip(names, q, strict=True):
            pb.resetJointState(self.body, self.joint_index[name], float(value), physicsClientId=self.client)

    def link_pose(self, link: str) -> np.ndarray:
        """World pose of ``link``'s URDF frame (not its centre of mass) as a 4x4 array [m]."""
        if link in self.merged:
            ancestor, offset = self.merged[link]
            return self.link_pose(ancestor) @ offset
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
#: configuration touch by construction and are not checked [m] (see :func:`disable_unchecked_pairs`).
TOUCHING_M = 1e-3


def disable_unchecked_pairs(
    sim: PyBulletRobot, listed: Iterable[tuple[str, str]] = (), margin_m: float = 0.0
) -> frozenset[tuple[str, str]]:
    """Turn off the self-collision pairs dualarm does not check; returns them by name (sorted pairs).

    The one list of pairs not checked, shared by the planners' checker, the execute stage and
    ``robot init``: the pairs ``listed`` (a robot's :attr:`~dualarm.model.robot.Robot.disabled_pairs`:
    rigidly joined, in contact everywhere, or the user's), and those that touch by construction: a
    link and its nearest ancestor with collision geometry when they are joined directly (PyBullet's
    own rule for a parent), or when they are joined through links without geometry and are within
    :data:`TOUCHING_M` of each other at the zero configuration, ``margin_m`` aside (the shapes of
    ``sim`` grown by ``margin_m``; the pelvis and the torso through the waist's yaw and pitch links,
    the forearm and the palm through the wrist links). Every other pair is checked: the upper arms
    keep 45 mm from the torso at rest, and an arm swung across the chest does hit it.

    The robot must be at the zero configuration (as loaded).
    """
    body, client = sim.body, sim.client
    name = sim.link_name
    skipped: set[tuple[str, str]] = set()
    for link, (up, through_bare) in sim.solid_parents().items():
        points = pb.getClosestPoints(body, body, 1.0, link, up, physicsClientId=client)
        touching = (
            bool(points) and min(p[8] for p in points) + 2 * margin_m < TOUCHING_M
        )  # the distance before the margin
        if through_bare and not touching:
            continue
        first, second = sorted((name[link], name[up]))
        skipped.add((first, second))
    return frozenset(disable_pairs(sim, skipped | set(listed)))


def disable_pairs(sim: PyBulletRobot, pairs: Iterable[tuple[str, str]]) -> set[tuple[str, str]]:
    """Turn off self-collision between each pair of links named; returns them as sorted pairs."""
    done = set()
    for a, b in pairs:
        pb.setCollisionFilterPair(
            sim.body, sim.body, sim.link_index[a], sim.link_index[b], enableCollision=0, physicsClientId=sim.client
        )
        done.add((a, b) if a < b else (b, a))
    return done


#: The most links PyBullet reports the state of (its ``MAX_DEGREE_OF_FREEDOM``): ``getLinkState`` fails on every
#: link of a body with more (a TIAGo dual with its two five-finger hands has 129).
MAX_LINKS = 128


def load_pybullet_robot(urdf: str | Path, *, self_collision: bool = False, gui: bool = False) -> PyBulletRobot:
    """Start a client (DIRECT, or a window with ``gui``) and load ``urdf`` with a fixed base at the origin.

    A robot of more than :data:`MAX_LINKS` links is loaded with the links hung by fixed joints merged into
    their parents (``URDF_MERGE_FIXED_LINKS``): their collision shapes move with the parent, which contacts
    name, and their poses are the parent's times the fixed joints' origins.

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
        try:
            body = pb.loadURDF(str(urdf), useFixedBase=True, flags=flags, physicsClientId=client)
        except pb.error:
            pb.disconnect(physicsClientId=client)
            raise RobotModelError(
                f"{excerpt(urdf)}: PyBullet cannot load it (a revolute or prismatic joint without <limit>, which "
                "URDF requires, or a mesh it cannot read)"
            ) from None
        if pb.getNumJoints(body, physicsClientId=client) > MAX_LINKS:
            pb.removeBody(body, physicsClientId=client)
            flags |= pb.URDF_MERGE_FIXED_LINKS
            body = pb.loadURDF(str(urdf), useFixedBase=True, flags=flags, physicsClientId=client)
    joint_index: dict[str, int] = {}
    link_index: dict[str, int] = {pb.getBodyInfo(body, physicsClientId=client)[0].decode(): -1}
    for i in range(pb.getNumJoints(body, physicsClientId=client)):
        info = pb.getJointInfo(body, i, physicsClientId=client)
        joint_index[info[1].decode()] = i
        link_index[info[12].decode()] = i
    link_name = {i: n for n, i in link_index.items()}
    merged = _merged_links(urdf, link_index) if flags & pb.URDF_MERGE_FIXED_LINKS else {}
    link_index |= {link: link_index[ancestor] for link, (ancestor, _) in merged.items()}
    return PyBulletRobot(
        client=client, body=body, joint_index=joint_index, link_index=link_index, link_name=link_name, merged=merged
    )


def loads(urdf: str) -> int:
    """Load ``urdf`` as :func:`load_pybullet_robot` does (self-collision on), unload it; its joints' count.

    Run in a process of its own (:func:`dualarm.isolation.isolated`) before a command relies on PyBullet reading a
    user's file: PyBullet's loader has crashed (signal 11) on URDFs it accepted the parse of.
    """
    with load_pybullet_robot(urdf, self_collision=True) as sim:
        return len(sim.joint_index)


def _merged_links(urdf: str | Path, kept: dict[str, int]) -> dict[str, tuple[str, np.ndarray]]:
    """Each link PyBullet merged away -> (its ancestor PyBullet kept, its pose in that ancestor's frame)."""
    from dualarm.model.kinematics import origin_matrix
    from dualarm.model.urdf import load_urdf

    model = load_urdf(urdf)
    by_child = {j.child: j for j in model.joints}
    out = {}
    for link in model.links:
        if link in kept:
            continue
        T, up = np.eye(4), link
        while up not in kept:
            T = origin_matrix(by_child[up]) @ T
            up = by_child[up].parent
        out[link] = (up, T)
    return out


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
