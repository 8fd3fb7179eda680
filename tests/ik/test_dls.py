"""DLS-SVD IK (Li-Liang eqs 12-20) against CasADi and PyBullet forward kinematics, finite-difference
Jacobians and the damped least-squares step written out with numpy."""

import dataclasses

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dualarm.describe.check import JACOBIAN_TOLERANCE, PYBULLET_TOLERANCE, finite_difference_jacobians
from dualarm.errors import InvalidArgumentError, RobotModelError, StageError
from dualarm.ik.pose_level.dls import DlsSettings, DlsSolver
from dualarm.model.kinematics import ChainKinematics
from dualarm.model.poses import pose_errors
from dualarm.sim.world import load_pybullet_robot

#: The three chain sets of the issue: one arm, waist + arm, both arms on the shared waist.
CHAIN_SETS = {
    "arm_7": ("torso", ("left_hand",)),
    "waist_arm_10": ("pelvis", ("left_hand",)),
    "both_arms_17": ("pelvis", ("left_hand", "right_hand")),
}
DOF = {"arm_7": 7, "waist_arm_10": 10, "both_arms_17": 17}
SAMPLES = 100
MARGIN_RAD = 0.1  # truth configurations keep this far from the limits
PERTURBATION_RAD = 0.3  # seeds are the truth plus uniform noise of this size, clipped to the limits
REQUIRED_SUCCESSES = 98
PYBULLET_SAMPLES = 5
TOLERANCE = 1e-9  # the solver's default tolerances, checked by forward kinematics [m, rad]

#: A 7-DOF left-arm configuration away from every singularity (checked in the tests that use it).
GENERIC_ARM = np.array([0.3, -0.5, 0.4, -1.2, 0.3, 0.8, 0.2])
ELBOW = 3  # index of left_elbow in the arm chain


@pytest.fixture(scope="module")
def solvers(humanoid):
    return {name: DlsSolver.of(humanoid, base, tips) for name, (base, tips) in CHAIN_SETS.items()}


def chain_kinematics(robot, solver):
    """Per tip: its own chain's kinematics and the positions of the chain's joints in ``solver.joint_names``."""
    out = []
    for tip in solver.tips:
        kin = ChainKinematics.of(robot.chain_between(solver.base, tip))
        out.append((kin, [solver.joint_names.index(name) for name in kin.chain.joint_names]))
    return out


def tip_poses(kinematics, q):
    return [kin.pose(q[columns]) for kin, columns in kinematics]


def pose_error(target, actual):
    """Position [m] and rotation-angle [rad] difference of two 4x4 poses (scipy)."""
    position, rotation = pose_errors(target[None], actual[None])
    return float(position[0]), float(rotation[0])


def error_vector(target, actual):
    """[p* - p; log(R* R^T)] of the module docstring, with scipy's rotation vector."""
    return np.concatenate(
        [target[:3, 3] - actual[:3, 3], Rotation.from_matrix(target[:3, :3] @ actual[:3, :3].T).as_rotvec()]
    )


def smallest_singular_value(J):
    return np.linalg.svd(J, compute_uv=False)[-1]


def rule(sigma_min, settings):
    """The Nakamura-Maciejewski damping, written out independently of the module."""
    eps, lam_max = settings.singular_region, settings.max_damping
    return lam_max * np.sqrt(1 - (sigma_min / eps) ** 2) if sigma_min < eps else 0.0


def fd_jacobian(kin, q):
    return finite_difference_jacobians(kin, np.asarray(q)[None])[0]


@pytest.mark.parametrize("name", CHAIN_SETS)
def test_joints_are_the_union_of_the_chains_in_urdf_order(humanoid, solvers, name):
    solver = solvers[name]
    waist = humanoid.chain("waist").joint_names
    arms = {"left_hand": humanoid.chain("left_arm").joint_names, "right_hand": humanoid.chain("right_arm").joint_names}
    expected = (waist if solver.base == "pelvis" else ()) + sum((arms[tip] for tip in solver.tips), ())
    assert solver.joint_names == expected
    assert len(solver.joint_names) == DOF[name]
    lower, upper = humanoid.lower_upper(expected)
    np.testing.assert_array_equal(solver.lower, lower)
    np.testing.assert_array_equal(solver.upper, upper)


