"""TV-GDD and pinv along whole tasks: the paper's ball-game figures, gestures, RMP, infeasibility."""

import dataclasses
import json
import re

import numpy as np
import pytest

from dualarm.errors import StageError
from dualarm.ik.metrics import ik_metrics
from dualarm.ik.velocity.pinv import settings_for as pinv_settings_for
from dualarm.ik.velocity.pinv import solve_pinv
from dualarm.ik.velocity.tvgdd import settings_for, solve_tvgdd
from dualarm.paths import build_reference
from dualarm.run import record_run
from dualarm.sim.world import load_pybullet_robot
from dualarm.tasks import load_task
from tests.helpers import HUMANOID, TASKS

# Zhang, Kong, Niu, section 4.2: MAE, AAE, RMSE of the hand positions
PAPER_MAE_M, PAPER_AAE_M, PAPER_RMSE_M = 2.1832e-5, 6.2e-6, 8.41e-6


@pytest.fixture(scope="module")
def ball_game():
    task = load_task(TASKS / "ball_game.toml")
    return task, build_reference(task)


@pytest.fixture(scope="module")
def tvgdd_path(ball_game):
    task, ref = ball_game
    return solve_tvgdd(task.robot, ref, task.initial_q, settings_for(task))


def _variant(tmp_path, text: str):
    path = tmp_path / "task.toml"
    path.write_text(text.replace('robot = "../robots/humanoid"', f'robot = "{HUMANOID}"'))
    return path


def test_ball_game_meets_the_paper_figures(ball_game, tvgdd_path):
    task, _ = ball_game
    m = ik_metrics(tvgdd_path, task.robot)
    assert m["ik.position_error_max_m"] <= PAPER_MAE_M
    assert m["ik.position_error_mean_m"] < PAPER_AAE_M
    assert m["ik.position_error_rmse_m"] < PAPER_RMSE_M
    assert m["ik.joint_limit_violations"] == 0 and m["ik.velocity_limit_violations"] == 0
    assert m["ik.failures"] == 0


def test_gesture_joints_reach_their_goals(ball_game, tvgdd_path):
    task, _ = ball_game
    g = task.spec.gesture
    gesture = [n for n in g.goal_lower if g.goal_lower[n] == g.goal_upper[n]]
    assert len(gesture) == 4
    final = dict(zip(tvgdd_path.joint_names, tvgdd_path.q[-1], strict=True))
    for name in gesture:
        assert abs(final[name] - g.goal_lower[name]) <= 1e-3, name


def test_gesture_joints_stay_inside_the_closing_bounds_only_with_the_feedforward(ball_game, tvgdd_path):
    """As published, eq (21) lets a joint pressed against a closing bound lag it (by about the
    bound's rate / nu); the ball game's bound feedforward keeps every joint inside theta_new+-."""
    task, ref = ball_game

    def outside(path):
        return np.maximum(path.extras["theta_lower"] - path.q, path.q - path.extras["theta_upper"]).max()

    assert task.spec.gesture.bound_feedforward
    published = solve_tvgdd(
        task.robot, ref, task.initial_q, dataclasses.replace(settings_for(task), bound_feedforward=False)
    )
    assert outside(tvgdd_path) <= 1e-9 < 1e-3 < outside(published)
    assert ik_metrics(published, task.robot)["ik.position_error_max_m"] <= PAPER_MAE_M


@pytest.mark.integration
def test_recorded_hand_errors_match_pybullet(ball_game, tvgdd_path):
    task, ref = ball_game
    with load_pybullet_robot(task.robot.urdf.path) as sim:
        for k in range(0, len(tvgdd_path), 150):
            q = tvgdd_path.configuration(k)
            sim.set_positions(list(q), list(q.values()))
            for j, hand in enumerate(tvgdd_path.hands):
                error = np.linalg.norm(sim.link_pose(f"{hand}_hand")[:3, 3] - ref.hands[hand].position[k])
                assert abs(error - tvgdd_path.hand_error_m[k, j]) < 1e-6


