"""Consistency metrics across repetitions, against deviations planted in a known path."""

import numpy as np
import pytest

from dualarm.contracts.joint_path import JointPath
from dualarm.ik.analytic.mc_inverse import McInverse
from dualarm.ik.analytic.mc_path import settings_for, solve_mc_inverse
from dualarm.ik.metrics import arm_angles, consistency_metrics
from dualarm.model.kinematics import ChainKinematics
from dualarm.paths import build_reference
from dualarm.tasks import load_task
from tests.helpers import TASKS


@pytest.fixture(scope="module")
def carry():
    task = load_task(TASKS / "carry_box.toml", repetitions=3)
    ref = build_reference(task)
    return task, ref, solve_mc_inverse(task.robot, ref, task.initial_q, settings_for(task))


def _with(path: JointPath, q: np.ndarray, status: np.ndarray | None = None) -> JointPath:
    fields = {
        f: getattr(path, f)
        for f in ("method", "joint_names", "t", "rep", "qd", "solve_time_s", "hand_error_m", "hands", "fixed")
    }
    return JointPath(**fields, q=q, status=path.status if status is None else status)


def test_planted_deviations_are_measured(carry):
    """Repetition 2 moved at one sample by 0.3 rad in one joint, and repetition 1 failing at one
    sample: the joint deviation is 0.3, the closure is untouched, one repetition failed."""
    task, ref, path = carry
    base = consistency_metrics(path, ref, arm_angles(path, task.robot, task.spec.arm_angle.vertical))
    assert base["ik.rep_joint_deviation_max_rad"] <= 1e-9 and base["ik.failed_reps"] == 0
    q = path.q.copy()
    k = np.flatnonzero(ref.rep == 2)[100]
    q[k, 3] += 0.3
    status = path.status.copy()
    status[np.flatnonzero(ref.rep == 1)[50]] = 1
    changed = _with(path, q, status)
    m = consistency_metrics(changed, ref, arm_angles(changed, task.robot, task.spec.arm_angle.vertical))
    assert m["ik.rep_joint_deviation_max_rad"] == pytest.approx(0.3, abs=1e-9)
    assert m["ik.failed_reps"] == 1
    assert m["ik.closure_error_max_rad"] == pytest.approx(base["ik.closure_error_max_rad"], abs=1e-12)


def test_arm_angle_deviation_is_the_self_motion_planted(carry):
    """Repetition 1 of the left arm re-solved by MC-Inverse at psi + 0.2 rad (the same hand poses,
    the arm turned about its shoulder-wrist line): the arm-angle deviation is 0.2 rad."""
    task, ref, path = carry
    chain = task.robot.hand_chain("left")
    columns = [path.joint_names.index(n) for n in chain.joint_names]
    solver = McInverse.of(chain)
    rep1 = np.flatnonzero(ref.rep == 1)
    arm_q = path.q[:, columns]
    hand = ChainKinematics.of(chain).poses(arm_q[rep1])
    psi = solver.kinematics.arm_angles(arm_q[rep1])
    candidates, reasons = solver.solve_many(hand, psi + 0.2)
    branch = np.argmin(np.abs(solver.solve_many(hand[:1], psi[:1])[0][0] - arm_q[rep1[0]]).max(axis=1))
    assert (reasons[:, branch] == 0).all()
    q = path.q.copy()
    q[np.ix_(rep1, columns)] = candidates[:, branch]
    changed = _with(path, q)
    m = consistency_metrics(changed, ref, arm_angles(changed, task.robot, task.spec.arm_angle.vertical))
    assert m["ik.rep_arm_angle_deviation_max_rad"] == pytest.approx(0.2, abs=1e-9)


def test_single_repetition_has_no_consistency_metrics():
    task = load_task(TASKS / "carry_box.toml", repetitions=1)
    ref = build_reference(task)
    path = solve_mc_inverse(task.robot, ref, task.initial_q, settings_for(task))
    assert consistency_metrics(path, ref, arm_angles(path, task.robot, task.spec.arm_angle.vertical)) == {}


@pytest.mark.integration
def test_orientation_metrics_of_a_pose_level_method_and_of_an_unmeasured_path(carry):
    """MC-Inverse reaches every asked orientation (PyBullet agrees to 1e-6 rad at every 50th sample), so its orientation
    error is ~0 and it counts as solving the orientation; a path that measured no orientation (a planner's, NaN) gets no
    orientation error keys rather than NaN in metrics.json."""
    from scipy.spatial.transform import Rotation

    from dualarm.ik.metrics import ik_metrics
    from dualarm.sim.world import load_pybullet_robot

    task, ref, path = carry
    with load_pybullet_robot(task.robot.urdf.path) as sim:
        for k in range(0, len(path), 50):
            q = path.configuration(k)
            sim.set_positions(list(q), list(q.values()))
            for j, hand in enumerate(path.hands):
                reached = Rotation.from_matrix(sim.link_pose(f"{hand}_hand")[:3, :3])
                assert (Rotation.from_matrix(ref.hands[hand].rotation[k]).inv() * reached).magnitude() < 1e-6
                assert abs(path.hand_orientation_error_rad[k, j]) < 1e-6
    m = ik_metrics(path, task.robot)
    assert m["ik.orientation_solved"] == 1.0 and m["ik.orientation_error_max_rad"] < 1e-6
    unmeasured = ik_metrics(_with(path, path.q), task.robot)
    assert "ik.orientation_error_max_rad" not in unmeasured and "ik.orientation_error_mean_rad" not in unmeasured


@pytest.mark.integration  # the ik stage's auto arm angle checks collisions in a PyBullet world
def test_condition_metrics_against_finite_differences_and_the_limits():
    """The least joint-limit margin, from the robot's limits sample by sample, and the least manipulability sqrt(det(J
    J^T)), from the singular values of Jacobians by central differences of the arm's forward kinematics
    (dualarm.describe.check), on MC-Inverse's triangle."""
    from dualarm.describe.check import finite_difference_jacobians
    from dualarm.ik.metrics import condition_metrics
    from dualarm.model.kinematics import ChainKinematics
    from dualarm.run import run_task

    result = run_task("triangle", "mc-inverse", stages=("path", "ik"))
    path, robot = result.joint_path, result.task.robot
    metrics = condition_metrics(path, robot)
    margins = [
        min(q - robot.lower_upper([name])[0][0], robot.lower_upper([name])[1][0] - q)
        for name, column in zip(path.joint_names, path.q.T, strict=True)
        for q in column
    ]
    assert metrics["ik.joint_limit_margin_min_rad"] == min(margins)
    chain = robot.hand_chain("left")
    J = finite_difference_jacobians(
        ChainKinematics.of(chain), path.q[:, [path.joint_names.index(n) for n in chain.joint_names]]
    )
    singular = np.linalg.svd(J, compute_uv=False)
    np.testing.assert_allclose(metrics["ik.manipulability_min"], singular.prod(axis=1).min(), rtol=1e-6)
    assert metrics == {k: result.metrics[k] for k in metrics}