@pytest.mark.parametrize("name", CHAIN_SETS)
def test_one_function_gives_pose_errors_and_the_stacked_jacobian(humanoid, solvers, name):
    """The shared waist has entries in both hands' rows; every block equals finite differences of
    that hand's own chain, zero in the other arm's columns."""
    solver = solvers[name]
    kinematics = chain_kinematics(humanoid, solver)
    rng = np.random.default_rng(11)
    q = rng.uniform(solver.lower, solver.upper)
    targets = tip_poses(kinematics, rng.uniform(solver.lower, solver.upper))
    x = np.concatenate([q] + [T.ravel(order="F") for T in targets])
    dx, errors, JT = (np.asarray(out) for out in solver.evaluate(x))
    dx, errors, J = dx.ravel(), errors.ravel(), JT.T
    h = len(solver.tips)
    assert J.shape == (6 * h, solver.n)
    for k, ((kin, columns), target) in enumerate(zip(kinematics, targets, strict=True)):
        actual = kin.pose(q[columns])
        np.testing.assert_allclose(dx[6 * k : 6 * k + 6], error_vector(target, actual), atol=1e-12)
        np.testing.assert_allclose(errors[[k, h + k]], pose_error(target, actual), atol=1e-12)
        block = J[6 * k : 6 * k + 6]
        assert np.abs(block[:, columns] - fd_jacobian(kin, q[columns])).max() <= JACOBIAN_TOLERANCE
        others = np.setdiff1d(np.arange(solver.n), columns)
        assert np.all(block[:, others] == 0.0)
    if h == 2:
        waist = [solver.joint_names.index(n) for n in humanoid.chain("waist").joint_names]
        assert np.all(np.abs(J[:6, waist]).max(axis=0) > 0) and np.all(np.abs(J[6:, waist]).max(axis=0) > 0)


@pytest.mark.integration
@pytest.mark.parametrize("name", CHAIN_SETS)
def test_random_reachable_poses_are_solved_to_1e_9(humanoid, solvers, name):
    solver = solvers[name]
    kinematics = chain_kinematics(humanoid, solver)
    rng = np.random.default_rng(2024)
    truths = rng.uniform(solver.lower + MARGIN_RAD, solver.upper - MARGIN_RAD, size=(SAMPLES, solver.n))
    seeds = np.clip(truths + rng.uniform(-PERTURBATION_RAD, PERTURBATION_RAD, truths.shape), solver.lower, solver.upper)
    targets = [tip_poses(kinematics, q) for q in truths]
    results = [solver.solve(T, seed) for T, seed in zip(targets, seeds, strict=True)]

    converged = [i for i, r in enumerate(results) if r.converged]
    assert len(converged) >= REQUIRED_SUCCESSES, [r.reason for r in results if not r.converged]
    iterations = np.array([results[i].iterations for i in converged])
    assert np.median(iterations) <= 10  # Gauss-Newton's quadratic convergence once undamped
    for r in results:
        assert np.all(r.q >= solver.lower) and np.all(r.q <= solver.upper)
        assert r.converged == (r.reason == "")

    # forward kinematics of each hand's own chain, errors measured with scipy
    for (kin, columns), k in zip(kinematics, range(len(solver.tips)), strict=True):
        Q = np.stack([results[i].q for i in converged])[:, columns]
        wanted = np.stack([targets[i][k] for i in converged])
        position, rotation = pose_errors(wanted, kin.poses(Q))
        assert position.max() <= TOLERANCE and rotation.max() <= TOLERANCE
        # a result reports its worst hand's errors
        reported = np.array([[results[i].position_error_m, results[i].orientation_error_rad] for i in converged])
        assert np.all(reported[:, 0] >= position - 1e-15) and np.all(reported[:, 1] >= rotation - 1e-12)

    # PyBullet's link frames (single precision), relative to the base link
    with load_pybullet_robot(humanoid.urdf.path) as sim:
        for i in converged[:PYBULLET_SAMPLES]:
            sim.set_positions(solver.joint_names, results[i].q)
            base = sim.link_pose(solver.base)
            for tip, target in zip(solver.tips, targets[i], strict=True):
                position, rotation = pose_error(target, np.linalg.solve(base, sim.link_pose(tip)))
                assert position <= PYBULLET_TOLERANCE and rotation <= PYBULLET_TOLERANCE


