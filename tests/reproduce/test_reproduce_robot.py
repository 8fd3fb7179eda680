"""`dualarm reproduce --robot`: the papers' experiments on a robot nobody here wrote them for; the parts it cannot run
reported as not available, with the reason."""

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from dualarm.cli import app
from tests.helpers import REPO, pybullet_urdf

runner = CliRunner()
DUAL_IIWA = REPO / "robots" / "dual_iiwa"


@pytest.mark.integration
def test_the_paper_experiments_run_on_the_dual_iiwa_and_the_bowl_grasp_is_not_available(tmp_path):
    """Table I's analogue, the pinv ball game and the bowl grasp on the dual iiwa: the first two run (every valid Table
    I candidate puts the iiwa's hand on the asked pose by PyBullet's FK), the bowl grasp is reported as not available
    because the robot has no waist; exit 0; the report names the robot and the reason; each command to reproduce a part
    alone carries --robot."""
    out = tmp_path / "repro"
    result = runner.invoke(
        app,
        [
            "reproduce",
            "--robot",
            "dual_iiwa",
            "--only",
            "table-i,ball-game-pinv,bowl-grasp",
            "--jobs",
            "1",
            "--out",
            str(out),
        ],
    )
    assert result.exit_code == 0, result.output
    index = json.loads((out / "parts.json").read_text())
    assert index["robot"]["name"] == "dual_iiwa"
    parts = {p["name"]: p for p in index["parts"]}
    assert parts["table-i"]["status"] == parts["ball-game-pinv"]["status"] == "complete"
    assert parts["bowl-grasp"]["status"] == "not available"
    assert "waist" in parts["bowl-grasp"]["error"]
    report = (out / "report.md").read_text()
    assert "reproduced on dual_iiwa" in report
    assert "not available on dual_iiwa: plans with the waist free" in report
    assert "--robot" in report and "dualarm run tasks/ball_game.toml --ik pinv --stages path,ik --robot" in report
    (run,) = parts["ball-game-pinv"]["outputs"]["runs"]
    manifest = json.loads((out / run / "manifest.json").read_text())
    assert manifest["robot"] == "dual_iiwa" and "--robot" in manifest["command"]

    table = json.loads((out / parts["table-i"]["outputs"]["table"]).read_text())
    asked = np.eye(4)
    asked[:3, :3] = Rotation.from_euler("xyz", table["pose"][3:]).as_matrix()
    asked[:3, 3] = table["pose"][:3]
    with pybullet_urdf(DUAL_IIWA / "dual_iiwa.urdf") as sim:
        valid = [c for c in table["candidates"] if c["valid"]]
        assert len(valid) >= 4
        for candidate in valid:
            sim.set([f"left_lbr_iiwa_joint_{k}" for k in range(1, 8)], candidate["q"])
            reached = np.linalg.inv(sim.frame(table["chain"]["base"])) @ sim.frame("left_lbr_iiwa_link_7")
            assert np.linalg.norm(reached[:3, 3] - asked[:3, 3]) < 1e-6  # PyBullet's link states are float32
            assert np.abs(reached[:3, :3] - asked[:3, :3]).max() < 1e-6


def test_a_robot_that_runs_no_part_exits_2_and_the_report_says_why(tmp_path):
    """The Panda (one arm, not S-R-S): Table I needs an S-R-S left arm, the carried box S-R-S arms, the triangle a left
    hand; each is named in one line, nothing runs, exit 2."""
    out = tmp_path / "repro"
    result = runner.invoke(
        app, ["reproduce", "--robot", "panda", "--only", "table-i,carry-box,triangle", "--jobs", "1", "--out", str(out)]
    )
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    assert "no part of the reproduction runs on panda" in result.stderr
    parts = {p["name"]: p for p in json.loads((out / "parts.json").read_text())["parts"]}
    assert {p["status"] for p in parts.values()} == {"not available"}
    assert "needs a left arm" in parts["table-i"]["error"]
    assert "S-R-S" in parts["carry-box"]["error"]
    assert "triangle.toml:frame" in parts["triangle"]["error"]
    assert "\n" not in "".join(p["error"] for p in parts.values())
