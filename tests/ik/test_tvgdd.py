"""The TV-GDD QP (23)-(25): the CasADi step and the LVI solver against quadprog."""

import numpy as np
import pytest
import quadprog

from dualarm.describe.check import PYBULLET_TOLERANCE
from dualarm.ik.velocity.stack import hand_stack, stacked_reference
from dualarm.ik.velocity.tvgdd import TvgddSettings, build_problem, joint_bounds, lvi_solve, settings_for
from dualarm.paths import build_reference
from dualarm.sim.world import load_pybullet_robot
from dualarm.tasks import load_task
from tests.helpers import TASKS


@pytest.fixture(scope="module")
def ball_game():
    task = load_task(TASKS / "ball_game.toml")
    stack = hand_stack(task.robot, task.spec.hands, task.initial_q)
    return task, stack, joint_bounds(task.robot, stack, settings_for(task)), build_reference(task)


def quadprog_solve(M, b, J, rhs, lo, hi):
    """min x'Mx/2 + b'x s.t. Jx = rhs, lo <= x <= hi, by Goldfarb-Idnani (quadprog)."""
    n = len(b)
    C = np.hstack([J.T, np.eye(n), -np.eye(n)])
    return quadprog.solve_qp(M, -b, C, np.concatenate([rhs, lo, -hi]), meq=J.shape[0])[0]


@pytest.mark.integration
def test_stack_positions_match_pybullet(ball_game):
    task, stack, _, _ = ball_game
    theta = stack.initial
    r = np.asarray(stack.positions(theta)).ravel()
    with load_pybullet_robot(task.robot.urdf.path) as sim:
        sim.set_positions(list(task.initial_q), list(task.initial_q.values()))
        expected = np.concatenate([sim.link_pose(f"{h}_hand")[:3, 3] for h in stack.hands])
    assert np.abs(r - expected).max() <= PYBULLET_TOLERANCE
    assert stack.n == 14 and stack.m == 6


@pytest.mark.parametrize("scheme", ["mvn", "rmp", "mke"])
def test_casadi_step_solves_the_qp_along_the_ball_game(ball_game, scheme):
    """On QP instances taken along the ball game (all 1801 for MVN), the conic solution equals quadprog's."""
    task, stack, bounds, ref = ball_game
    settings = TvgddSettings(scheme=scheme, feedback_gain=task.spec.gesture.feedback_gain)
    problem = build_problem(
        stack, bounds, settings, ref.period_s, task.robot.urdf.kinematic_xml, task.robot.joint_names
    )
    R, V = stacked_reference(stack, ref)
    theta = theta0 = stack.initial
    worst, stride = 0.0, 1 if scheme == "mvn" else 3
    for k in range(0, len(ref), stride):
        args = (theta, ref.t[k], R[k], V[k], theta0)
        qd = np.asarray(problem.step(*args)[0]).ravel()
        M, b, J, rhs, lo, hi, _, _ = (np.asarray(x) for x in problem.data(*args))
        expected = quadprog_solve(M, b.ravel(), J, rhs.ravel(), lo.ravel(), hi.ravel())
        worst = max(worst, np.abs(qd - expected).max())
        assert np.abs(J @ qd - rhs.ravel()).max() < 1e-9
        assert np.all(qd >= lo.ravel() - 1e-9) and np.all(qd <= hi.ravel() + 1e-9)
        theta = theta + stride * problem.period_s * qd
    assert worst < 1e-8


def along(problem, ref, theta0):
    """Every QP instance along ``ref`` from ``theta0``, following quadprog's solutions: the step
    arguments, the QP data (M, b, J, rhs, lo, hi) batched over steps, and the solutions."""
    R, V = stacked_reference(problem.stack, ref)
    theta = theta0
    steps, data, expected = [], [], []
    for k in range(len(ref)):
        args = (theta, ref.t[k], R[k], V[k], theta0)
        qp = [np.asarray(x).squeeze() for x in problem.data(*args)[:6]]
        steps.append(args)
        data.append(qp)
        expected.append(quadprog_solve(*qp))
        theta = theta + problem.period_s * expected[-1]
    return problem, steps, [np.array(column) for column in zip(*data, strict=True)], np.array(expected)


@pytest.fixture(scope="module")
def instances(ball_game):
    """Every QP instance along the ball game (MVN, position task space as the paper's, the casadi path)."""
    task, stack, bounds, ref = ball_game
    return along(
        build_problem(stack, bounds, TvgddSettings(feedback_gain=task.spec.gesture.feedback_gain), ref.period_s),
        ref,
        stack.initial,
    )


@pytest.fixture(scope="module")
def pose_instances():
    """Every QP instance along one triangle repetition in pose task space (6 rows on 7 joints;
    RMP, nu = 10, from MC-Inverse's start, as in tests/ik/test_pose.py): the upper-arm roll presses
    on its bound on 268 of the 601 steps."""
    from dualarm.ik.analytic.mc_path import settings_for as mc_settings_for
    from dualarm.ik.analytic.mc_path import solve_mc_inverse

    task = load_task(TASKS / "triangle.toml", 1)
    ref = build_reference(task)
    start = solve_mc_inverse(task.robot, ref, task.initial_q, mc_settings_for(task)).configuration(0)
    settings = settings_for(task, scheme="rmp", nu=10.0)
    stack = hand_stack(task.robot, task.spec.hands, start, task_space=settings.task_space)
    return along(
        build_problem(stack, joint_bounds(task.robot, stack, settings), settings, ref.period_s), ref, stack.initial
    )


