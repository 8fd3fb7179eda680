"""The TV-GDD QP (23)-(25): the CasADi step and the LVI solver against quadprog."""

import numpy as np
import pytest
import quadprog

from dualarm.execute.world import load_pybullet_robot
from dualarm.ik.stack import hand_stack, stacked_reference
from dualarm.ik.tvgdd import TvgddSettings, build_problem, joint_bounds, lvi_solve, settings_for
from dualarm.model.check import PYBULLET_TOLERANCE
from dualarm.paths import build_reference
from dualarm.tasks import load_task
from tests.conftest import TASKS


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
    problem = build_problem(stack, bounds, settings, ref.period_s, task.robot.urdf.kinematic_xml, task.robot.joint_names)
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


@pytest.fixture(scope="module")
def instances(ball_game):
    """Every QP instance along the ball game (MVN, the casadi path): the step arguments, the QP
    data (M, b, J, rhs, lo, hi) batched over steps, and quadprog's solutions."""
    task, stack, bounds, ref = ball_game
    problem = build_problem(stack, bounds, TvgddSettings(feedback_gain=task.spec.gesture.feedback_gain), ref.period_s)
    R, V = stacked_reference(stack, ref)
    theta = theta0 = stack.initial
    steps, data, expected = [], [], []
    for k in range(len(ref)):
        args = (theta, ref.t[k], R[k], V[k], theta0)
        qp = [np.asarray(x).squeeze() for x in problem.data(*args)[:6]]
        steps.append(args)
        data.append(qp)
        expected.append(quadprog_solve(*qp))
        theta = theta + problem.period_s * expected[-1]
    return problem, steps, [np.array(column) for column in zip(*data)], np.array(expected)


def kkt_violation(M, b, J, rhs, lo, hi, x, lam):
    """Largest violation of the KKT conditions of (23)-(25) at (x, lambda): primal feasibility,
    and g = M x + b - J^T lambda zero on free joints, >= 0 at a lower bound, <= 0 at an upper one."""
    g = M @ x + b - J.T @ lam
    at_lower, at_upper = x <= lo + 1e-6, x >= hi - 1e-6
    stationarity = np.where(at_lower, np.maximum(-g, 0), np.where(at_upper, np.maximum(g, 0), np.abs(g)))
    stationarity = np.where(at_lower & at_upper, 0.0, stationarity)
    return max(np.abs(J @ x - rhs).max(), np.maximum(lo - x, x - hi).max(), stationarity.max())


def test_backends_agree_and_satisfy_kkt_on_every_ball_game_step(instances):
    """All 1801 instances: casadi and lvi (stopped at ||eps|| <= 1e-6) agree to 1e-4 rad/s, both
    meet the KKT conditions to 1e-6, and both equal quadprog's solution."""
    problem, steps, data, expected = instances
    assert len(steps) >= 1000
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
