"""The TV-GDD QP (23)-(25): the CasADi step and the LVI solver against quadprog."""

import numpy as np
import pytest
import quadprog

from pipeline.ik.stack import hand_stack, stacked_reference
from pipeline.ik.tvgdd import JointBounds, TvgddSettings, build_problem, lvi_solve
from pipeline.model.check import PYBULLET_TOLERANCE
from pipeline.execute.world import load_pybullet_robot
from pipeline.paths import build_reference
from pipeline.tasks import load_task
from tests.conftest import TASKS


@pytest.fixture(scope="module")
def ball_game():
    task = load_task(TASKS / "ball_game.toml")
    stack = hand_stack(task)
    lim = task.robot.limits
    names = stack.joint_names
    g = task.spec.gesture
    bounds = JointBounds(
        lower=np.array([lim[n].lower for n in names]),
        upper=np.array([lim[n].upper for n in names]),
        goal_lower=np.array([g.goal_lower.get(n, lim[n].lower) for n in names]),
        goal_upper=np.array([g.goal_upper.get(n, lim[n].upper) for n in names]),
        velocity=np.full(len(names), task.spec.limits.velocity),
    )
    return task, stack, bounds, build_reference(task)


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
    problem = build_problem(stack, bounds, settings, task.robot.urdf.kinematic_xml, task.robot.joint_names)
    R, V = stacked_reference(stack, ref)
    theta = theta0 = stack.initial
    worst, stride = 0.0, 1 if scheme == "mvn" else 3
    for k in range(0, len(ref), stride):
        args = (theta, ref.t[k], R[k], V[k], theta0)
        qd = np.asarray(problem.step(*args)).ravel()
        M, b, J, rhs, lo, hi, _, _ = (np.asarray(x) for x in problem.data(*args))
        expected = quadprog_solve(M, b.ravel(), J, rhs.ravel(), lo.ravel(), hi.ravel())
        worst = max(worst, np.abs(qd - expected).max())
        assert np.abs(J @ qd - rhs.ravel()).max() < 1e-9
        assert np.all(qd >= lo.ravel() - 1e-9) and np.all(qd <= hi.ravel() + 1e-9)
        theta = theta + stride * settings.period_s * qd
    assert worst < 1e-8


def test_lvi_converges_to_the_qp_solution(ball_game):
    """The projection method of eqs (26)-(27), run to a tight tolerance, reaches quadprog's solution
    on states taken along the ball game."""
    task, stack, bounds, ref = ball_game
    problem = build_problem(stack, bounds, TvgddSettings(feedback_gain=task.spec.gesture.feedback_gain))
    R, V = stacked_reference(stack, ref)
    theta = theta0 = stack.initial
    for k in range(1201):
        args = (theta, ref.t[k], R[k], V[k], theta0)
        if k % 400 == 0:
            M, b, J, rhs, lo, hi, _, _ = (np.asarray(x).squeeze() for x in problem.data(*args))
            qd, _, _ = lvi_solve(M, b, J, rhs, lo, hi, tol=1e-9)
            np.testing.assert_allclose(qd, quadprog_solve(M, b, J, rhs, lo, hi), atol=1e-7)
        theta = theta + problem.settings.period_s * np.asarray(problem.step(*args)).ravel()
