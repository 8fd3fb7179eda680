"""MC-Inverse along a path: master-slave, repetition consistency, named failures."""

import re

import numpy as np
import pytest

from dualarm.describe.check import adam_poses
from dualarm.errors import StageError
from dualarm.ik.analytic.mc_inverse import McInverse
from dualarm.ik.analytic.mc_path import settings_for, solve_mc_inverse
from dualarm.model.kinematics import ChainKinematics
from dualarm.model.poses import invert, pose_errors
from dualarm.paths import build_reference
from dualarm.tasks import load_task
from tests.helpers import HUMANOID, TASKS


@pytest.fixture(scope="module")
def carry_box():
    task = load_task(TASKS / "carry_box.toml")
    ref = build_reference(task)
    return task, ref, solve_mc_inverse(task.robot, ref, task.initial_q, settings_for(task))


def test_master_slave_relative_pose_is_constant(carry_box):
    """Eq (11): both hands hold the box, so the left-to-right hand transform of the IK output,
    by the chains' forward kinematics, stays what it was at the first sample to 1e-9 m."""
    task, ref, path = carry_box
    poses = {}
    for hand in ("left", "right"):
        chain = task.hand_chain_from_root(hand)
        Q = np.array([[path.configuration(k)[n] for n in chain.joint_names] for k in range(len(path))])
        poses[hand] = ChainKinematics.of(chain).poses(Q)
    relative = invert(poses["left"]) @ poses["right"]
    assert np.abs(relative - relative[0]).max() <= 1e-9
    assert path.hand_error_m.max() <= 1e-9


def test_repetitions_give_identical_joints(carry_box):
    """Arm angle held and branch kept: every repetition's joints equal the first's to 1e-9 rad."""
    _, ref, path = carry_box
    reps = [path.q[ref.rep == r] for r in np.unique(ref.rep)]
    first = reps[0][1:]  # the first repetition also holds the start sample
    assert len(reps) == 5
    for later in reps[1:]:
        assert np.abs(later - first).max() <= 1e-9


def test_a_joint_jump_fails_naming_the_sample(tmp_path):
    text = (TASKS / "carry_box.toml").read_text().replace('robot = "../robots/humanoid"', f'robot = "{HUMANOID}"')
    path = tmp_path / "carry_box.toml"
    path.write_text(text.replace("[arm_angle]\n", "[arm_angle]\nmax_joint_step_rad = 1e-6\n"))
    task = load_task(path)
    with pytest.raises(
        StageError, match=r"MC-Inverse, left arm: left_\w+ jumps [\d.]+ rad between samples 0 and 1 \(t = 0\.010 s\)"
    ):
        solve_mc_inverse(task.robot, build_reference(task), task.initial_q, settings_for(task))


def test_a_scheduled_arm_angle_repeats_with_the_repetitions(tmp_path):
    """A schedule over the time within a repetition (here 0 -> 0.1 -> 0 rad over carry_box's 4 s
    repetitions) gives every repetition the first one's joints, sample for sample."""
    text = (TASKS / "carry_box.toml").read_text().replace('robot = "../robots/humanoid"', f'robot = "{HUMANOID}"')
    path = tmp_path / "carry_box.toml"
    path.write_text(
        text.replace(
            '[arm_angle]\nmode = "initial"\n',
            '[arm_angle]\nmode = "schedule"\nschedule = { left = [[0.0, 0.0], [2.0, 0.1], [4.0, 0.0]],'
            " right = [[0.0, 0.0], [2.0, -0.1], [4.0, 0.0]] }\n",
        )
    )
    task = load_task(path)
    ref = build_reference(task)
    joints = solve_mc_inverse(task.robot, ref, task.initial_q, settings_for(task))
    first = joints.q[ref.rep == 0][1:]
    assert np.abs(first[199] - joints.q[ref.rep == 0][0]).max() > 1e-3  # the schedule does move the arm
    for r in range(1, 5):
        assert np.abs(joints.q[ref.rep == r] - first).max() <= 1e-9


@pytest.mark.parametrize("name", ["triangle", "circle"])
def test_auto_arm_angle_completes_the_papers_repeated_paths(name):
    """Triangle and circle with ``mode = "auto"`` and the paper's psi range (-pi, 0): adam's
    double-precision forward kinematics of the joints meets the path to 1e-9 m / 1e-9 rad at every
    sample, every joint is inside its URDF limits, psi(q) by eq (1) stays in the range and is the
    same in every repetition, and repetitions give identical joints."""
    task = load_task(TASKS / f"{name}.toml")
    ref = build_reference(task)
    path = solve_mc_inverse(task.robot, ref, task.initial_q, settings_for(task))
    chain = task.robot.hand_chain("left")
    q = np.array([[path.configuration(k)[n] for n in chain.joint_names] for k in range(len(path))])
    lower, upper = task.robot.lower_upper(chain.joint_names)
    assert ((q >= lower) & (q <= upper)).all()
    torso = task.robot.chain_between(ref.frame, chain.base)
    base = ChainKinematics.of(torso).pose(np.array([task.initial_q[n] for n in torso.joint_names]))
    position, rotation = pose_errors(base[None] @ adam_poses(task.robot, chain, q), ref.hands["left"].poses)
    assert position.max() <= 1e-9 and rotation.max() <= 1e-9
    psi = McInverse.of(chain).kinematics.arm_angles(q)
    assert ((psi > -np.pi) & (psi < 0)).all()
    first = q[ref.rep == 0][1:]
    for r in range(1, 5):
        assert np.abs(q[ref.rep == r] - first).max() <= 1e-9
    assert np.abs(np.diff(q, axis=0)).max() <= task.spec.arm_angle.max_joint_step_rad


def test_auto_fails_naming_the_sample_when_the_range_is_too_narrow(tmp_path):
    """psi held in (-0.3, 0.3) cannot follow the triangle: one line naming the sample and its time."""
    text = (TASKS / "triangle.toml").read_text().replace('robot = "../robots/humanoid"', f'robot = "{HUMANOID}"')
    path = tmp_path / "triangle.toml"
    path.write_text(text.replace("range_rad = [-3.141592653589793, 0.0]", "range_rad = [-0.3, 0.3]"))
    task = load_task(path)
    ref = build_reference(task)
    with pytest.raises(
        StageError,
        match=r"^MC-Inverse, left arm: no arm angle in arm_angle.range_rad .* beyond sample \d+ \(t = [\d.]+ s\)$",
    ) as failure:
        solve_mc_inverse(task.robot, ref, task.initial_q, settings_for(task))
    k, t = re.search(r"sample (\d+) \(t = ([\d.]+) s\)", str(failure.value)).groups()
    assert 0 < int(k) < len(ref) and float(t) == pytest.approx(ref.t[int(k)], abs=1e-3)