def test_velocities_stay_within_the_time_varying_bounds(tvgdd_path):
    lo, hi = tvgdd_path.extras["zeta_lower"], tvgdd_path.extras["zeta_upper"]
    assert np.all(tvgdd_path.qd >= lo - 1e-9) and np.all(tvgdd_path.qd <= hi + 1e-9)


def test_pinv_leaves_the_gesture_bounds_far_more_than_tvgdd(ball_game, tvgdd_path):
    """The paper's contrast (Figs 3 and 5): without bounds the minimum-norm rate lets the wrists
    wander out of the band TV-GDD closes on them."""
    task, ref = ball_game
    pinv_settings = pinv_settings_for(task)
    assert pinv_settings.feedback_gain == task.spec.gesture.feedback_gain
    pinv = solve_pinv(task.robot, ref, task.initial_q, pinv_settings)
    lo, hi = tvgdd_path.extras["theta_lower"], tvgdd_path.extras["theta_upper"]

    def outside(q):
        return np.maximum(lo - q, q - hi).max()

    assert outside(tvgdd_path.q) <= 1e-9 < 0.05 < outside(pinv.q)
    assert ik_metrics(pinv, task.robot)["ik.position_error_max_m"] < 1e-4  # it does track the hands


def test_rmp_returns_to_the_start_on_a_closed_path_and_mvn_does_not(tmp_path):
    """The ball game without gesture bounds, strokes doubled (MVN's drift grows with the loop)."""
    text = re.sub(r"\[gesture\].*?(?=\[\[moves\]\])", "", (TASKS / "ball_game.toml").read_text(), flags=re.S)
    text = re.sub(
        r"by = \[([^]]*)\]",
        lambda m: "by = [" + ", ".join(f"{2 * float(v)}" for v in m.group(1).split(",")) + "]",
        text,
    )
    task = load_task(_variant(tmp_path, text))
    ref = build_reference(task)
    assert np.allclose(ref.hands["left"].position[-1], ref.hands["left"].position[0], atol=1e-12)
    closure = {}
    for scheme in ("mvn", "rmp"):
        path = solve_tvgdd(
            task.robot, ref, task.initial_q, dataclasses.replace(settings_for(task, scheme=scheme), feedback_gain=50.0)
        )
        closure[scheme] = np.abs(path.q[-1] - path.q[0]).max()
    assert closure["rmp"] <= 1e-5 < 1e-4 < closure["mvn"]


@pytest.mark.integration
def test_infeasible_step_fails_the_run_naming_step_time_and_joint(tmp_path):
    """A wrist goal 3.3 rad away (from -1.0323 rad) reached within 0.1 s: nu (theta_new- - theta) exceeds the 6 rad/s
    limit."""
    text = (TASKS / "ball_game.toml").read_text()
    text = (
        text.replace("t_sp_s = 0.75", "t_sp_s = 0.05")
        .replace("c_tuning = 1.0", "c_tuning = 0.01")
        .replace("bound_feedforward = true", "bound_feedforward = false")
    )
    head, goals = text.split("[gesture.goal_lower]")
    text = head + "[gesture.goal_lower]" + goals.replace("left_wrist_roll = -1.0323", "left_wrist_roll = 2.2677")
    task_file = _variant(tmp_path, text)
    with pytest.raises(StageError, match=r"TV-GDD step \d+ \(t = [\d.]+ s\) is infeasible: .*left_wrist_roll"):
        record_run(task_file, "tvgdd", out_dir=tmp_path / "out")
    (run,) = (tmp_path / "out" / "ball_game").iterdir()
    manifest = json.loads((run / "manifest.json").read_text())
    assert manifest["status"] == "failed" and "left_wrist_roll" in manifest["error"]


