"""robot.toml and URDF loading."""

import re
import shutil

import pytest

from dualarm.errors import RobotModelError
from dualarm.model.robot import load_robot, robot_from_urdf
from dualarm.sim.world import load_pybullet_robot, pb
from tests.helpers import HUMANOID


def test_chains_and_hands(humanoid):
    assert set(humanoid.chains) == {"left_arm", "right_arm", "waist"}
    assert humanoid.hands == ("left", "right")
    assert humanoid.chain("left_arm").dof == 7 and humanoid.chain("waist").dof == 3
    assert humanoid.chain_between("base_link", "left_hand").dof == 10
    assert len(humanoid.joint_names) == 17


@pytest.mark.integration
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
        (
            lambda t: t.replace("waist_yaw = 4.0", "waist_yaw = -4.0"),
            "limits.acceleration.waist_yaw: -4 is outside the allowed range [0.01, 10000]",
        ),
        (
            lambda t: t.replace('urdf = "humanoid.urdf"', 'urdf = "missing.urdf"'),
            "missing.urdf: cannot read the URDF: No such file or directory",
        ),
        (lambda t: t + "\n[home.bad]\nnot_a_joint = 1.0\n", "home.bad.not_a_joint: no such joint"),
        (
            lambda t: t + '\n[collision]\ndisabled = [["torso", "head"]]\n',
            "collision.disabled[0]: expected [link, link, reason], got ['torso', 'head']",
        ),
        (
            lambda t: t + '\n[collision]\ndisabled = [["torso", "tail", "rigid"]]\n',
            "collision.disabled[0]: no link 'tail' in the URDF",
        ),
        (
            lambda t: t + '\n[collision]\ndisabled = [["torso", "head", "because"]]\n',
            "collision.disabled[0]: reason 'because' is not one of rigid, always, user",
        ),
        (lambda t: t + "\n[collision]\nenabled = []\n", "collision.enabled: unknown key"),
        (
            lambda t: t.replace("[limits.acceleration]", '[limits]\nassumed = ["speed"]\n\n[limits.acceleration]', 1),
            "limits.assumed: expected a list of limit kinds (velocity, acceleration, jerk), got ['speed']",
        ),
    ],
)
def test_malformed_robot_toml(tmp_path, edit, message):
    for f in HUMANOID.iterdir():
        shutil.copy(f, tmp_path / f.name)
    (tmp_path / "robot.toml").write_text(edit((HUMANOID / "robot.toml").read_text()))
    with pytest.raises(RobotModelError, match=re.escape(message)):
        load_robot(tmp_path)


def test_missing_robot_directory(tmp_path):
    with pytest.raises(RobotModelError, match="nowhere: no robot.toml"):
        load_robot(tmp_path / "nowhere")


# ---------------------------------------------------------------------------------------------
# Absurd numbers and wrong types in robot.toml and the URDF: one line naming the key


