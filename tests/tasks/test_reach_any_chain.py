"""The loader's reach test on an arm that is not S-R-S (the Panda): numeric IK inside the joint limits, cross-checked by
PyBullet."""

from pathlib import Path

import numpy as np
import pybullet as pb
import pybullet_data
import pytest
from tests.helpers import TASKS

from dualarm.errors import UnreachablePoseError
from dualarm.model.kinematics import hand_pose
from dualarm.tasks.load import load_task
from dualarm.tasks.reach import NumericReach, arm_reach

TASK = Path(__file__).parents[1] / "panda" / "panda_triangle.toml"
ARM = tuple(f"panda_joint{i}" for i in range(1, 8))


def _task_with_b_at(tmp_path: Path, position: list[float], rpy: list[float]) -> Path:
    text = TASK.read_text().replace('robot = "../../robots/panda"', f'robot = "{TASK.parents[2] / "robots" / "panda"}"')
    text = text.replace("position = [0.41, 0.15, 0.405]\nrpy = [2.94, 0.2, 0.3]", f"position = {position}\nrpy = {rpy}")
    path = tmp_path / "panda_triangle.toml"
    path.write_text(text)
    return path


def _pybullet_reach(seeds: int) -> float:
    """The farthest any of ``seeds`` random configurations within the limits puts the Panda's grasp target from its base
    [m], by PyBullet on pybullet_data's URDF (a lower bound of the true reach)."""
    client = pb.connect(pb.DIRECT)
    try:
        body = pb.loadURDF(
            str(Path(pybullet_data.getDataPath()) / "franka_panda" / "panda.urdf"),
            useFixedBase=True,
            physicsClientId=client,
        )
        limits = np.array([pb.getJointInfo(body, i, physicsClientId=client)[8:10] for i in range(7)])
        rng = np.random.default_rng(0)
        far = 0.0
        for _ in range(seeds):
            for i, value in enumerate(rng.uniform(limits[:, 0], limits[:, 1])):
                pb.resetJointState(body, i, value, physicsClientId=client)
            far = max(
                far,
                float(
                    np.linalg.norm(pb.getLinkState(body, 11, computeForwardKinematics=True, physicsClientId=client)[4])
                ),
            )
    finally:
        pb.disconnect(client)
    return far


def test_the_panda_gets_the_numeric_test_and_the_humanoid_keeps_the_closed_form():
    assert isinstance(arm_reach(load_task(TASK), "right"), NumericReach)
    assert not isinstance(arm_reach(load_task(TASKS / "triangle.toml"), "left"), NumericReach)


def test_a_pose_outside_the_workspace_is_refused_naming_the_key(tmp_path):
    # 1.2 m above the base's joint-2 centre at z = 0.333 m: the arm's links add up to 0.316 + 0.0825 + 0.384 + 0.0825 +
    # 0.088 + 0.107 + 0.105 = 1.165 m
    with pytest.raises(UnreachablePoseError) as caught:
        load_task(_task_with_b_at(tmp_path, [0.0, 0.0, 1.55], [3.14, 0.0, 0.0]))
    message = str(caught.value)
    assert (
        "\n" not in message
        and ":waypoints.B: the right hand cannot reach [0.000, 0.000, 1.550]" in message
        and "joint limits" in message
    )


@pytest.mark.integration
def test_a_pose_made_by_forward_kinematics_inside_the_limits_is_accepted_and_pybullet_reaches_it(tmp_path):
    task = load_task(TASK)
    lower, upper = task.robot.lower_upper(ARM)
    q = np.random.default_rng(5).uniform(lower + 0.1, upper - 0.1)
    T = hand_pose(task.robot, "right", dict(zip(ARM, q, strict=True)))  # reachable by construction
    reach = arm_reach(task, "right")
    assert reach.within(T[None]).all()
    x, _, _ = reach.solve(T)
    assert x is not None and ((lower - 1e-12 <= x) & (x <= upper + 1e-12)).all()
    # the configuration the test found, put into PyBullet's own panda.urdf, reaches the pose
    client = pb.connect(pb.DIRECT)
    try:
        body = pb.loadURDF(
            str(Path(pybullet_data.getDataPath()) / "franka_panda" / "panda.urdf"),
            useFixedBase=True,
            physicsClientId=client,
        )
        for i, value in enumerate(x):
            pb.resetJointState(body, i, value, physicsClientId=client)
        state = pb.getLinkState(body, 11, computeForwardKinematics=True, physicsClientId=client)
        assert pb.getJointInfo(body, 11, physicsClientId=client)[12].decode() == "panda_grasptarget"
        reached_R = np.array(pb.getMatrixFromQuaternion(state[5])).reshape(3, 3)
    finally:
        pb.disconnect(client)
    assert np.linalg.norm(np.array(state[4]) - T[:3, 3]) < 1e-4
    assert np.abs(reached_R - T[:3, :3]).max() < 1e-3


@pytest.mark.integration
def test_the_refused_height_is_beyond_every_sampled_configuration():
    assert _pybullet_reach(seeds=2000) < 1.55