def test_damping_is_zero_far_from_singularity_and_grows_as_the_elbow_straightens(humanoid, solvers):
    solver = solvers["arm_7"]
    kin = ChainKinematics.of(humanoid.chain_between("torso", "left_hand"))
    settings = solver.settings
    elbows = [-1.2, -0.6, -0.3, -0.1, -0.03, -0.01, 0.0]
    used, expected = [], []
    for elbow in elbows:
        q = GENERIC_ARM.copy()
        q[ELBOW] = elbow
        sigma = smallest_singular_value(fd_jacobian(kin, q))
        used.append(solver.damping_at(q))
        expected.append(rule(sigma, settings))
    np.testing.assert_allclose(used, expected, atol=1e-6)
    assert used[0] == 0.0  # GENERIC_ARM (elbow -1.2): s_min above eps
    assert smallest_singular_value(fd_jacobian(kin, GENERIC_ARM)) > settings.singular_region
    assert np.all(np.diff(used) >= 0)  # more damping the straighter the elbow
    assert used[-1] == pytest.approx(settings.max_damping, abs=1e-6)  # straight elbow: s_min = 0


def test_first_step_is_the_damped_least_squares_solution_of_eq_16(humanoid):
    """One step from a straight elbow is J^T (J J^T + lambda^2 I)^-1 dx (eq 16, numpy solve on a
    finite-difference Jacobian), smaller than the pseudoinverse step and within |dx| / (2 lambda);
    away from singularities it is the pseudoinverse step."""
    settings = DlsSettings(max_iterations=1)
    solver = DlsSolver.of(humanoid, "torso", ["left_hand"], settings)
    kin = ChainKinematics.of(humanoid.chain_between("torso", "left_hand"))
    rng = np.random.default_rng(5)
    for elbow, damped in ((0.0, True), (GENERIC_ARM[ELBOW], False)):
        seed = GENERIC_ARM.copy()
        seed[ELBOW] = elbow
        target = kin.pose(seed + rng.uniform(-0.05, 0.05, 7))
        J = fd_jacobian(kin, seed)
        dx = error_vector(target, kin.pose(seed))
        lam = rule(smallest_singular_value(J), settings)
        assert (lam > 0) == damped
        expected = J.T @ np.linalg.solve(J @ J.T + lam**2 * np.eye(6), dx)  # eq (16)
        result = solver.solve([target], seed)
        assert result.iterations == 1 and not result.converged
        step = result.q - seed
        np.testing.assert_allclose(step, expected, atol=1e-6)
        if damped:
            assert np.linalg.norm(step) <= np.linalg.norm(dx) / (2 * lam) + 1e-9
            assert np.linalg.norm(step) < np.linalg.norm(np.linalg.pinv(J) @ dx)
        else:
            np.testing.assert_allclose(step, np.linalg.pinv(J) @ dx, atol=1e-6)


def test_solves_from_a_straight_elbow(humanoid, solvers):
    solver = solvers["arm_7"]
    kin = ChainKinematics.of(humanoid.chain_between("torso", "left_hand"))
    seed = GENERIC_ARM.copy()
    seed[ELBOW] = 0.0
    target = kin.pose(GENERIC_ARM)
    result = solver.solve([target], seed)
    assert result.converged, result.reason
    assert max(pose_error(target, kin.pose(result.q))) <= TOLERANCE


