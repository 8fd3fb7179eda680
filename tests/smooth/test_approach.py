"""The approach around an obstacle: where the straight joint-space line collides, a collision-free path.

The obstacle is a box the task places where the left hand passes halfway along the straight line; the
collisions are PyBullet's own contact points (the robot's URDF and the box loaded here, not the
planners' closed-form checker).
"""

from __future__ import annotations

import numpy as np
import pybullet as pb
import pytest

from dualarm.model.kinematics import ChainKinematics
from dualarm.smooth.approach import approach_trajectory, approach_waypoints
from dualarm.tasks import load_task
from tests.helpers import HUMANOID, TASKS, pybullet_urdf

pytestmark = pytest.mark.integration  # PyBullet worlds

#: The left arm's move: from the triangle's initial configuration by these joint changes [rad].
MOVE_RAD = np.array([-0.9, 0.3, 0.0, 0.8, 0.0, 0.0, 0.0])
#: The obstacle's half size [m].
HALF_M = 0.04


def _task(tmp_path, box_at):
    text = (TASKS / "triangle.toml").read_text().replace('robot = "../robots/humanoid"', f'robot = "{HUMANOID}"')
    box = ", ".join(f"{v:.6f}" for v in box_at)
    size = ", ".join([f"{2 * HALF_M}"] * 3)
    text += f'\n[[environment]]\nname = "obstacle"\nshape = "box"\nsize_m = [{size}]\npose = {{ position = [{box}] }}\n'
    path = tmp_path / "triangle.toml"
    path.write_text(text)
    return load_task(path, 1)


def _in_contact(urdf, box, names, Q) -> np.ndarray:
    """Whether the robot touches the box (PyBullet's contact points, no margin) at each row of Q; (M,) bool."""
    hits = []
    for q in Q:
        urdf.set(names, q)
        pb.performCollisionDetection(physicsClientId=urdf.client)
        points = pb.getContactPoints(bodyA=urdf.body, bodyB=box, physicsClientId=urdf.client)
        hits.append(any(p[8] < 0 for p in points))
    return np.array(hits)


def test_a_colliding_straight_approach_goes_around_through_rest_to_rest_segments(tmp_path):
    probe = load_task(TASKS / "triangle.toml", 1)
    robot = probe.robot
    names = robot.hand_chain("left").joint_names
    start = np.array([probe.initial_q[n] for n in names])
    goal = np.clip(start + MOVE_RAD, *robot.lower_upper(names))
    chain = robot.chain_between(robot.urdf.root, robot.hand_chain("left").tip)
    q_full = np.array([probe.initial_q[n] for n in chain.joint_names])
    arm = [chain.joint_names.index(n) for n in names]
    hand = []
    for q in (start, (start + goal) / 2, goal):
        q_full[arm] = q
        hand.append(ChainKinematics.of(chain).pose(q_full)[:3, 3])
    assert min(np.linalg.norm(hand[1] - hand[0]), np.linalg.norm(hand[1] - hand[2])) > 3 * HALF_M
    task = _task(tmp_path, hand[1])
    fixed = {n: v for n, v in task.initial_q.items() if n not in names}

    waypoints = approach_waypoints(task, names, start, goal, fixed)
    limits = [robot.limit_array(k, names) for k in ("velocity", "acceleration", "jerk")]
    traj = approach_trajectory(names, start, goal, *limits, 0.01, fixed, via=list(waypoints[1:-1]))

    with pybullet_urdf(HUMANOID / "humanoid.urdf") as urdf:
        urdf.set(list(fixed), list(fixed.values()))
        shape = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=[HALF_M] * 3, physicsClientId=urdf.client)
        box = pb.createMultiBody(0, shape, basePosition=hand[1].tolist(), physicsClientId=urdf.client)
        line = start + np.linspace(0, 1, 201)[:, None] * (goal - start)
        straight = _in_contact(urdf, box, names, line)
        assert straight.any() and not straight[[0, -1]].any()  # the setup: only the way collides
        assert not _in_contact(urdf, box, names, traj.q).any()

    assert len(waypoints) > 2 and np.array_equal(waypoints[0], start) and np.array_equal(waypoints[-1], goal)
    assert np.allclose(traj.q[0], start) and np.allclose(traj.q[-1], goal, atol=1e-9)
    for w in waypoints[1:-1]:  # the trajectory stops at each waypoint
        k = int(np.argmin(np.abs(traj.q - w).max(axis=1)))
        assert np.abs(traj.q[k] - w).max() < 1e-9 and np.abs(traj.qd[k]).max() < 1e-9
    dt = np.diff(traj.t)
    assert (dt > 0).all()
    velocity = np.diff(traj.q, axis=0) / dt[:, None]  # finite differences, against the limits
    assert (np.abs(velocity) <= limits[0] * (1 + 1e-6)).all()


def test_a_free_straight_approach_is_the_line(tmp_path):
    task = load_task(TASKS / "triangle.toml", 1)
    names = task.robot.hand_chain("left").joint_names
    start = np.array([task.initial_q[n] for n in names])
    goal = start + 0.05
    fixed = {n: v for n, v in task.initial_q.items() if n not in names}
    assert np.array_equal(approach_waypoints(task, names, start, goal, fixed), np.stack([start, goal]))
