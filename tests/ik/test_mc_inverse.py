"""MC-Inverse: exactness against the chains' own forward kinematics and PyBullet, validity flags."""

import numpy as np
import pytest

from dualarm.errors import NotSRSError
from dualarm.ik.analytic.ikfast_style import IkfastStyle
from dualarm.ik.analytic.mc_inverse import OUT_OF_REACH, OUTSIDE_LIMITS, SINGULAR, VALID, McInverse
from dualarm.model.kinematics import ChainKinematics
from dualarm.model.poses import pose_errors
from dualarm.model.robot import Chain, robot_from_urdf
from dualarm.model.urdf import JointSpec
from dualarm.sim.world import load_pybullet_robot


def _roundtrip(mc: McInverse, samples: int, seed: int):
    kin = ChainKinematics.of(mc.chain)
    Q = np.random.default_rng(seed).uniform(mc.lower, mc.upper, (samples, 7))
    T = kin.poses(Q)
    psi = mc.kinematics.arm_angles(Q)
    C, reason = mc.solve_many(T, psi)
    return kin, Q, T, psi, C, reason


@pytest.mark.parametrize("side", ["left", "right"])
def test_ik_of_fk_contains_q_and_every_valid_candidate_reaches_the_pose(humanoid, side):
    """10,000 random configurations within limits: IK(FK(q), psi(q)) holds q to 1e-9 rad; every
    valid candidate reproduces the pose to 1e-9 m / 1e-9 rad and has the same arm angle."""
    mc = McInverse.of(humanoid.chain(f"{side}_arm"))
    kin, Q, T, psi, C, reason = _roundtrip(mc, 10_000, seed=1)
    distance = np.abs(C - Q[:, None, :]).max(axis=2)
    assert distance.min(axis=1).max() <= 1e-9
    valid = reason == VALID
    assert valid.sum() >= 4 * len(Q)  # a pose inside the limits usually has several valid branches
    reached = kin.poses(C[valid])
    targets = np.repeat(T[:, None], 8, axis=1)[valid]
    position, rotation = pose_errors(reached, targets)
    assert position.max() <= 1e-9 and rotation.max() <= 1e-9
    angles = mc.kinematics.arm_angles(C[valid])
    expected = np.repeat(psi[:, None], 8, axis=1)[valid]
    assert np.abs(np.angle(np.exp(1j * (angles - expected)))).max() <= 1e-9


def test_reasons_match_independent_checks(humanoid):
    """A candidate is flagged outside its limits exactly when its values leave the URDF limits."""
    mc = McInverse.of(humanoid.chain("left_arm"))
    _, _, _, _, C, reason = _roundtrip(mc, 2000, seed=2)
    lower, upper = humanoid.lower_upper(mc.chain.joint_names)
    outside = np.any((C < lower) | (C > upper), axis=2)
    assert np.array_equal(reason == OUTSIDE_LIMITS, outside & (reason != SINGULAR) & (reason != OUT_OF_REACH))
    assert (reason == OUTSIDE_LIMITS).any() and (reason == VALID).any()


@pytest.mark.integration
def test_candidates_reach_the_pose_in_pybullet(humanoid):
    mc = McInverse.of(humanoid.chain("right_arm"))
    kin, Q, T, psi, C, reason = _roundtrip(mc, 20, seed=3)
    names = mc.chain.joint_names
    with load_pybullet_robot(humanoid.urdf.path) as sim:
        torso = None
        for i in range(len(Q)):
            for j in np.flatnonzero(reason[i] == VALID):
                sim.set_positions(names, C[i, j])
                torso = sim.link_pose("torso")
                hand = np.linalg.inv(torso) @ sim.link_pose("right_hand")
                assert np.abs(hand[:3, 3] - T[i][:3, 3]).max() < 1e-6
                assert np.abs(hand[:3, :3] - T[i][:3, :3]).max() < 1e-6
    assert torso is not None


def test_out_of_reach_and_straight_elbow_are_flagged(humanoid):
    mc = McInverse.of(humanoid.chain("left_arm"))
    kin = ChainKinematics.of(mc.chain)
    far = kin.pose(np.zeros(7))
    far[:3, 3] += [2.0, 0.0, 0.0]
    assert np.all(mc.solve(far, 0.3).reason == OUT_OF_REACH)
    # the elbow's straight position, found from the geometry: |SW| = L2 + L3
    straight = np.array([0.3, 0.4, 0.2, 0.0, 0.1, 0.5, 0.2])
    S, E, W = (np.asarray(x).ravel() for x in mc.kinematics.points(straight))
    geo = mc.kinematics.geometry
    assert abs(np.linalg.norm(W - S) - geo.reach) < 1e-12  # the humanoid's elbow is straight at zero
    solution = mc.solve(kin.pose(straight), 0.0)
    assert np.all(solution.reason == SINGULAR)


def test_any_srs_arm_the_kuka_iiwa(kuka_urdf, seed=4):
    """A second S-R-S arm from another URDF, with its own axes and offsets. Its URDF writes pi/2 as
    1.57079632679, so its axes are perpendicular only to ~5e-12 rad; near a wrist or shoulder
    singularity (sin ~ 1e-3) that rounding moves the split between the outer angles by up to
    ~1e-8 rad, while the pose stays exact. Hence 1e-7 rad here (1e-9 for the humanoid)."""
    robot = robot_from_urdf(kuka_urdf, "lbr_iiwa_link_0", "lbr_iiwa_link_7")
    mc = McInverse.of(robot.chain("chain"))
    kin, Q, T, psi, C, reason = _roundtrip(mc, 2000, seed=seed)
    assert np.abs(C - Q[:, None, :]).max(axis=2).min(axis=1).max() <= 1e-7
    reached = kin.poses(C[reason == VALID])
    targets = np.repeat(T[:, None], 8, axis=1)[reason == VALID]
    position, rotation = pose_errors(reached, targets)
    assert position.max() <= 1e-9 and rotation.max() <= 1e-9


@pytest.mark.parametrize("solver", [McInverse, IkfastStyle])
def test_non_perpendicular_shoulder_axes_are_refused(humanoid, solver):
    chain = humanoid.chain("left_arm")
    joints = list(chain.joints)
    i = next(k for k, j in enumerate(joints) if j.name == "left_shoulder_pitch")
    j = joints[i]
    tilted = np.array([0.0, 1.0, 0.2]) / np.linalg.norm([0.0, 1.0, 0.2])
    joints[i] = JointSpec(**{**j.__dict__, "axis": tuple(tilted)})
    broken = Chain(name="tilted", base=chain.base, tip=chain.tip, joints=tuple(joints))
    with pytest.raises(NotSRSError, match="left_shoulder_yaw and left_shoulder_pitch are not perpendicular"):
        solver.of(broken)


@pytest.mark.parametrize("solver", [McInverse, IkfastStyle])
def test_waist_and_arm_is_not_srs(humanoid, solver):
    with pytest.raises(NotSRSError, match="10 movable joints"):
        solver.of(humanoid.chain_between("pelvis", "left_hand"))
