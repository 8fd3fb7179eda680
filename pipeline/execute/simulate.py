"""The execute stage: a joint trajectory played on the humanoid in PyBullet, measured every step.

The robot is loaded in DIRECT mode with a fixed base and self-collision on, with the task's fixed
objects (:class:`~dualarm.tasks.schema.EnvironmentObject`) as static bodies. Link pairs that touch
by construction are not collision-checked: a pair whose kinematic path passes only through links
without collision geometry (the pelvis and the torso through the waist's yaw and pitch links, the
forearm and the palm through the wrist links) always overlaps; the others are checked, as MoveIt
disables "adjacent" pairs.

Each physics step (``step_s``, 1 kHz by default) the joints are driven by PyBullet's position
motors with the robot's effort limits. PyBullet's motor asks for the joint velocity
v = velocity_gain qd* + position_gain (q* - q) / step_s; it is given the trajectory's state
(q*, qd*) at the start of the step, so with velocity_gain = 1 the joint ends the step near the
trajectory's position at the step's end, which is where the measured state is logged (with the
trajectory's position there, ``q_command``). Without the velocity term (velocity_gain = 0) the
motors went unstable on the triangle at position gains of 0.5 and 1. Locked joints are held by the
same motors.

Contacts are counted per step and per pair of bodies (a robot link and another link, or a link and
a named object); pairs the task expects (``expected_contacts``, such as the palms on a carried box)
are counted apart from the others. With ``gui`` the steps are paced to real time.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np

from dualarm.arrays import frozen
from dualarm.errors import StageError
from dualarm.execute.world import add_environment, load_pybullet_robot, pb
from dualarm.model.robot import Robot
from dualarm.retime.trajectory import JointTrajectory


@dataclass(frozen=True)
class ExecutionSettings:
    """Settings of the simulation.

    Attributes:
        step_s: physics step [s].
        position_gain: PyBullet's ``positionGain`` of the joint motors [1].
        velocity_gain: PyBullet's ``velocityGain`` [1].
        gravity_m_s2: gravity along -z [m/s^2].
        gui: show the simulation in a PyBullet window, in real time (needs a display).
    """

    step_s: float = 0.001
    position_gain: float = 0.2
    velocity_gain: float = 1.0
    gravity_m_s2: float = 9.81
    gui: bool = False


@dataclass(frozen=True)
class ExecutionLog:
    """What the simulator did.

    Attributes:
        joint_names: the driven joints, the columns of ``q``.
        t: step end times (K,) [s].
        q: measured joint positions (K, n) [rad].
        qd: measured joint velocities (K, n) [rad/s].
        q_command: the trajectory's positions at ``t`` (K, n) [rad].
        rep: repetition index (K,).
        hand_poses: per hand, the measured hand link pose in the world (K, 4, 4) [m].
        self_contacts: unexpected robot-robot contact points per step (K,).
        environment_contacts: unexpected robot-environment contact points per step (K,).
        expected_contacts: contact points of the expected pairs per step (K,).
        contact_pairs: every (link, link or object) pair that touched -> the number of steps it
            touched in, expected pairs included.
    """

    joint_names: tuple[str, ...]
    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    q_command: np.ndarray
    rep: np.ndarray
    hand_poses: Mapping[str, np.ndarray]
    self_contacts: np.ndarray
    environment_contacts: np.ndarray
    expected_contacts: np.ndarray
    contact_pairs: Mapping[tuple[str, str], int] = field(default_factory=dict)
    fixed: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        K, n = len(self.t), len(self.joint_names)
        for name, shape, dtype in (
            ("t", (K,), float),
            ("q", (K, n), float),
            ("qd", (K, n), float),
            ("q_command", (K, n), float),
            ("rep", (K,), int),
            ("self_contacts", (K,), int),
            ("environment_contacts", (K,), int),
            ("expected_contacts", (K,), int),
        ):
            object.__setattr__(self, name, frozen(getattr(self, name), shape, name, dtype))
        object.__setattr__(self, "hand_poses", MappingProxyType({h: frozen(p, (K, 4, 4), f"hand_poses[{h}]") for h, p in self.hand_poses.items()}))
        object.__setattr__(self, "fixed", MappingProxyType(dict(self.fixed)))
        object.__setattr__(self, "contact_pairs", MappingProxyType(dict(self.contact_pairs)))


def _disable_touching_by_construction(sim) -> None:
    """No collision check between links joined only through links without collision geometry."""
    for link, (up, _) in sim.solid_parents().items():
        pb.setCollisionFilterPair(sim.body, sim.body, link, up, enableCollision=0, physicsClientId=sim.client)


def execute_trajectory(
    trajectory: JointTrajectory,
    robot: Robot,
    hands: Sequence[str],
    environment=(),
    expected_contacts: Sequence[tuple[str, str]] = (),
    settings: ExecutionSettings = ExecutionSettings(),
) -> ExecutionLog:
    """Play ``trajectory`` on ``robot`` in PyBullet and measure it each step.

    Args:
        trajectory: what the joints are to do (``fixed`` joints are held).
        robot: the robot.
        hands: the hands whose link poses are logged.
        environment: the task's fixed objects (:class:`~dualarm.tasks.schema.EnvironmentObject`).
        expected_contacts: (link, link or object name) pairs, in either order, whose contacts are
            expected and counted apart.
        settings: the simulation's settings.

    Raises:
        StageError: a trajectory joint the robot does not have, or a non-positive step.
    """
    if not settings.step_s > 0:
        raise StageError(f"execute: the physics step must be positive, not {settings.step_s}")
    expected_pairs = {tuple(sorted(pair)) for pair in expected_contacts}
    with load_pybullet_robot(robot.urdf.path, self_collision=True, gui=settings.gui) as sim:
        missing = [n for n in (*trajectory.joint_names, *trajectory.fixed) if n not in sim.joint_index]
        if missing:
            raise StageError(f"execute: the robot has no joint {missing[0]}")
        _disable_touching_by_construction(sim)
        objects = add_environment(sim, environment)
        client, body = sim.client, sim.body
        pb.setGravity(0, 0, -settings.gravity_m_s2, physicsClientId=client)
        pb.setTimeStep(settings.step_s, physicsClientId=client)
        names = list(trajectory.joint_names) + list(trajectory.fixed)
        index = [sim.joint_index[n] for n in names]
        effort = [robot.limits[n].effort for n in names]
        sim.set_positions(names, [*trajectory.q[0], *trajectory.fixed.values()])
        t_end = np.arange(1, int(np.ceil(trajectory.duration_s / settings.step_s - 1e-9)) + 1) * settings.step_s
        command, command_velocity, _, _ = trajectory.interpolate(t_end - settings.step_s)
        expected, _, _, rep = trajectory.interpolate(t_end)
        held = np.array(list(trajectory.fixed.values()))
        K, n = len(t_end), len(trajectory.joint_names)
        q, qd = np.empty((K, n)), np.empty((K, n))
        hand_links = {h: sim.link_index[robot.hand_chain(h).tip] for h in hands}
        hand_poses = {h: np.empty((K, 4, 4)) for h in hands}
        self_contacts, environment_contacts, expected_contacts_ = (np.zeros(K, int) for _ in range(3))
        pair_steps: dict[tuple[str, str], int] = {}
        link_name = {i: n for n, i in sim.link_index.items()}
        start = time.monotonic()
        for k in range(K):
            pb.setJointMotorControlArray(
                body,
                index,
                pb.POSITION_CONTROL,
                targetPositions=[*command[k], *held],
                targetVelocities=[*command_velocity[k], *np.zeros(len(held))],
                forces=effort,
                positionGains=[settings.position_gain] * len(index),
                velocityGains=[settings.velocity_gain] * len(index),
                physicsClientId=client,
            )
            pb.stepSimulation(physicsClientId=client)
            states = pb.getJointStates(body, index[:n], physicsClientId=client)
            q[k] = [s[0] for s in states]
            qd[k] = [s[1] for s in states]
            for h, link in hand_links.items():
                hand_poses[h][k] = sim.link_pose(link_name[link])
            touching: set[tuple[str, str]] = set()
            for contact in pb.getContactPoints(bodyA=body, physicsClientId=client):
                other = contact[2]
                first, second = sorted((link_name[contact[3]], link_name[contact[4]] if other == body else objects.get(other, str(other))))
                key = (first, second)
                touching.add(key)
                counter = expected_contacts_ if key in expected_pairs else self_contacts if other == body else environment_contacts
                counter[k] += 1
            for key in touching:
                pair_steps[key] = pair_steps.get(key, 0) + 1
            if settings.gui:
                time.sleep(max(0.0, start + t_end[k] - time.monotonic()))
        return ExecutionLog(
            joint_names=trajectory.joint_names,
            t=t_end,
            q=q,
            qd=qd,
            q_command=expected,
            rep=rep,
            hand_poses=hand_poses,
            self_contacts=self_contacts,
            environment_contacts=environment_contacts,
            expected_contacts=expected_contacts_,
            contact_pairs=dict(sorted(pair_steps.items())),
            fixed=trajectory.fixed,
        )
