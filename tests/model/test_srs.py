"""S-R-S geometry and the arm angle of MC-Inverse eq (1)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dualarm.describe.check import PYBULLET_TOLERANCE
from dualarm.errors import NotSRSError
from dualarm.model.robot import Chain, random_configurations, robot_from_urdf
from dualarm.model.srs import SrsKinematics, arm_angle, srs_geometry
from dualarm.model.urdf import JointSpec
from dualarm.sim.world import load_pybullet_robot


@pytest.mark.integration
@pytest.mark.parametrize("side", ["left", "right"])
def test_shoulder_elbow_wrist_match_pybullet_joint_frames(humanoid, side):
    """S, E, W are the origins of the shoulder, elbow and forearm-roll joints in the URDF."""
    chain = humanoid.chain(f"{side}_arm")
    srs = SrsKinematics.of(chain)
    Q = random_configurations(humanoid, chain, 100, seed=11)
    with load_pybullet_robot(humanoid.urdf.path) as sim:
        for q in Q:
            sim.set_positions(chain.joint_names, q)
            base = np.linalg.inv(sim.link_pose(chain.base))
            expected = [
                (base @ sim.link_pose(link))[:3, 3]
                for link in (f"{side}_shoulder_yaw_link", f"{side}_forearm", f"{side}_forearm_roll_link")
            ]
            for ours, theirs in zip(srs.points(q), expected, strict=True):
                assert np.linalg.norm(np.asarray(ours).ravel() - theirs) <= PYBULLET_TOLERANCE


def test_humanoid_link_lengths(humanoid):
    g = srs_geometry(humanoid.chain("left_arm"))
    assert g.upper_arm == pytest.approx(0.32, abs=1e-12)
    assert g.forearm == pytest.approx(0.28, abs=1e-12)
    np.testing.assert_allclose(g.tool_from_wrist, [0, 0, 0.09], atol=1e-12)


def test_kuka_iiwa_is_srs_with_its_datasheet_lengths(kuka_urdf):
    """The LBR iiwa 14 R820: shoulder-elbow 0.42 m, elbow-wrist 0.40 m (KUKA datasheet)."""
    robot = robot_from_urdf(kuka_urdf, "lbr_iiwa_link_0", "lbr_iiwa_link_7")
    g = srs_geometry(robot.chain("chain"))
    assert g.upper_arm == pytest.approx(0.42, abs=1e-9)
    assert g.forearm == pytest.approx(0.40, abs=1e-9)
    np.testing.assert_allclose(g.shoulder, [0, 0, 0.36], atol=1e-9)


def test_wrist_offset_is_refused_naming_the_axes(humanoid):
    chain = humanoid.chain("left_arm")
    joints = list(chain.joints)
    i = next(k for k, j in enumerate(joints) if j.name == "left_wrist_pitch")
    j = joints[i]
    joints[i] = JointSpec(**{**j.__dict__, "origin_xyz": (0.01, 0.0, 0.0)})
    broken = Chain(name="broken", base=chain.base, tip=chain.tip, joints=tuple(joints))
    with pytest.raises(NotSRSError, match="left_forearm_roll, left_wrist_pitch, left_wrist_roll"):
        srs_geometry(broken)


def test_non_seven_dof_chain_is_refused(humanoid):
    with pytest.raises(NotSRSError, match="3 movable joints"):
        srs_geometry(humanoid.chain("waist"))


@pytest.mark.parametrize(
    ("elbow", "expected"),
    [
        ((0.5, 0.0, -0.3), 0.0),  # below the shoulder-wrist line in the vertical plane
        ((0.5, -0.3, 0.0), np.pi / 2),  # to the right of a forward-pointing arm
        ((0.5, 0.3, 0.0), -np.pi / 2),  # to the left
        ((0.5, 0.0, 0.3), np.pi),  # above
    ],
)
def test_arm_angle_closed_form_cases(elbow, expected):
    S, W = np.zeros(3), np.array([1.0, 0.0, 0.0])
    psi = arm_angle(S, np.array(elbow), W)
    assert np.isclose(np.cos(psi), np.cos(expected), atol=1e-12) and np.isclose(
        np.sin(psi), np.sin(expected), atol=1e-12
    )


def test_arm_angle_measures_rotation_of_the_elbow_about_sw():
    """Self-motion: turning E by delta about -SW, the screw axis xi_SW of MC-Inverse eq (5),
    changes psi by delta (mod 2 pi)."""
    rng = np.random.default_rng(0)
    for _ in range(200):
        S, E, W = rng.normal(size=(3, 3))
        delta = rng.uniform(-3, 3)
        axis = (W - S) / np.linalg.norm(W - S)
        E2 = S + Rotation.from_rotvec(-delta * axis).apply(E - S)
        change = arm_angle(S, E2, W) - arm_angle(S, E, W)
        assert abs(np.angle(np.exp(1j * (change - delta)))) < 1e-9


@pytest.mark.integration
def test_arm_angle_of_q_matches_pybullet_points(humanoid):
    chain = humanoid.chain("left_arm")
    srs = SrsKinematics.of(chain)
    Q = random_configurations(humanoid, chain, 50, seed=12)
    psis = srs.arm_angles(Q)
    with load_pybullet_robot(humanoid.urdf.path) as sim:
        for q, psi in zip(Q, psis, strict=True):
            sim.set_positions(chain.joint_names, q)
            base = np.linalg.inv(sim.link_pose(chain.base))
            S, E, W = (
                (base @ sim.link_pose(link))[:3, 3]
                for link in ("left_shoulder_yaw_link", "left_forearm", "left_forearm_roll_link")
            )
            assert abs(np.angle(np.exp(1j * (psi - arm_angle(S, E, W))))) < 1e-5  # float32 points
