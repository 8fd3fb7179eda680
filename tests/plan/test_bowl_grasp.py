"""The bowl grasp: the scenario needs planning, both planners solve it, the first plan executes
without collision, and bad input fails in one line."""

import json
import re

import numpy as np
import pandas as pd
import pytest
from mcap.reader import make_reader
from typer.testing import CliRunner

from dualarm.cli import app
from dualarm.errors import StageError
from dualarm.plan.collision import CollisionChecker
from dualarm.plan.mcikrrt import TreeSearchSettings
from dualarm.plan.problem import PlanningProblem, PlanningSettings
from dualarm.record.readback import read_run
from dualarm.tasks import load_task
from tests.helpers import TASKS

BOWL = TASKS / "bowl_grasp.toml"
runner = CliRunner()


@pytest.fixture(scope="module")
def task():
    return load_task(BOWL)


@pytest.fixture(scope="module")
def problem(task):
    with PlanningProblem(task) as p:
        yield p


@pytest.fixture(scope="module")
def bare_checker(task, problem):
    """The same pairs without any safety margin, at a finer resolution."""
    with CollisionChecker(
        task.robot,
        problem.joint_names,
        problem.fixed,
        task.spec.environment,
        task.spec.expected_contacts,
        margin_m=0.0,
        resolution_rad=0.005,
    ) as checker:
        yield checker


@pytest.mark.integration
def test_the_straight_segment_to_every_goal_collides(problem, bare_checker):
    goals = []
    for seed in range(6):
        sampler = problem.goal_sampler(seed)
        for _ in range(12):
            sampler()
        goals += sampler.goals
    assert len(goals) >= 20
    for goal in goals:
        assert bare_checker.free(goal)
        assert not bare_checker.segment_free(problem.start, goal)


@pytest.mark.integration
@pytest.mark.parametrize("planner", ["mcikrrt", "ompl-rrtconnect"])
def test_planners_find_free_paths(problem, bare_checker, planner):
    for seed in range(3):
        result = problem.solve(planner, seed)
        assert result.success, result.reason
        assert np.array_equal(result.path[0], problem.start)
        assert np.all(result.path >= problem.lower - 1e-12) and np.all(result.path <= problem.upper + 1e-12)
        for a, b in zip(result.path[:-1], result.path[1:], strict=True):
            assert bare_checker.segment_free(a, b)
        # the last waypoint puts each hand in its WTA (eq 26 distance ~ 0)
        poses = problem.task.hand_poses(problem.joint_names, result.path[-1:], problem.fixed)
        for hand, areas in problem.areas.items():
            assert min(float(a.distance(poses[hand][0])) for a in areas) < 1e-5


@pytest.mark.integration
def test_plan_command_writes_trials_summary_and_a_collision_free_run(tmp_path, bare_checker):
    result = runner.invoke(
        app,
        ["plan", str(BOWL), "--trials", "3", "--out", str(tmp_path / "plan"), "--recordings", str(tmp_path / "rec")],
    )
    assert result.exit_code == 0, result.output
    table = pd.read_csv(tmp_path / "plan" / "plan_trials.csv")
    summary = json.loads((tmp_path / "plan" / "plan_summary.json").read_text())
    assert len(table) == 3 and list(table.seed) == [0, 1, 2]
    assert summary["success_rate"] == table.success.mean() == 1.0
    assert summary["planning_time_median_s"] == pytest.approx(np.median(table.planning_time_s))
    assert summary["planning_time_p95_s"] == pytest.approx(np.percentile(table.planning_time_s, 95))
    run = read_run(summary["run"])
    assert run.manifest["stages"] == ["path", "plan", "retime", "smooth", "approach", "execute"]
    m = run.metrics
    assert m["plan.planning_time_s"] == pytest.approx(table.planning_time_s[0])
    assert m["plan.collision_checks"] == table.collision_checks[0]
    assert m["execute.self_collisions"] == 0 and m["execute.environment_collisions"] == 0
    assert m["execute.tracking_error_max_m"] < 1e-3
    planned = run.topics["/plan/sample"]
    names = bare_checker.joint_names
    for q in planned[[f"position.{n}" for n in names]].to_numpy()[::5]:
        assert bare_checker.free(q)
    with open(run.directory / "run.mcap", "rb") as f:
        channels = make_reader(f).get_summary().channels.values()
    scene = [c for c in channels if c.topic == "/task/environment"]
    assert len(scene) == 1 and scene[0].message_encoding == "protobuf"


