"""CasADi chain kinematics against adam-robotics, PyBullet and finite differences."""

import numpy as np
import pytest

from dualarm.describe.check import (
    FK_TOLERANCE,
    JACOBIAN_TOLERANCE,
    PYBULLET_TOLERANCE,
    adam_poses,
    check_chain,
    finite_difference_jacobians,
    pybullet_poses,
)
from dualarm.model.kinematics import ChainKinematics
from dualarm.model.poses import pose_errors
from dualarm.model.robot import random_configurations, robot_from_urdf


@pytest.mark.integration
@pytest.mark.parametrize("chain_name", ["left_arm", "right_arm", "waist"])
def test_humanoid_chains_pass_robot_check(humanoid, chain_name):
    result = check_chain(humanoid, humanoid.chain(chain_name), samples=1000, seed=1)
    assert result.fk_position_error_m <= FK_TOLERANCE
    assert result.fk_rotation_error_rad <= FK_TOLERANCE
    assert result.pybullet_position_error_m <= PYBULLET_TOLERANCE
    assert result.pybullet_rotation_error_rad <= PYBULLET_TOLERANCE
    assert result.jacobian_error <= JACOBIAN_TOLERANCE
    assert result.passed


@pytest.mark.integration
def test_waist_and_arm_chain_from_floor_matches_pybullet(humanoid):
    chain = humanoid.chain_between("base_link", "right_hand")  # 10 DOF: waist + arm
    assert chain.dof == 10
    Q = random_configurations(humanoid, chain, 200, seed=3)
    ours = ChainKinematics.of(chain).poses(Q)
    position, rotation = pose_errors(ours, pybullet_poses(humanoid, chain, Q))
    assert position.max() <= PYBULLET_TOLERANCE and rotation.max() <= PYBULLET_TOLERANCE
    position, rotation = pose_errors(ours, adam_poses(humanoid, chain, Q))
    assert position.max() <= FK_TOLERANCE and rotation.max() <= FK_TOLERANCE


@pytest.mark.integration
def test_bare_urdf_chain_of_another_robot(kuka_urdf):
    robot = robot_from_urdf(kuka_urdf, "lbr_iiwa_link_0", "lbr_iiwa_link_7")
    result = check_chain(robot, robot.chain("chain"), samples=300, seed=2)
    assert result.dof == 7
    assert result.passed, result


def test_mapped_evaluation_equals_single_calls(humanoid):
    kin = ChainKinematics.of(humanoid.chain("left_arm"))
    Q = random_configurations(humanoid, kin.chain, 50, seed=4)
    singles = np.stack([kin.pose(q) for q in Q])
    np.testing.assert_array_equal(kin.poses(Q), singles)
    jac_singles = np.stack([np.asarray(kin.jacobian(q)) for q in Q])
    np.testing.assert_array_equal(kin.jacobians(Q), jac_singles)


def test_jacobian_detects_a_wrong_column(humanoid):
    """The finite-difference comparison is sensitive: a Jacobian of the wrong chain fails it."""
    kin = ChainKinematics.of(humanoid.chain("left_arm"))
    Q = random_configurations(humanoid, kin.chain, 20, seed=5)
    fd = finite_difference_jacobians(kin, Q)
    assert np.abs(kin.jacobians(Q) - fd).max() <= JACOBIAN_TOLERANCE
    assert np.abs(kin.jacobians(Q)[:, :, ::-1] - fd).max() > 1e-2