def copy_humanoid(tmp_path):
    for f in HUMANOID.iterdir():
        shutil.copy(f, tmp_path / f.name)
    return tmp_path


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        (
            "waist_yaw = 4.0",
            "waist_yaw = 1e300",
            "robot.toml:limits.acceleration.waist_yaw: 1e+300 is outside the allowed range [0.01, 10000]",
        ),
        (
            "waist_yaw = 40.0",
            "waist_yaw = 1e-300",
            "robot.toml:limits.jerk.waist_yaw: 1e-300 is outside the allowed range [0.1, 1e+06]",
        ),
        ("waist_yaw = 40.0", "waist_yaw = inf", "robot.toml:limits.jerk.waist_yaw: expected a finite number, got inf"),
        ("waist_yaw = 40.0", "waist_yaw = nan", "robot.toml:limits.jerk.waist_yaw: expected a finite number, got nan"),
        (
            "left_elbow = -1.5708",
            "left_elbow = 1" + "0" * 400,
            "robot.toml:home.ready.left_elbow: expected a finite number, got 100000",
        ),
        ('name = "humanoid"', "name = 5", "robot.toml:name: expected a non-empty string, got 5"),
        (
            'urdf = "humanoid.urdf"',
            'urdf = ["humanoid.urdf"]',
            "robot.toml:urdf: expected a non-empty string, got ['humanoid.urdf']",
        ),
        ('base = "pelvis"', "base = 1", "robot.toml:chains.waist.base: expected a non-empty string, got 1"),
        ("[chains.waist]", '[chains.waist]\n"' + "k" * 5000 + '" = 1', "robot.toml:chains.waist.kkkkkkkkkk"),
    ],
    ids=[
        "acceleration_1e300",
        "jerk_1e-300",
        "jerk_inf",
        "jerk_nan",
        "home_1e400",
        "name_int",
        "urdf_list",
        "base_int",
        "long_key",
    ],
)
def test_absurd_robot_toml(tmp_path, old, new, message):
    directory = copy_humanoid(tmp_path)
    text = (HUMANOID / "robot.toml").read_text()
    assert text.count(old) == 1, old
    (directory / "robot.toml").write_text(text.replace(old, new))
    with pytest.raises(RobotModelError) as info:
        load_robot(directory)
    assert message in str(info.value) and "\n" not in str(info.value) and len(str(info.value)) < 400, str(info.value)[
        :1000
    ]
    assert "k" * 100 not in str(info.value)  # a long key is quoted short


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        (
            '<joint name="waist_yaw" type="revolute">',
            '<joint name="waist_yaw" type="revolute">\n<axis xyz="0 0 nan"/>',
            "joint 'waist_yaw' axis: expected finite numbers",
        ),
        ('lower="-0.785398"', 'lower="nan"', "joint 'waist_yaw' has a NaN limit"),
    ],
    ids=["nan_axis", "nan_limit"],
)
def test_non_finite_urdf_numbers(tmp_path, old, new, message):
    directory = copy_humanoid(tmp_path)
    text = (HUMANOID / "humanoid.urdf").read_text()
    assert text.count(old) == 1, old
    (directory / "humanoid.urdf").write_text(text.replace(old, new, 1))
    with pytest.raises(RobotModelError, match=re.escape(message)):
        load_robot(directory)


def test_urdf_origin_overflowing_to_inf(tmp_path):
    """1e400 is a valid XML attribute that float() reads as inf: refused, naming the joint's origin."""
    directory = copy_humanoid(tmp_path)
    text = (HUMANOID / "humanoid.urdf").read_text()
    first = text.index('<origin xyz="', text.index('<joint name="waist_yaw"'))
    end = text.index('"', first + len('<origin xyz="'))
    (directory / "humanoid.urdf").write_text(text[: first + len('<origin xyz="')] + "1e400 0 0" + text[end:])
    with pytest.raises(
        RobotModelError, match=r"joint 'waist_yaw' origin xyz: expected finite numbers, got \[inf, 0, 0\]"
    ):
        load_robot(directory)


def test_urdf_entity_bomb_and_deep_nesting(tmp_path):
    """An XML entity bomb (10^10 characters) and 200,000 nested elements: refused in one line, not expanded or recursed
    into."""
    bomb = ['<?xml version="1.0"?>', "<!DOCTYPE robot [", ' <!ENTITY e0 "aaaaaaaaaa">']
    bomb += [f' <!ENTITY e{i} "{f"&e{i - 1};" * 10}">' for i in range(1, 10)]
    bomb += ["]>", '<robot name="&e9;"><link name="a"/></robot>']
    (tmp_path / "bomb.urdf").write_text("\n".join(bomb))
    (tmp_path / "deep.urdf").write_text(
        '<robot name="x">' + '<link name="a">' * 200_000 + "</link>" * 200_000 + "</robot>"
    )
    for name, needle in (("bomb.urdf", "not valid XML"), ("deep.urdf", "nested too deeply")):
        with pytest.raises(RobotModelError) as info:
            robot_from_urdf(tmp_path / name, "a", "a")
        assert needle in str(info.value) and "\n" not in str(info.value), str(info.value)[:500]