@pytest.mark.integration
def test_unreachable_wta_is_named_at_the_timeout(tmp_path):
    text = BOWL.read_text().replace(
        'name = "bowl_right"\nhand = "right"\nreference = { position = [0.40, 0.0, 0.93] }',
        'name = "bowl_right"\nhand = "right"\nreference = { position = [1.60, 0.0, 0.93] }',
    )
    (tmp_path / "far.toml").write_text(
        text.replace('robot = "../robots/humanoid"', f'robot = "{TASKS.parent / "robots" / "humanoid"}"')
    )
    result = runner.invoke(app, ["run", str(tmp_path / "far.toml"), "--timeout", "0.5", "--out", str(tmp_path / "rec")])
    assert result.exit_code == 1  # the planner failed: the run is kept as failed
    lines = result.output.strip().splitlines()
    assert len(lines) == 3 and lines[0] == "verdict: failed" and lines[2].startswith("the run is kept as failed in ")
    line = lines[1]
    assert re.search(r"no IK sample reached WTA 'bowl_right' \(\d+ samples, nearest [0-9.]+ m\)", line), line
    assert "bowl_left" not in line


@pytest.mark.integration
def test_start_in_collision_names_the_pair(tmp_path):
    text = BOWL.read_text().replace(
        "[[wta]]",
        '[[environment]]\nname = "post"\nshape = "box"\nsize_m = [0.05, 0.05, 0.3]\n'
        "pose = { position = [0.0, 0.2, 0.8] }\n\n[[wta]]",
        1,
    )
    (tmp_path / "hit.toml").write_text(
        text.replace('robot = "../robots/humanoid"', f'robot = "{TASKS.parent / "robots" / "humanoid"}"')
    )
    with pytest.raises(
        StageError, match=r"start configuration is in collision: left_(forearm|upper_arm|palm) with post"
    ):
        PlanningProblem(load_task(tmp_path / "hit.toml"))
    result = runner.invoke(app, ["run", str(tmp_path / "hit.toml"), "--out", str(tmp_path / "rec")])
    assert result.exit_code == 2 and "with post" in result.output
    assert not (tmp_path / "rec").exists()  # refused before any run was written


@pytest.mark.integration
def test_obstacle_overlapping_the_base_is_refused_at_load(tmp_path):
    text = BOWL.read_text().replace("pose = { position = [0.30, 0.0, 0.97] }", "pose = { position = [0.0, 0.05, 0.6] }")
    assert text != BOWL.read_text()
    (tmp_path / "base.toml").write_text(
        text.replace('robot = "../robots/humanoid"', f'robot = "{TASKS.parent / "robots" / "humanoid"}"')
    )
    result = runner.invoke(app, ["run", str(tmp_path / "base.toml"), "--out", str(tmp_path / "rec")])
    assert result.exit_code == 2
    assert re.search(r"environment\[2\]: 'panel' overlaps the robot's base link 'pelvis'", result.output), result.output
    assert not (tmp_path / "rec").exists()


def test_unknown_planner_is_one_line():
    result = runner.invoke(app, ["plan", str(BOWL), "--planner", "prm"])
    assert result.exit_code == 2 and "unknown planner 'prm'" in result.output


@pytest.mark.integration
def test_ompl_without_goals_names_the_wta(tmp_path):
    text = BOWL.read_text().replace(
        'name = "bowl_left"\nhand = "left"\nreference = { position = [0.40, 0.0, 0.93] }',
        'name = "bowl_left"\nhand = "left"\nreference = { position = [0.40, 1.50, 0.93] }',
    )
    (tmp_path / "far.toml").write_text(
        text.replace('robot = "../robots/humanoid"', f'robot = "{TASKS.parent / "robots" / "humanoid"}"')
    )
    settings = PlanningSettings(planner=TreeSearchSettings(timeout_s=0.3))
    with PlanningProblem(load_task(tmp_path / "far.toml"), settings) as problem:
        result = problem.solve("ompl-rrtconnect", 0)
    assert not result.success and result.goals == 0
    # the far area is named first (the right hand, dragged over the shared waist, may miss too)
    assert re.search(r"no IK sample reached WTA 'bowl_left' \(\d+ samples, nearest 0\.[0-9]+ m\)", result.reason), (
        result.reason
    )