@pytest.mark.parametrize("name", CHAIN_SETS)
def test_targets_at_the_joint_limits_are_reached_within_them(humanoid, solvers, name):
    """Truth configurations with three joints exactly at their limits, seeds partly outside the
    limits (the solver clamps them first). 20 of 20 converge per chain set; this needs the joint
    clamping: with a plain clip after each step 2 to 6 of the 20 stall against a limit."""
    solver = solvers[name]
    kinematics = chain_kinematics(humanoid, solver)
    rng = np.random.default_rng(8)
    solved = 0
    for _ in range(20):
        truth = rng.uniform(solver.lower + MARGIN_RAD, solver.upper - MARGIN_RAD)
        at_limit = rng.choice(solver.n, size=3, replace=False)
        truth[at_limit] = np.where(rng.random(3) < 0.5, solver.lower[at_limit], solver.upper[at_limit])
        seed = truth + rng.uniform(-PERTURBATION_RAD, PERTURBATION_RAD, solver.n)
        result = solver.solve(tip_poses(kinematics, truth), seed)
        assert np.all(result.q >= solver.lower) and np.all(result.q <= solver.upper)
        if result.converged:
            solved += 1
            for (kin, columns), target in zip(kinematics, tip_poses(kinematics, truth), strict=True):
                assert max(pose_error(target, kin.pose(result.q[columns]))) <= TOLERANCE
    assert solved >= 19


@pytest.mark.parametrize("name", CHAIN_SETS)
def test_a_target_2_m_away_is_reported_unconverged(humanoid, solvers, name):
    solver = solvers[name]
    kinematics = chain_kinematics(humanoid, solver)
    seed = np.zeros(solver.n)
    targets = tip_poses(kinematics, seed)
    targets[0][:3, 3] += [2.0, 0.0, 0.0]
    result = solver.solve(targets, seed)
    assert not result.converged
    assert result.position_error_m > 1.0  # both arms are 0.69 m long: no configuration comes close
    assert result.reason and "position error" in result.reason
    assert result.iterations <= solver.settings.max_iterations
    assert np.all(result.q >= solver.lower) and np.all(result.q <= solver.upper)
    kin, columns = kinematics[0]
    assert pose_error(targets[0], kin.pose(result.q[columns]))[0] == pytest.approx(result.position_error_m, abs=1e-12)


def test_a_pose_needing_the_elbow_beyond_its_limit_is_reported_unconverged(humanoid, solvers):
    """For an S-R-S arm the shoulder-wrist distance fixes |elbow|; a pose made with the elbow at
    2.5 rad (limit 2.094) has no solution within the limits."""
    solver = solvers["arm_7"]
    kin = ChainKinematics.of(humanoid.chain_between("torso", "left_hand"))
    truth = GENERIC_ARM.copy()
    truth[ELBOW] = 2.5
    assert truth[ELBOW] > solver.upper[ELBOW]
    result = solver.solve([kin.pose(truth)], np.clip(truth, solver.lower, solver.upper))
    assert not result.converged and result.reason
    assert result.position_error_m > 1e-3
    assert np.all(result.q >= solver.lower) and np.all(result.q <= solver.upper)


def test_results_are_immutable(humanoid, solvers):
    solver = solvers["arm_7"]
    kin = ChainKinematics.of(humanoid.chain_between("torso", "left_hand"))
    result = solver.solve([kin.pose(GENERIC_ARM)], GENERIC_ARM + 0.1)
    assert result.converged
    assert not result.q.flags.writeable and not solver.lower.flags.writeable
    with pytest.raises(dataclasses.FrozenInstanceError):
        result.converged = False


def test_bad_inputs_raise_stage_errors(humanoid, solvers):
    solver = solvers["both_arms_17"]
    with pytest.raises(StageError, match="2 tips"):
        solver.solve([np.eye(4)], np.zeros(17))
    with pytest.raises(StageError, match="right_hand"):
        solver.solve([np.eye(4), np.eye(3)], np.zeros(17))
    with pytest.raises(StageError, match="17 finite joint values"):
        solver.solve([np.eye(4), np.eye(4)], np.zeros(7))
    with pytest.raises(StageError, match="no tips"):
        DlsSolver.of(humanoid, "pelvis", [])
    with pytest.raises(StageError, match="repeated"):
        DlsSolver.of(humanoid, "pelvis", ["left_hand", "left_hand"])
    with pytest.raises(RobotModelError, match="no link 'left_hnd'"):
        DlsSolver.of(humanoid, "pelvis", ["left_hnd"])
    with pytest.raises(InvalidArgumentError, match="max_damping"):
        DlsSettings(max_damping=0.0)
    with pytest.raises(InvalidArgumentError, match="max_iterations"):
        DlsSettings(max_iterations=0)
