"""``dualarm report`` on real recordings."""

from pathlib import Path

import numpy as np
from typer.testing import CliRunner

from pipeline.cli import app
from pipeline.ik.pinv import solve_pinv
from pipeline.ik.tvgdd import settings_for
from pipeline.paths import build_reference
from pipeline.record.readback import read_run
from pipeline.report.run_report import excursions
from pipeline.run import run_task
from pipeline.tasks import load_task
from tests.conftest import TASKS


def test_report_of_a_pinv_run(tmp_path):
    run = run_task(TASKS / "ball_game.toml", ik="pinv", out_dir=tmp_path / "runs")
    result = CliRunner().invoke(app, ["report", str(run), "--out", str(tmp_path / "report")])
    assert result.exit_code == 0, result.output
    out = Path(result.stdout.strip().splitlines()[-1])
    assert {p.name for p in out.glob("*.png")} == {"hand_errors.png", "joints_vs_bounds.png", "velocities_vs_bounds.png", "bound_profiles.png"}
    summary = (out / "summary.md").read_text()
    assert "## IK: pinv" in summary and "ik.position_error_max_m" in summary

    # the excursion table read back from the recording equals one computed from the solver's arrays
    task = load_task(TASKS / "ball_game.toml")
    path = solve_pinv(task, build_reference(task), settings_for(task).feedback_gain)
    lo, hi = path.extras["theta_lower"], path.extras["theta_upper"]
    outside = np.maximum(lo - path.q, path.q - hi).max(axis=0)
    expected = {n: v for n, v in zip(path.joint_names, outside) if v > 1e-9}
    data = read_run(run)
    table = excursions(data["/ik/sample"], data["/ik/bounds"], "position")
    assert dict(zip(table["joint"], table["max_outside"])).keys() == expected.keys()
    for joint, value in zip(table["joint"], table["max_outside"]):
        assert abs(value - expected[joint]) < 1e-12
