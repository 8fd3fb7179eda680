"""robot.toml and URDF loading."""

import shutil

import pytest

from dualarm.errors import RobotModelError
from dualarm.execute.world import load_pybullet_robot, pb
from dualarm.model.robot import load_robot
from tests.conftest import HUMANOID


def test_chains_and_hands(humanoid):
    assert set(humanoid.chains) == {"left_arm", "right_arm", "waist"}
    assert humanoid.hands == ("left", "right")
    assert humanoid.chain("left_arm").dof == 7 and humanoid.chain("waist").dof == 3
    assert humanoid.chain_between("base_link", "left_hand").dof == 10
    assert len(humanoid.joint_names) == 17


def test_limits_agree_with_pybullet(humanoid):
    """Position and velocity limits as PyBullet reads them from the same URDF."""
    with load_pybullet_robot(humanoid.urdf.path) as sim:
        for name, index in sim.joint_index.items():
            info = pb.getJointInfo(sim.body, index, physicsClientId=sim.client)
            if info[2] == pb.JOINT_FIXED:
                continue
            lim = humanoid.limits[name]
            assert lim.lower == pytest.approx(info[8]) and lim.upper == pytest.approx(info[9])
            assert lim.velocity == pytest.approx(info[11])
            assert 0 < lim.acceleration < float("inf") and 0 < lim.jerk < float("inf")


def test_home_poses_are_within_limits(humanoid):
    for name, q in humanoid.homes.items():
        for joint, value in q.items():
            lim = humanoid.limits[joint]
            assert lim.lower <= value <= lim.upper, (name, joint)


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda t: t.replace('tip = "left_hand"', 'tip = "left_foot"'), "no link 'left_foot'"),
        (lambda t: t.replace("[chains.waist]", "[chains.waist]\ncolour = 1"), "chains.waist.colour: unknown key"),
        (lambda t: t.replace("left_elbow = -1.5708", "left_elbow = -9.0"), "home.ready.left_elbow"),
        (lambda t: t.replace("waist_yaw = 4.0", "waist_yaw = -4.0"), "limits.acceleration.waist_yaw: must be positive"),
        (lambda t: t.replace('urdf = "humanoid.urdf"', 'urdf = "missing.urdf"'), "URDF file not found"),
        (lambda t: t + "\n[home.bad]\nnot_a_joint = 1.0\n", "home.bad.not_a_joint: no such joint"),
    ],
)
def test_malformed_robot_toml(tmp_path, edit, message):
    for f in HUMANOID.iterdir():
        shutil.copy(f, tmp_path / f.name)
    (tmp_path / "robot.toml").write_text(edit((HUMANOID / "robot.toml").read_text()))
    with pytest.raises(RobotModelError, match=message.replace("(", r"\(").replace(")", r"\)")):
        load_robot(tmp_path)


def test_missing_robot_directory(tmp_path):
    with pytest.raises(RobotModelError, match="no robot.toml"):
        load_robot(tmp_path / "nowhere")
