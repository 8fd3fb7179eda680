"""ikfast-style baseline (theta_3 free, discretised): exactness against independent forward
kinematics (adam-robotics), reachability per free value, nearest-solution selection, refusals."""

import numpy as np
import pytest

from dualarm.describe.check import adam_poses
from dualarm.ik.analytic.ikfast_style import IkfastStyle
from dualarm.ik.analytic.mc_inverse import OUT_OF_REACH, OUTSIDE_LIMITS, SINGULAR, VALID
from dualarm.model.kinematics import ChainKinematics
from dualarm.model.poses import pose_errors
from dualarm.model.robot import random_configurations, robot_from_urdf

#: Largest joint difference [rad] between IK(FK(q)) and q. The KUKA URDF writes pi/2 as
#: 1.57079632679, so its axes meet and are perpendicular only to ~5e-12; near a wrist singularity
#: or where the two shoulder roots of a free value nearly merge that rounding moves the joint
#: values by up to ~1e-8 rad while the pose stays exact (as in test_mc_inverse).
CONTAINS = {"left": 1e-9, "right": 1e-9, "kuka": 1e-7}


def _arm(request, which: str):
    if which == "kuka":
        robot = robot_from_urdf(request.getfixturevalue("kuka_urdf"), "lbr_iiwa_link_0", "lbr_iiwa_link_7")
        return robot, robot.chain("chain")
    robot = request.getfixturevalue("humanoid")
    return robot, robot.hand_chain(which)


@pytest.mark.parametrize("which", ["left", "right", "kuka"])
def test_ik_of_fk_at_its_own_theta3_contains_q_and_valid_candidates_reach_the_pose(request, which):
    """2000 random configurations within limits: IK(FK(q), q_3) holds q, and every valid candidate
    reproduces the pose by adam-robotics' forward kinematics to 1e-9 m / 1e-9 rad."""
    robot, chain = _arm(request, which)
    ik = IkfastStyle.of(chain)
    Q = random_configurations(robot, chain, 2000, seed=11)
    T = adam_poses(robot, chain, Q)
    C, reason = ik.solve_many(T, Q[:, 2])
    assert np.abs(C - Q[:, None, :]).max(axis=2).min(axis=1).max() <= CONTAINS[which]
    valid = reason == VALID
    assert valid.sum() >= 4 * len(Q)
    assert np.all(C[..., 2] == Q[:, None, 2])  # the free joint is returned as given
    reached = adam_poses(robot, chain, C[valid])
    position, rotation = pose_errors(reached, np.repeat(T[:, None], 8, axis=1)[valid])
    assert position.max() <= 1e-9 and rotation.max() <= 1e-9


def test_other_free_values_reach_the_pose_exactly_when_the_shoulder_can(humanoid):
    """At a random theta_3 the shoulder must turn v = W - S of (0, 0, theta_3, q_4, 0, 0, 0) onto
    W - S of q. About the perpendicular axes k1 (fixed) and k2 this is possible exactly when
    (k1 . u)^2 + (k2 . v)^2 <= |v|^2; candidates flagged out of reach are those where it is not,
    and every valid candidate reaches the pose (adam-robotics) with the requested theta_3."""
    chain = humanoid.hand_chain("left")
    ik = IkfastStyle.of(chain)
    kin = ChainKinematics.of(chain)
    rng = np.random.default_rng(12)
    Q = random_configurations(humanoid, chain, 2000, seed=12)
    T = kin.poses(Q)
    theta3 = rng.uniform(ik.lower[2], ik.upper[2], len(Q))
    C, reason = ik.solve_many(T, theta3)

    J0 = kin.jacobians(np.zeros((1, 7)))[0]
    k1, k2 = J0[3:, 0], J0[3:, 1]  # joint axes at q = 0 in the base frame
    assert abs(k1 @ k2) < 1e-15

    def points(q):
        return [np.asarray(x).ravel() for x in ik.kinematics.points(q)]

    margin, checked = 1e-9, 0
    for i in range(len(Q)):
        S, _, W = points(Q[i])
        u = W - S
        branch = 0 if abs(C[i, 0, 3] - Q[i, 3]) < abs(C[i, 4, 3] - Q[i, 3]) else 4  # q's elbow root
        v = points(np.array([0, 0, theta3[i], Q[i, 3], 0, 0, 0]))[2] - S
        slack = (v @ v - (k1 @ u) ** 2 - (k2 @ v) ** 2) / (v @ v)
        if abs(slack) > margin:
            checked += 1
            assert np.all((reason[i, branch : branch + 4] == OUT_OF_REACH) == (slack < 0)), i
    assert checked > 1900
    assert (reason == OUT_OF_REACH).any() and (reason == VALID).any()

    valid = reason == VALID
    assert np.all(C[..., 2][valid] == np.repeat(theta3[:, None], 8, axis=1)[valid])
    reached = adam_poses(humanoid, chain, C[valid])
    position, rotation = pose_errors(reached, np.repeat(T[:, None], 8, axis=1)[valid])
    assert position.max() <= 1e-9 and rotation.max() <= 1e-9


