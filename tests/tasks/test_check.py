"""``dualarm task check``: shipped tasks pass, an unreachable waypoint is named (exit 3), a malformed task is one line
(exit 2)."""

import os

import numpy as np
import pytest
from tests.helpers import HUMANOID, TASKS
from typer.testing import CliRunner

from dualarm.cli import app

runner = CliRunner()


@pytest.mark.parametrize(
    "name",
    # the bowl grasp's check builds its environment in a PyBullet world
    ["triangle", "circle", "carry_box", "ball_game", pytest.param("bowl_grasp", marks=pytest.mark.integration)],
)
def test_shipped_tasks_check_out(name):
    result = runner.invoke(app, ["task", "check", str(TASKS / f"{name}.toml")])
    assert result.exit_code == 0, result.output
    assert "NOT reachable" not in result.stdout


def test_the_reported_intervals_hold_in_a_single_solve(humanoid):
    """A psi in the middle of each reported interval of waypoint A gives, for that branch, joints inside the robot's
    limits that reach the pose by the chain's FK."""
    from dualarm.ik.analytic.mc_inverse import mc_inverse
    from dualarm.model.kinematics import hand_pose
    from dualarm.model.poses import pose_matrix
    from dualarm.task_check import check_task

    result = check_task(TASKS / "triangle.toml")
    a = next(w for w in result.waypoints if w.key == "waypoints.A")
    target = pose_matrix(a.position_m, a.rpy_rad)
    lower, upper = humanoid.lower_upper(humanoid.hand_chain("left").joint_names)
    for b, intervals in a.branches.items():
        for lo, hi in intervals:
            q = mc_inverse(humanoid, "left", target, float(np.angle(np.exp(1j * (lo + hi) / 2)))).q[b]
            names = humanoid.hand_chain("left").joint_names
            assert np.all((q >= lower) & (q <= upper))
            reached = hand_pose(humanoid, "left", dict(zip(names, q, strict=True)))
            assert np.abs(reached - target).max() < 1e-9


def _triangle(tmp_path, a_position: str):
    text = (TASKS / "triangle.toml").read_text().replace('robot = "../robots/humanoid"', f'robot = "{HUMANOID}"')
    path = tmp_path / "triangle.toml"
    path.write_text(text.replace("position = [0.300, 0.070, -0.397]", f"position = {a_position}"))
    return path


def test_an_unreachable_waypoint_is_named_and_exits_3(tmp_path):
    path = _triangle(tmp_path, "[0.300, 0.270, 2.500]")  # 1.5 m above: beyond the arm's span
    result = runner.invoke(app, ["task", "check", str(path)])
    assert result.exit_code == 3, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and ":waypoints.A: the left hand cannot reach it" in lines[0]
    assert "waypoints.B (left hand)" in result.stdout and "waypoints.A (left hand)" in result.stdout


def test_a_malformed_task_is_one_line_exit_2(tmp_path):
    path = _triangle(tmp_path, "[0.300, 0.270]")
    result = runner.invoke(app, ["task", "check", str(path)])
    assert (
        result.exit_code == 2
        and len(result.stderr.strip().splitlines()) == 1
        and "waypoints.A.position" in result.stderr
    )


def test_a_relative_robot_path_is_taken_from_the_working_directory(tmp_path, monkeypatch):
    """``--robot`` relative to where the user is (not to the task file), as ``dualarm run --robot`` takes it: the same
    report as the absolute path."""
    robot = HUMANOID.parent / "dual_iiwa"
    monkeypatch.chdir(tmp_path)
    relative = os.path.relpath(robot, tmp_path)
    by_relative = runner.invoke(app, ["task", "check", str(TASKS / "triangle.toml"), "--robot", relative])
    by_absolute = runner.invoke(app, ["task", "check", str(TASKS / "triangle.toml"), "--robot", str(robot)])
    assert by_relative.exit_code == by_absolute.exit_code == 0, by_relative.output
    assert by_relative.stdout == by_absolute.stdout


@pytest.mark.integration
def test_a_task_whose_path_leaves_reach_is_refused_as_the_run_refuses_it(tmp_path):
    """The circle with its centre moved 0.5 m right: its start is within reach, the arc is not. task check refuses it
    (exit 3) with the very line ``dualarm run`` refuses it with (exit 2, before any stage), naming the move and time;
    it passed before (it checked waypoints only)."""
    text = (TASKS / "circle.toml").read_text().replace('robot = "../robots/humanoid"', f'robot = "{HUMANOID}"')
    path = tmp_path / "circle.toml"
    path.write_text(text.replace("arc_center = [0.31, -0.11, -0.35]", "arc_center = [0.31, -0.61, -0.35]"))
    checked = runner.invoke(app, ["task", "check", str(path)])
    assert checked.exit_code == 3, checked.output
    assert "waypoints.P0 (left hand)" in checked.stdout and "NOT reachable" not in checked.stdout
    (line,) = checked.stderr.strip().splitlines()
    assert ":moves[0]: at t = " in line and "the left hand cannot reach" in line
    ran = runner.invoke(app, ["run", str(path), "--ik", "mc-inverse", "--reps", "1", "--out", str(tmp_path / "runs")])
    assert ran.exit_code == 2 and ran.stderr.strip() == f"error: {line}", ran.output


def test_a_task_check_that_passes_says_how_many_samples_it_checked():
    result = runner.invoke(app, ["task", "check", str(TASKS / "circle.toml")])
    assert result.exit_code == 0 and "path: all 2001 samples within reach" in result.stdout, result.output
