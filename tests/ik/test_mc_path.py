"""MC-Inverse along a path: master-slave, repetition consistency, named failures."""

import numpy as np
import pytest

from pipeline.errors import StageError
from pipeline.ik.mc_path import solve_mc_inverse
from pipeline.model.kinematics import ChainKinematics
from pipeline.model.poses import invert
from pipeline.paths import build_reference
from pipeline.tasks import load_task
from tests.conftest import HUMANOID, TASKS


@pytest.fixture(scope="module")
def carry_box():
    task = load_task(TASKS / "carry_box.toml")
    ref = build_reference(task)
    return task, ref, solve_mc_inverse(task, ref)


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
    path.write_text(text + '\n[arm_angle]\nmax_joint_step_rad = 1e-6\n')
    task = load_task(path)
    with pytest.raises(StageError, match=r"MC-Inverse, left arm: left_\w+ jumps [\d.]+ rad between samples 0 and 1 \(t = 0\.010 s\)"):
        solve_mc_inverse(task, build_reference(task))


def test_a_scheduled_arm_angle_repeats_with_the_repetitions(tmp_path):
    """A schedule over the time within a repetition (here 0 -> 0.1 -> 0 rad over carry_box's 4 s
    repetitions) gives every repetition the first one's joints, sample for sample."""
    text = (TASKS / "carry_box.toml").read_text().replace('robot = "../robots/humanoid"', f'robot = "{HUMANOID}"')
    path = tmp_path / "carry_box.toml"
    path.write_text(text + '\n[arm_angle]\nmode = "schedule"\nschedule = { left = [[0.0, 0.0], [2.0, 0.1], [4.0, 0.0]], right = [[0.0, 0.0], [2.0, -0.1], [4.0, 0.0]] }\n')
    task = load_task(path)
    ref = build_reference(task)
    joints = solve_mc_inverse(task, ref)
    first = joints.q[ref.rep == 0][1:]
    assert np.abs(first[199] - joints.q[ref.rep == 0][0]).max() > 1e-3  # the schedule does move the arm
    for r in range(1, 5):
        assert np.abs(joints.q[ref.rep == r] - first).max() <= 1e-9