def test_reasons_outside_limits_match_the_urdf_limits(humanoid):
    chain = humanoid.hand_chain("right")
    ik = IkfastStyle.of(chain)
    Q = random_configurations(humanoid, chain, 2000, seed=13)
    C, reason = ik.solve_many(ChainKinematics.of(chain).poses(Q), Q[:, 2])
    lower, upper = humanoid.lower_upper(chain.joint_names)
    outside = np.any((C < lower) | (C > upper), axis=2)
    assert np.array_equal(reason == OUTSIDE_LIMITS, outside & (reason != SINGULAR) & (reason != OUT_OF_REACH))
    assert (reason == OUTSIDE_LIMITS).any()


def test_free_values_span_the_limits_at_the_resolution(humanoid):
    ik = IkfastStyle.of(humanoid.hand_chain("left"), resolution_rad=0.01)
    lower, upper = humanoid.lower_upper(humanoid.hand_chain("left").joint_names)
    grid = ik.free_values
    assert grid[0] == lower[2] and grid[-1] == upper[2]
    steps = np.diff(grid)
    assert steps.max() <= 0.01 and steps.min() > 0.0099
    assert len(grid) == int(np.ceil((upper[2] - lower[2]) / 0.01)) + 1


@pytest.mark.parametrize("which", ["left", "kuka"])
def test_nearest_returns_a_configuration_on_the_grid(request, which):
    """A configuration whose theta_3 is a grid value, given as the previous solution, is returned
    itself; from a perturbed seed the choice is valid, reaches the pose and is at least as near the
    seed as that configuration."""
    robot, chain = _arm(request, which)
    ik = IkfastStyle.of(chain)
    rng = np.random.default_rng(14)
    Q = random_configurations(robot, chain, 20, seed=14)
    Q[:, 2] = ik.free_values[rng.integers(0, len(ik.free_values), len(Q))]
    T = adam_poses(robot, chain, Q)
    for q, pose in zip(Q, T, strict=True):
        result = ik.nearest(pose, q)
        assert result.ok
        assert np.abs(result.q - q).max() <= CONTAINS[which]
        assert result.free_value == q[2]

        seed = q + rng.normal(0, 0.05, 7)
        result = ik.nearest(pose, seed)
        assert result.ok and result.q[2] == result.free_value and result.free_value in ik.free_values
        assert np.linalg.norm(result.q - seed) <= np.linalg.norm(q - seed) + CONTAINS[which]
        assert np.all((result.q >= ik.lower) & (result.q <= ik.upper))
        position, rotation = pose_errors(adam_poses(robot, chain, result.q[None]), pose[None])
        assert position[0] <= 1e-9 and rotation[0] <= 1e-9


def test_out_of_reach_pose_keeps_the_seed(humanoid):
    chain = humanoid.hand_chain("left")
    ik = IkfastStyle.of(chain)
    seed = np.array([0.3, 0.4, 0.2, -1.0, 0.1, 0.5, 0.2])
    far = ChainKinematics.of(chain).pose(seed)
    far[:3, 3] += [2.0, 0.0, 0.0]  # 2 m beyond an arm well under 1 m long
    assert ik.kinematics.geometry.reach < 1.0
    result = ik.nearest(far, seed)
    assert not result.ok
    assert np.array_equal(result.q, seed) and np.isnan(result.free_value)


def test_a_repeated_path_is_solved_as_each_pose_alone(humanoid):
    """Along the circle task (its poses met again in each repetition, their candidates then reused): every sample is
    :meth:`IkfastStyle.nearest` of its pose from the previous solution, computed here without reuse."""
    from pathlib import Path

    from dualarm.ik.pose_level.pointwise import arm_problems, solve_pointwise
    from dualarm.paths import build_reference
    from dualarm.tasks import load_task

    reference = build_reference(load_task(Path(__file__).resolve().parents[2] / "tasks" / "circle.toml"))
    path = solve_pointwise("ikfast-style", humanoid, reference, "ready")
    (arm,) = arm_problems(humanoid, reference, humanoid.configuration("ready", "q0"))
    ik = IkfastStyle.of(arm.chain)
    seed = arm.q0
    index = [path.joint_names.index(j) for j in arm.chain.joint_names]
    for k, target in enumerate(arm.targets):
        result = ik.nearest(target, seed)
        assert result.ok and np.array_equal(np.asarray(path.q)[k, index], result.q), k
        seed = result.q