def test_rollout_in_one_call_equals_the_step_loop(ball_game, tvgdd_path):
    """The mapaccum rollout (used by the benchmark) integrates exactly what the per-step loop does."""
    from dualarm.ik.velocity.stack import hand_stack, stacked_reference
    from dualarm.ik.velocity.tvgdd import build_problem, joint_bounds

    task, ref = ball_game
    settings = settings_for(task)
    stack = hand_stack(task.robot, task.spec.hands, task.initial_q, free_waist=settings.free_waist)
    problem = build_problem(stack, joint_bounds(task.robot, stack, settings), settings, ref.period_s)
    R, V = stacked_reference(stack, ref)
    theta0 = tvgdd_path.q[0]
    theta, velocity = problem.rollout(len(ref))(theta0, np.vstack([ref.t, R.T, V.T]), theta0)
    np.testing.assert_allclose(np.asarray(theta).T[:-1], tvgdd_path.q[1:], atol=1e-12)
    np.testing.assert_allclose(np.asarray(velocity).T, tvgdd_path.qd, atol=1e-12)


def _triangle_from_ready(tmp_path):
    """triangle.toml with its ``[initial]`` table (MC-Inverse's configuration on the path start) replaced by ``initial =
    "ready"``."""
    text = (TASKS / "triangle.toml").read_text()
    text, count = re.subn(r"^\[initial\][^\n]*\n(?:\w+ = [^\n]*\n)+", 'initial = "ready"\n', text, flags=re.MULTILINE)
    assert count == 1
    return _variant(tmp_path, text)


@pytest.mark.integration
def test_one_hand_off_the_path_start_begins_on_it(tmp_path):
    """triangle, started from robot.toml's ``ready``: one hand (7 DOF), whose initial configuration is
    then 0.16 m off the path start. The IK (position task space here; pose in tests/ik/test_pose.py)
    starts from the nearest configuration that puts the hand there (checked with PyBullet)."""
    from dualarm.ik.velocity.stack import hand_stack, start_configuration

    task = load_task(_triangle_from_ready(tmp_path))
    assert task.initial_q == task.robot.home("ready")
    ref = build_reference(task)
    stack = hand_stack(task.robot, task.spec.hands, task.initial_q)
    lower, upper = task.robot.lower_upper(stack.joint_names)
    start = start_configuration(stack, ref, lower, upper)
    assert stack.n == 7 and np.all(start >= lower) and np.all(start <= upper)
    with load_pybullet_robot(task.robot.urdf.path) as sim:
        q = {**task.initial_q, **dict(zip(stack.joint_names, start, strict=True))}
        sim.set_positions(list(q), list(q.values()))
        assert np.linalg.norm(sim.link_pose("left_hand")[:3, 3] - ref.hands["left"].position[0]) < 1e-6
        sim.set_positions(list(task.initial_q), list(task.initial_q.values()))
        assert np.linalg.norm(sim.link_pose("left_hand")[:3, 3] - ref.hands["left"].position[0]) > 0.1
    path = solve_tvgdd(task.robot, ref, task.initial_q, settings_for(task, task_space="position"))
    np.testing.assert_allclose(path.q[0], start, atol=1e-12)
    assert ik_metrics(path, task.robot)["ik.joint_limit_violations"] == 0


def test_tvgdd_with_the_waist_free_solves_17_joints(tmp_path):
    """The ball game with the waist free: 17 active joints, a shared waist in both hands' Jacobians."""
    task = load_task(
        _variant(tmp_path, (TASKS / "ball_game.toml").read_text().replace('waist = "locked"', 'waist = "free"'))
    )
    path = solve_tvgdd(task.robot, build_reference(task), task.initial_q, settings_for(task))
    assert len(path.joint_names) == 17 and sum(n.startswith("waist") for n in path.joint_names) == 3
    assert np.abs(path.qd[:, [n.startswith("waist") for n in path.joint_names]]).max() > 1e-3  # the waist does move
    m = ik_metrics(path, task.robot)
    assert m["ik.position_error_max_m"] <= PAPER_MAE_M and m["ik.joint_limit_violations"] == 0
