"""The command line: help texts, robot check, and one-line errors."""

import pytest
from typer.testing import CliRunner

from dualarm.cli import app
from tests.conftest import HUMANOID, TASKS

runner = CliRunner()


@pytest.mark.parametrize(
    "command",
    [[], ["run"], ["inspect"], ["report"], ["bench"], ["bench", "tvgdd"], ["bench", "ik"], ["bench", "plan"], ["plan"], ["consistency"], ["robot"], ["robot", "check"], ["ik"], ["ik", "srs"]],
)
def test_every_command_has_help(command):
    result = runner.invoke(app, [*command, "--help"])
    assert result.exit_code == 0
    assert "Usage" in result.output and len(result.output.splitlines()) > 3


def test_robot_check_humanoid_passes():
    result = runner.invoke(app, ["robot", "check", str(HUMANOID)])
    assert result.exit_code == 0, result.output
    for chain in ("left_arm", "right_arm", "waist"):
        assert chain in result.stdout
    assert result.stdout.count("pass") == 3 and "FAIL" not in result.stdout
    assert "L2 = 0.3200 m" in result.stdout


def test_robot_check_bare_urdf(kuka_urdf):
    result = runner.invoke(app, ["robot", "check", "--urdf", str(kuka_urdf), "--base", "lbr_iiwa_link_0", "--tip", "lbr_iiwa_link_7", "--samples", "200"])
    assert result.exit_code == 0, result.output
    assert "7 DOF" in result.stdout and "S-R-S" in result.stdout


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["robot", "check"], "give either ROBOT_DIR or --urdf"),
        (["robot", "check", "robots/none"], "no robot.toml"),
        (["robot", "check", "--urdf", "x.urdf", "--base", "a"], "--urdf needs --base LINK and --tip LINK"),
        (["robot", "check", "--urdf", str(HUMANOID / "humanoid.urdf"), "--base", "torso", "--tip", "foot"], "no link 'foot'"),
        (["robot", "check", "--urdf", str(HUMANOID / "humanoid.urdf"), "--base", "left_hand", "--tip", "torso"], "is not below link"),
        (["run", str(TASKS / "triangle.toml"), "--stages", "path,ik,smooth", "--ik", "pinv"], "stage 'smooth' needs stage 'retime'"),
        (["run", str(TASKS / "triangle.toml"), "--ik", "pinv", "--timing", "slow"], "unknown timing 'slow' (timings: optimal, task)"),
        (["run", str(TASKS / "triangle.toml"), "--stages", "path,ik"], "stage 'ik' needs --ik METHOD"),
        (["run", str(TASKS / "ball_game.toml"), "--ik", "magic"], "unknown IK method 'magic'"),
        (["run", str(TASKS / "ball_game.toml"), "--ik", "tvgdd", "--scheme", "fast"], "unknown TV-GDD scheme 'fast'"),
        (["run", str(TASKS / "ball_game.toml"), "--ik", "tvgdd", "--qp-backend", "gurobi"], "unknown QP backend 'gurobi'"),
        (["run", str(TASKS / "triangle.toml"), "--stages", "fly"], "unknown stage 'fly'"),
        (["inspect", "recordings/no-such-run"], "no such run directory"),
        (["ik", "srs", str(HUMANOID), "--pose", "0.3", "0.2", "0.1", "0", "0", "0", "--arm-angle", "0"], "give --arm left or --arm right"),
        (["ik", "srs", "--urdf", str(HUMANOID / "humanoid.urdf"), "--base", "pelvis", "--tip", "left_hand", "--pose", "0.3", "0.2", "0.1", "0", "0", "0", "--arm-angle", "0"], "10 movable joints"),
    ],
)
def test_user_mistakes_give_one_line_and_exit_2(args, needle, tmp_path):
    result = runner.invoke(app, args)
    assert result.exit_code == 2
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and needle in lines[0], result.stderr
    assert "Traceback" not in result.output


@pytest.mark.parametrize("backend", ["casadi", "lvi"])
def test_infeasible_ik_step_prints_one_line_even_from_c(backend, tmp_path):
    """Run in a subprocess, so that anything CasADi prints from C would show on stderr too."""
    import subprocess
    import sys

    text = (TASKS / "ball_game.toml").read_text().replace('robot = "../robots/humanoid"', f'robot = "{HUMANOID}"')
    task = tmp_path / "ball_game.toml"
    task.write_text(text.replace("velocity = 6.0", "velocity = 0.01"))
    command = [sys.executable, "-c", "from dualarm.cli import app; app()", "run", str(task), "--ik", "tvgdd", "--qp-backend", backend, "--out", str(tmp_path / "out")]
    result = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert result.returncode == 2
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: TV-GDD step "), result.stderr
    assert "meets the hand-velocity equality (24)" in lines[0]


def test_ik_srs_json_lists_8_candidates_that_pybullet_confirms(humanoid):
    """Table I's analogue: every candidate of the JSON output reaches the pose in PyBullet, the
    valid ones are inside the limits, and all share the elbow magnitude |theta_4|."""
    import json

    import numpy as np

    from dualarm.execute.world import load_pybullet_robot
    from dualarm.model.poses import pose_matrix

    pose = [0.147, 0.404, 0.455, 0.937, 0.560, -0.377]
    result = runner.invoke(app, ["ik", "srs", str(HUMANOID), "--arm", "left", "--pose", *map(str, pose), "--arm-angle", "2.2", "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    candidates = data["candidates"]
    assert len(candidates) == 8 and {c["reason"] for c in candidates} <= {"valid", "outside limits"}
    target = pose_matrix(pose[:3], pose[3:])
    lower, upper = humanoid.lower_upper(tuple(data["chain"]["joints"]))
    with load_pybullet_robot(humanoid.urdf.path) as sim:
        for c in candidates:
            sim.set_positions(data["chain"]["joints"], c["q"])
            hand = np.linalg.inv(sim.link_pose("torso")) @ sim.link_pose("left_hand")
            assert np.abs(hand - target).max() < 1e-6 and c["position_error_m"] < 1e-9
            assert c["valid"] == bool(np.all((np.array(c["q"]) >= lower) & (np.array(c["q"]) <= upper)))
    assert len({round(abs(c["q"][3]), 12) for c in candidates}) == 1
