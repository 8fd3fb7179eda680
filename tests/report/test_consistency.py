"""``dualarm consistency``: the table is the runs' own metrics, and the figures exist."""

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from dualarm.cli import app
from dualarm.model.robot import load_robot
from dualarm.record.readback import read_run
from dualarm.report.consistency import COLUMNS
from tests.helpers import HUMANOID, TASKS

runner = CliRunner()


@pytest.fixture(scope="module")
def short_circle(tmp_path_factory):
    text = (TASKS / "circle.toml").read_text().replace('robot = "../robots/humanoid"', f'robot = "{HUMANOID}"')
    path = tmp_path_factory.mktemp("tasks") / "circle.toml"
    path.write_text(text.replace("duration_s = 4.0", "duration_s = 1.0"))
    return path


@pytest.mark.integration
def test_consistency_writes_the_runs_metrics_and_figures(short_circle, tmp_path):
    result = runner.invoke(
        app,
        ["consistency", str(short_circle), "--methods", "mc-inverse,dls-svd", "--reps", "3", "--out", str(tmp_path)],
    )
    # a circle in 1 s asks the shoulder for more than its velocity limit (no retime follows the IK
    # runs of a consistency comparison): both runs are violated, which the table and the exit say
    assert result.exit_code == 3, result.output
    table = pd.read_csv(tmp_path / "consistency.csv")
    assert list(table["status"]) == ["violated", "violated"] and all(
        v.startswith("ik: velocity of ") for v in table["violation"]
    )
    robot = load_robot(HUMANOID)
    arm = tuple(robot.hand_chain("left").joint_names)
    for _, row in table.iterrows():
        joints = read_run(Path(row["run"]))["/ik/sample"][[f"position.{n}" for n in arm]].to_numpy()
        assert (
            np.abs(np.diff(joints, axis=0)).max(axis=0) / 0.01 > robot.limit_array("velocity", arm)
        ).any()  # finite differences of the recorded joints
    assert list(table.columns[: len(COLUMNS) + 1]) == ["method", *COLUMNS]
    assert list(table["method"]) == ["mc-inverse", "dls-svd"]
    for _, row in table.iterrows():
        run = json.loads((Path(row["run"]) / "manifest.json").read_text())
        metrics = json.loads((Path(row["run"]) / "metrics.json").read_text())
        assert run["settings"]["path"]["repetitions"] == 3 and run["settings"]["ik"]["method"] == row["method"]
        for column in COLUMNS:
            assert row[column] == pytest.approx(metrics[f"ik.{column}"], rel=1e-12, abs=0)
    mc = table.set_index("method").loc["mc-inverse"]
    assert mc["rep_joint_deviation_max_rad"] <= 1e-9 and mc["failed_reps"] == 0
    for name in ("joints_left.png", "arm_angle.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    markdown = (tmp_path / "consistency.md").read_text()
    assert "| mc-inverse |" in markdown and "arm_angle.png" in markdown


def test_an_unknown_method_writes_nothing(short_circle, tmp_path):
    result = runner.invoke(
        app, ["consistency", str(short_circle), "--methods", "mc-inverse,magic", "--out", str(tmp_path / "out")]
    )
    assert result.exit_code == 2
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "unknown IK method 'magic'" in lines[0]
    assert not (tmp_path / "out").exists()


@pytest.mark.integration
def test_a_failing_method_is_a_row_not_the_end(short_circle, tmp_path):
    """MC-Inverse held to psi in (-0.1, 0.1) cannot draw the circle: its row says so, and the
    other method still runs."""
    narrow = tmp_path / "circle.toml"
    narrow.write_text(
        short_circle.read_text().replace("range_rad = [-3.141592653589793, 0.0]", "range_rad = [-0.1, 0.1]")
    )
    result = runner.invoke(
        app,
        ["consistency", str(narrow), "--methods", "mc-inverse,pybullet", "--reps", "2", "--out", str(tmp_path / "out")],
    )
    assert result.exit_code == 1, result.output  # the worst verdict: a failed run
    table = pd.read_csv(tmp_path / "out" / "consistency.csv").set_index("method")
    assert table.loc["mc-inverse", "status"] == "failed" and "arm_angle.range_rad" in table.loc["mc-inverse", "error"]
    assert np.isnan(table.loc["mc-inverse", "rep_joint_deviation_max_rad"])
    assert table.loc["pybullet", "status"] in (
        "complete",
        "violated",
    )  # it ran (its verdict may name its failed samples)
    manifest = json.loads((Path(table.loc["mc-inverse", "run"]) / "manifest.json").read_text())
    assert manifest["status"] == "failed"
