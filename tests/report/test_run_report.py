"""``dualarm report`` on real recordings."""

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from dualarm.cli import app
from dualarm.ik.velocity.pinv import settings_for, solve_pinv
from dualarm.paths import build_reference
from dualarm.record.readback import read_run
from dualarm.report.run_report import excursions, write_report
from dualarm.run import record_run
from dualarm.tasks import load_task
from tests.helpers import HUMANOID, TASKS

pytestmark = pytest.mark.integration


def test_report_of_a_pinv_run(tmp_path):
    run = record_run(TASKS / "ball_game.toml", "pinv", stages=("path", "ik"), out_dir=tmp_path / "runs").directory
    result = CliRunner().invoke(app, ["report", str(run), "--out", str(tmp_path / "report")])
    assert result.exit_code == 0, result.output
    out = Path(result.stdout.strip().splitlines()[-1])
    assert {p.name for p in out.glob("*.png")} == {
        "hand_errors.png",
        "joints_vs_bounds.png",
        "velocities_vs_bounds.png",
        "bound_profiles.png",
    }
    summary = (out / "summary.md").read_text()
    assert "## IK: pinv" in summary and "ik.position_error_max_m" in summary

    # the excursion table read back from the recording equals one computed from the solver's arrays
    task = load_task(TASKS / "ball_game.toml")
    path = solve_pinv(task.robot, build_reference(task), task.initial_q, settings_for(task))
    lo, hi = path.extras["theta_lower"], path.extras["theta_upper"]
    outside = np.maximum(lo - path.q, path.q - hi).max(axis=0)
    expected = {n: v for n, v in zip(path.joint_names, outside, strict=True) if v > 1e-9}
    data = read_run(run)
    table = excursions(data["/ik/sample"], data["/ik/bounds"], "position")
    assert dict(zip(table["joint"], table["max_outside"], strict=True)).keys() == expected.keys()
    for joint, value in zip(table["joint"], table["max_outside"], strict=True):
        assert abs(value - expected[joint]) < 1e-12


def test_report_lists_joints_leaving_their_physical_limits(tmp_path):
    """pinv under a 0.05 rad/s velocity limit it ignores: the report's table of velocity-limit
    excursions equals the one computed from the solver's velocities and the task's limit."""
    text = (TASKS / "ball_game.toml").read_text().replace("velocity = 6.0", "velocity = 0.05")
    assert "velocity = 0.05" in text
    task_file = tmp_path / "ball_game.toml"
    task_file.write_text(text.replace('robot = "../robots/humanoid"', f'robot = "{HUMANOID}"'))
    run = record_run(task_file, "pinv", stages=("path", "ik"), out_dir=tmp_path / "runs").directory
    out = write_report(run, tmp_path / "report")

    task = load_task(task_file)
    path = solve_pinv(task.robot, build_reference(task), task.initial_q, settings_for(task))
    fastest = np.abs(path.qd).max(axis=0) - 0.05
    expected = {n: v for n, v in zip(path.joint_names, fastest, strict=True) if v > 1e-9}
    assert expected, "the limit should be exceeded"
    table = pd.read_csv(out / "velocity_limit_excursions.csv")
    assert dict(zip(table["joint"], table["max_outside"], strict=True)).keys() == expected.keys()
    for joint, value in zip(table["joint"], table["max_outside"], strict=True):
        assert abs(value - expected[joint]) < 1e-9
    summary = (out / "summary.md").read_text()
    assert "Joint velocities outside their physical limits:" in summary
    assert "Joint positions outside their physical limits: none." in summary