def kkt_violation(M, b, J, rhs, lo, hi, x, lam):
    """Largest violation of the KKT conditions of (23)-(25) at (x, lambda): primal feasibility,
    and g = M x + b - J^T lambda zero on free joints, >= 0 at a lower bound, <= 0 at an upper one."""
    g = M @ x + b - J.T @ lam
    at_lower, at_upper = x <= lo + 1e-6, x >= hi - 1e-6
    stationarity = np.where(at_lower, np.maximum(-g, 0), np.where(at_upper, np.maximum(g, 0), np.abs(g)))
    stationarity = np.where(at_lower & at_upper, 0.0, stationarity)
    return max(np.abs(J @ x - rhs).max(), np.maximum(lo - x, x - hi).max(), stationarity.max())


@pytest.mark.parametrize("case", ["instances", "pose_instances"])
def test_backends_agree_and_satisfy_kkt_on_every_step(request, case):
    """Every instance of the ball game (1801, position task space) and of the pose triangle (601):
    casadi and lvi (stopped at ||eps|| <= 1e-6) agree to 1e-4 rad/s, both meet the KKT conditions
    to 1e-6, and both equal quadprog's solution; the pose QPs do have bounds at work."""
    problem, steps, data, expected = request.getfixturevalue(case)
    assert len(steps) >= 600
    lo_all, hi_all = data[4], data[5]
    assert ((expected <= lo_all + 1e-9) | (expected >= hi_all - 1e-9)).any(axis=1).sum() >= 50
    lvi, u, _ = lvi_solve(*data, tol=1e-6)
    n = lvi.shape[1]
    for k, args in enumerate(steps):
        M, b, J, rhs, lo, hi = (x[k] for x in data)
        x = np.asarray(problem.step(*args)[0]).ravel()
        free = (x > lo + 1e-6) & (x < hi - 1e-6)
        lam = np.linalg.lstsq(J[:, free].T, (M @ x + b)[free], rcond=None)[0]  # multipliers from the free joints
        assert kkt_violation(M, b, J, rhs, lo, hi, x, lam) <= 1e-6, k
        assert kkt_violation(M, b, J, rhs, lo, hi, lvi[k], u[k, n:]) <= 1e-6, k
        assert np.abs(x - lvi[k]).max() <= 1e-4, k
        assert np.abs(x - expected[k]).max() <= 1e-8, k


def test_lvi_at_the_published_stop_errs_by_at_most_its_linear_bound(instances):
    """Stopped at ||eps|| <= 1e-5 (as published), the LVI's velocity error is bounded by
    ||(E^-1)_theta|| 1e-5, where E is the Jacobian of eps(u) at the solution (Gamma's rows on free
    joints and on lambda, identity rows on joints at a bound). Along the ball game (elbows forward
    and out) that bound stays under 1e-4 rad/s, so the published stop gives 1e-4 agreement."""
    _, _, data, expected = instances
    picks = np.arange(0, len(expected), 3)
    lvi, _, _ = lvi_solve(*(x[picks] for x in data))
    n = lvi.shape[1]
    bounds = []
    for row, k in enumerate(picks):
        M, _, J, _, lo, hi = (x[k] for x in data)
        m = J.shape[0]
        E = np.block([[M, -J.T], [J, np.zeros((m, m))]])
        active = np.flatnonzero((expected[k] <= lo + 1e-9) | (expected[k] >= hi - 1e-9))
        E[active] = np.eye(n + m)[active]
        bounds.append(np.linalg.norm(np.linalg.inv(E)[:n], 2) * 1e-5)
        assert np.linalg.norm(lvi[row] - expected[k]) <= bounds[-1] * 1.01, k
    assert max(bounds) <= 1e-4
    assert np.abs(lvi - expected[picks]).max() <= 1e-4


def test_lvi_backend_follows_the_casadi_one_in_pose_mode():
    """The whole solve loop in pose task space with either backend, over the triangle's first 320
    samples (the upper-arm roll presses on its bound from step 278 on): the same joint path."""
    from dataclasses import replace

    from dualarm.contracts.reference import CartesianReference, HandReference
    from dualarm.ik.analytic.mc_path import settings_for as mc_settings_for
    from dualarm.ik.analytic.mc_path import solve_mc_inverse
    from dualarm.ik.velocity.tvgdd import solve_tvgdd

    task = load_task(TASKS / "triangle.toml", 1)
    full = build_reference(task)
    hand = full.hands["left"]
    ref = CartesianReference(
        full.period_s,
        {
            "left": HandReference(
                hand.position[:320], hand.rotation[:320], hand.linear_velocity[:320], hand.angular_velocity[:320]
            )
        },
    )
    start = solve_mc_inverse(task.robot, full, task.initial_q, mc_settings_for(task)).configuration(0)
    settings = settings_for(task, scheme="rmp", nu=10.0)
    casadi = solve_tvgdd(task.robot, ref, start, settings)
    lvi = solve_tvgdd(task.robot, ref, start, replace(settings, backend="lvi"))
    assert casadi.task_space == lvi.task_space == "pose"
    active = (casadi.qd <= casadi.extras["zeta_lower"] + 1e-9) | (casadi.qd >= casadi.extras["zeta_upper"] - 1e-9)
    assert active.any(axis=1).sum() >= 30
    assert np.abs(lvi.qd - casadi.qd).max() <= 1e-3
    assert np.abs(lvi.q - casadi.q).max() <= 1e-5
    assert np.abs(lvi.hand_orientation_error_rad - casadi.hand_orientation_error_rad).max() <= 1e-5
