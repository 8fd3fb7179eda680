"""The execute stage: a joint trajectory played on the humanoid in PyBullet, measured every step.

The robot is loaded in DIRECT mode with a fixed base and self-collision on, with the task's fixed
objects (:class:`~dualarm.tasks.schema.EnvironmentObject`) as static bodies. Link pairs that touch
by construction are not collision-checked, as MoveIt disables "adjacent" pairs, nor the pairs the
robot's ``[collision] disabled`` lists; the list is the planners' own
(:func:`~dualarm.sim.world.disable_unchecked_pairs`), so the upper arms are checked against the
torso here as there.

Each physics step (``step_s``, 1 kHz by default) the joints are driven by PyBullet's position
motors with the robot's effort limits. PyBullet's motor asks for the joint velocity
v = velocity_gain qd* + position_gain (q* - q) / step_s; it is given the trajectory's state
(q*, qd*) at the start of the step, so with velocity_gain = 1 the joint ends the step near the
trajectory's position at the step's end, which is where the measured state is logged (with the
trajectory's position there, ``q_command``). Without the velocity term (velocity_gain = 0) the
motors went unstable on the triangle at position gains of 0.5 and 1. Locked joints are held by the
same motors.

Contacts are recorded per step and per pair of bodies (a robot link and another link, or a link
and a named object), with the pair's deepest penetration in that step; pairs the task expects
(``expected_contacts``, such as the palms on a carried box) are told apart from the others. With
``gui`` the steps are paced to real time.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from dualarm.contracts.execution import ContactEvent, ExecutionLog
from dualarm.contracts.trajectory import JointTrajectory
from dualarm.errors import StageError
from dualarm.model.robot import Robot
from dualarm.sim.world import (
    PyBulletRobot,
    add_environment,
    disable_unchecked_pairs,
    in_contact,
    load_pybullet_robot,
    pb,
)


@dataclass(frozen=True)
class ExecutionSettings:
    """Settings of the simulation.

    Attributes:
        step_s: physics step [s].
        position_gain: PyBullet's ``positionGain`` of the joint motors [1].
        velocity_gain: PyBullet's ``velocityGain`` [1].
        gravity_m_s2: gravity along -z [m/s^2].
        gui: show the simulation in a PyBullet window, in real time (needs a display).
        execute_anyway: play a trajectory that fails its validation (limits, collisions) for
            diagnosis; the run is then at best ``violated``.
    """

    step_s: float = 0.001
    position_gain: float = 0.2
    velocity_gain: float = 1.0
    gravity_m_s2: float = 9.81
    gui: bool = False
    execute_anyway: bool = False


def execute_trajectory(
    trajectory: JointTrajectory,
    robot: Robot,
    hands: Sequence[str],
    environment=(),
    expected_contacts: Sequence[tuple[str, str]] = (),
    settings: ExecutionSettings = ExecutionSettings(),
) -> ExecutionLog:
    """Play ``trajectory`` on ``robot`` in PyBullet and measure it each step.

    After its ``approach``, when it has one.

    Args:
        trajectory: what the joints are to do (``fixed`` joints are held).
        robot: the robot.
        hands: the hands whose link poses are logged.
        environment: the task's fixed objects (:class:`~dualarm.tasks.schema.EnvironmentObject`).
        expected_contacts: (link, link or object name) pairs, in either order, whose contacts are
            expected and counted apart.
        settings: the simulation's settings.

    Returns:
        The trajectory's log, with the approach's (on its own clock) as its ``approach``.

    Raises:
        StageError: a trajectory joint the robot does not have, or a non-positive step.
    """
    if not settings.step_s > 0:
        raise StageError(f"execute: the physics step must be positive, not {settings.step_s}")
    with load_pybullet_robot(robot.urdf.path, self_collision=True, gui=settings.gui) as sim:
        missing = [n for n in (*trajectory.joint_names, *trajectory.fixed) if n not in sim.joint_index]
        if missing:
            raise StageError(f"execute: the robot has no joint {missing[0]}")
        disable_unchecked_pairs(sim, robot.disabled_pairs)
        player = _Player(
            sim,
            robot,
            hands,
            add_environment(sim, environment),
            {tuple(sorted(pair)) for pair in expected_contacts},
            settings,
        )
        pb.setGravity(0, 0, -settings.gravity_m_s2, physicsClientId=sim.client)
        pb.setTimeStep(settings.step_s, physicsClientId=sim.client)
        first = trajectory.approach if trajectory.approach is not None else trajectory
        sim.set_positions([*first.joint_names, *first.fixed], [*first.q[0], *first.fixed.values()])
        approach = player.play(trajectory.approach) if trajectory.approach is not None else None
        return replace(player.play(trajectory), approach=approach)


@dataclass
class _Player:
    """Plays trajectories one after the other in one simulation (see :func:`execute_trajectory`)."""

    sim: PyBulletRobot
    robot: Robot
    hands: Sequence[str]
    objects: dict[int, str]
    expected_pairs: set[tuple[str, ...]]
    settings: ExecutionSettings

    def play(self, trajectory: JointTrajectory) -> ExecutionLog:
        """Drive the joints along ``trajectory`` from where they are, step by step; its log.

        The log: the state it starts from at t = 0, then the state at the end of each step.
        """
        sim, settings, client, body = self.sim, self.settings, self.sim.client, self.sim.body
        names = list(trajectory.joint_names) + list(trajectory.fixed)
        index = [sim.joint_index[n] for n in names]
        effort = [self.robot.limits[n].effort for n in names]
        t = np.arange(0, int(np.ceil(trajectory.duration_s / settings.step_s - 1e-9)) + 1) * settings.step_s
        command, command_velocity, _, _ = trajectory.interpolate(
            np.maximum(t - settings.step_s, 0.0)
        )  # row k's step starts at t[k] - step
        expected, _, _, rep = trajectory.interpolate(t)
        held = np.array(list(trajectory.fixed.values()))
        K, n = len(t), len(trajectory.joint_names)
        q, qd = np.empty((K, n)), np.empty((K, n))
        hand_links = {h: self.robot.hand_chain(h).tip for h in self.hands}
        hand_poses = {h: np.empty((K, 4, 4)) for h in self.hands}
        self_contacts, environment_contacts, expected_contacts = (np.zeros(K, int) for _ in range(3))
        events: list[ContactEvent] = []
        link_name = sim.link_name
        targets = np.hstack(
            [command, np.broadcast_to(held, (K, len(held)))]
        ).tolist()  # one list per step, made at once
        target_velocities = np.hstack([command_velocity, np.zeros((K, len(held)))]).tolist()
        position_gains, velocity_gains = [settings.position_gain] * len(index), [settings.velocity_gain] * len(index)
        start = time.monotonic()
        for k in range(K):
            if k == 0:  # the state the motion starts from: measured, with its contacts, before any step
                pb.performCollisionDetection(physicsClientId=client)
            else:
                pb.setJointMotorControlArray(
                    body,
                    index,
                    pb.POSITION_CONTROL,
                    targetPositions=targets[k],
                    targetVelocities=target_velocities[k],
                    forces=effort,
                    positionGains=position_gains,
                    velocityGains=velocity_gains,
                    physicsClientId=client,
                )
                pb.stepSimulation(physicsClientId=client)
            states = pb.getJointStates(body, index[:n], physicsClientId=client)
            q[k] = [s[0] for s in states]
            qd[k] = [s[1] for s in states]
            for h, link in hand_links.items():
                hand_poses[h][k] = sim.link_pose(link)
            depth: dict[tuple[str, str], float] = {}
            for contact in filter(in_contact, pb.getContactPoints(bodyA=body, physicsClientId=client)):
                other = contact[2]
                first, second = sorted(
                    (
                        link_name[contact[3]],
                        link_name[contact[4]] if other == body else self.objects.get(other, str(other)),
                    )
                )
                key = (first, second)
                depth[key] = max(depth.get(key, 0.0), -float(contact[8]))
                counter = (
                    expected_contacts
                    if key in self.expected_pairs
                    else self_contacts
                    if other == body
                    else environment_contacts
                )
                counter[k] += 1
            events += [
                ContactEvent(float(t[k]), int(rep[k]), a, b, d, (a, b) in self.expected_pairs)
                for (a, b), d in sorted(depth.items())
            ]
            if settings.gui:
                time.sleep(max(0.0, start + t[k] - time.monotonic()))
        return ExecutionLog(
            joint_names=trajectory.joint_names,
            t=t,
            q=q,
            qd=qd,
            q_command=expected,
            rep=rep,
            hand_poses=hand_poses,
            self_contacts=self_contacts,
            environment_contacts=environment_contacts,
            expected_contacts=expected_contacts,
            contact_events=tuple(events),
            fixed=trajectory.fixed,
        )
