"""The command line: help texts, robot check, and one-line errors."""

import pytest
from typer.testing import CliRunner

from dualarm.cli import app
from tests.helpers import HUMANOID, TASKS

runner = CliRunner()


def _commands(group=None, prefix=()) -> list[list[str]]:
    """Every command and group of the CLI, walked from typer's command tree (so that a new command cannot be missed)."""
    import typer

    group = group if group is not None else typer.main.get_command(app)
    found = [list(prefix)]
    for name, command in getattr(group, "commands", {}).items():
        found += _commands(command, (*prefix, name)) if hasattr(command, "commands") else [[*prefix, name]]
    return found


def test_the_command_walk_finds_the_commands_users_type():
    assert {
        ("reproduce",),
        ("robot", "init"),
        ("robot", "poses"),
        ("task", "check"),
        ("ik", "srs"),
        ("view",),
        ("bench", "plan"),
    } <= {tuple(c) for c in _commands()}


@pytest.mark.parametrize("command", _commands(), ids=lambda c: " ".join(c) or "dualarm")
def test_every_command_has_help(command):
    result = runner.invoke(app, [*command, "--help"])
    assert result.exit_code == 0
    assert "Usage" in result.output and len(result.output.splitlines()) > 3


@pytest.mark.integration
def test_robot_check_humanoid_passes():
    result = runner.invoke(app, ["robot", "check", str(HUMANOID)])
    assert result.exit_code == 0, result.output
    for chain in ("left_arm", "right_arm", "waist"):
        assert chain in result.stdout
    assert result.stdout.count("pass") == 3 and "FAIL" not in result.stdout
    assert "L2 = 0.3200 m" in result.stdout


@pytest.mark.integration
def test_robot_check_bare_urdf(kuka_urdf):
    result = runner.invoke(
        app,
        [
            "robot",
            "check",
            "--urdf",
            str(kuka_urdf),
            "--base",
            "lbr_iiwa_link_0",
            "--tip",
            "lbr_iiwa_link_7",
            "--samples",
            "200",
        ],
    )
    assert result.exit_code == 0, result.output
    assert "7 DOF" in result.stdout and "S-R-S" in result.stdout


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["robot", "check"], "give either ROBOT_DIR or --urdf"),
        (["robot", "check", "robots/none"], "no robot.toml"),
        (["robot", "check", "--urdf", "x.urdf", "--base", "a"], "--urdf needs --base LINK and --tip LINK"),
        (
            ["robot", "check", "--urdf", str(HUMANOID / "humanoid.urdf"), "--base", "torso", "--tip", "foot"],
            "no link 'foot'",
        ),
        (
            ["robot", "check", "--urdf", str(HUMANOID / "humanoid.urdf"), "--base", "left_hand", "--tip", "torso"],
            "is not below link",
        ),
        (
            ["run", str(TASKS / "triangle.toml"), "--stages", "path,ik,smooth", "--ik", "pinv"],
            "stage 'smooth' needs stage 'retime'",
        ),
        (
            ["run", str(TASKS / "triangle.toml"), "--ik", "pinv", "--timing", "slow"],
            "unknown timing 'slow' (timings: jerk-limited, optimal, task)",
        ),
        (["run", str(TASKS / "triangle.toml"), "--stages", "path,ik"], "stage 'ik' needs --ik METHOD"),
        (["run", str(TASKS / "ball_game.toml"), "--ik", "magic"], "unknown IK method 'magic'"),
        (["run", str(TASKS / "ball_game.toml"), "--ik", "tvgdd", "--scheme", "fast"], "unknown TV-GDD scheme 'fast'"),
        (
            ["run", str(TASKS / "ball_game.toml"), "--ik", "tvgdd", "--qp-backend", "gurobi"],
            "unknown QP backend 'gurobi'",
        ),
        (["run", str(TASKS / "triangle.toml"), "--stages", "fly"], "unknown stage 'fly'"),
        (["inspect", "recordings/no-such-run"], "no such run directory"),
        (
            ["ik", "srs", str(HUMANOID), "--pose", "0.3", "0.2", "0.1", "0", "0", "0", "--arm-angle", "0"],
            "give --arm left or --arm right",
        ),
        (
            [
                "ik",
                "srs",
                "--urdf",
                str(HUMANOID / "humanoid.urdf"),
                "--base",
                "pelvis",
                "--tip",
                "left_hand",
                "--pose",
                "0.3",
                "0.2",
                "0.1",
                "0",
                "0",
                "0",
                "--arm-angle",
                "0",
            ],
            "10 movable joints",
        ),
    ],
)
def test_user_mistakes_give_one_line_and_exit_2(args, needle, tmp_path):
    result = runner.invoke(app, args)
    assert result.exit_code == 2
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and needle in lines[0], result.stderr
    assert "Traceback" not in result.output


@pytest.mark.integration
@pytest.mark.parametrize("backend", ["casadi", "lvi"])
def test_infeasible_ik_step_prints_one_line_even_from_c(backend, tmp_path):
    """Run in a subprocess, so that anything CasADi prints from C would show on stderr too."""
    import subprocess
    import sys

    text = (TASKS / "ball_game.toml").read_text().replace('robot = "../robots/humanoid"', f'robot = "{HUMANOID}"')
    task = tmp_path / "ball_game.toml"
    task.write_text(text.replace("velocity = 6.0", "velocity = 0.01"))
    command = [
        sys.executable,
        "-c",
        "from dualarm.cli import app; app()",
        "run",
        str(task),
        "--ik",
        "tvgdd",
        "--qp-backend",
        backend,
        "--out",
        str(tmp_path / "out"),
    ]
    result = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert result.returncode == 1  # the run failed on valid input
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 3 and lines[0] == "verdict: failed" and lines[1].startswith("error: TV-GDD step "), (
        result.stderr
    )
    assert "meets the hand-velocity equality (24)" in lines[1] and lines[2].startswith("the run is kept as failed in ")


@pytest.mark.integration
def test_ik_srs_json_lists_8_candidates_that_pybullet_confirms(humanoid):
    """Table I's analogue: every candidate of the JSON output reaches the pose in PyBullet, the
    valid ones are inside the limits, and all share the elbow magnitude |theta_4|."""
    import json

    import numpy as np

    from dualarm.model.poses import pose_matrix
    from dualarm.sim.world import load_pybullet_robot

    pose = [0.147, 0.404, 0.455, 0.937, 0.560, -0.377]
    result = runner.invoke(
        app,
        [
            "ik",
            "srs",
            str(HUMANOID),
            "--arm",
            "left",
            "--pose",
            *map(str, pose),
            "--arm-angle",
            "2.2",
            "--json",
            "--frame",
            "chain",
        ],
    )
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


# --- arguments checked before any work; messages printed as they are ------------------------------

SRS = ["ik", "srs", str(HUMANOID), "--arm", "left"]
POSE = ["--pose", "0.3", "0.2", "0.1", "0", "0", "0"]
TRIANGLE = str(TASKS / "triangle.toml")
BOWL = str(TASKS / "bowl_grasp.toml")


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        *[
            (command + ["--seed", "-1"], "--seed -1: a seed is an integer >= 0")
            for command in (
                ["run", TRIANGLE],
                ["plan", BOWL],
                ["consistency", TRIANGLE],
                ["bench", "ik"],
                ["bench", "plan"],
                ["robot", "check", str(HUMANOID)],
            )
        ],
        *[
            (
                [*SRS, "--pose", v, "0.2", "0.1", "0", "0", "0", "--arm-angle", "0"],
                f"--pose X {float(v)}: give a finite number in [-1000, 1000]",
            )
            for v in ("nan", "inf", "-inf")
        ],
        (
            [*SRS, "--pose", "0.3", "0.2", "0.1", "1e308", "0", "0", "--arm-angle", "0"],
            "--pose ROLL 1e+308: give a finite number in [-1000, 1000]",
        ),
        *[
            ([*SRS, *POSE, "--arm-angle", v], f"--arm-angle {float(v)}: give a finite number")
            for v in ("nan", "inf", "1e308")
        ],
        ([*SRS, *POSE, "--arm-angle", "0", "--vertical", "0", "0", "nan"], "--vertical nan: give a finite number"),
        ([*SRS, *POSE, "--arm-angle", "0", "--vertical", "0", "0", "0"], "--vertical must not be zero"),
        *[
            (["compare", "a", "b", "--tol", v], f"--tol {float(v)}: give a finite number >= 0")
            for v in ("inf", "nan", "-1")
        ],
        *[
            (
                ["run", TRIANGLE, "--ik", "tvgdd", "--lvi-tolerance", v],
                f"--lvi-tolerance {float(v)}: give a finite number in (0, 1]",
            )
            for v in ("inf", "nan", "0", "2")
        ],
        *[
            (["run", TRIANGLE, "--timeout", v], f"--timeout {float(v)}: give a finite number in (0, 86400]")
            for v in ("inf", "nan", "0", "-1")
        ],
        (["plan", BOWL, "--timeout", "inf"], "--timeout inf: give a finite number in (0, 86400]"),
        *[(["run", TRIANGLE, "--stages", v], f"--stages '{v}': names no stage") for v in ("", ",", " , ")],
        *[
            (command + [option, ""], f"{option} '': an empty path")
            for command, option in (
                (["run", TRIANGLE], "--out"),
                (["plan", BOWL], "--out"),
                (["plan", BOWL], "--recordings"),
                (["consistency", TRIANGLE], "--out"),
                (["reproduce"], "--out"),
                (["report", "r"], "--out"),
                (["compare", "a", "b"], "--csv"),
            )
        ],
        (["plan", BOWL, "--trials", "1000000"], "--trials 1000000: give a finite number in [1, 100000]"),
        (["bench", "ik", "--poses", "10000000"], "--poses 10000000: give a finite number in [1, 1e+06]"),
        (
            ["robot", "check", str(HUMANOID), "--samples", "10000000"],
            "--samples 10000000: give a finite number in [1, 1e+06]",
        ),
        (["bench", "tvgdd", "--repeats", "5000"], "--repeats 5000: give a finite number in [1, 1000]"),
        # Click's usage errors: one line, not four (usage, hint, blank, error)
        (["run", TRIANGLE, "--bogus"], "error: dualarm run: No such option: --bogus"),
        (["robot", "init"], "error: dualarm robot init: Missing argument 'urdf' (see 'dualarm robot init --help')"),
        (["run", TRIANGLE, "--reps", "abc"], "error: dualarm run: Invalid value for '--reps'"),
        (["nosuch"], "error: dualarm: No such command 'nosuch'"),
    ],
)
def test_arguments_outside_their_meaning_are_one_line_before_any_work(args, needle, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # nothing may be written, not even a default output directory
    result = runner.invoke(app, args)
    assert result.exit_code == 2, (result.output, result.exception)
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and needle in lines[0], result.stderr
    assert "Traceback" not in result.output and not list(tmp_path.iterdir())


@pytest.mark.integration
def test_a_seed_of_any_size_plans_and_is_recorded_exactly(tmp_path):
    """2**64 + 5 is past numpy's legacy range and OMPL's (its trials' seeds go on past it): the CSV, the summary and the
    run's manifest, read by the standard library, hold the exact integers."""
    import csv
    import json
    from pathlib import Path

    seed = 2**64 + 5
    result = runner.invoke(
        app,
        [
            "plan",
            BOWL,
            "--planner",
            "ompl-rrtconnect",
            "--trials",
            "2",
            "--seed",
            str(seed),
            "--out",
            str(tmp_path / "p"),
            "--recordings",
            str(tmp_path / "r"),
        ],
    )
    assert result.exit_code in (0, 3), (result.output, result.exception)
    with (tmp_path / "p" / "plan_trials.csv").open() as f:
        assert [int(row["seed"]) for row in csv.DictReader(f)] == [seed, seed + 1]
    summary = json.loads((tmp_path / "p" / "plan_summary.json").read_text())
    assert summary["seed"] == seed and summary["run_seed"] in (seed, seed + 1)
    assert json.loads((Path(summary["run"]) / "manifest.json").read_text())["seed"] == summary["run_seed"]


@pytest.mark.integration
def test_a_run_with_a_huge_seed_records_it(tmp_path):
    import json

    result = runner.invoke(app, ["run", TRIANGLE, "--seed", str(2**70), "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    (run,) = (tmp_path / "triangle").iterdir()
    assert json.loads((run / "manifest.json").read_text())["seed"] == 2**70


def test_messages_are_printed_as_they_are(tmp_path):
    """Rich would print ':robot:' as an emoji and eat '[bold]'; a message is the user's text."""
    name = "file:robot: :notes: [bold]x[/bold].toml"
    result = runner.invoke(app, ["run", str(tmp_path / name)])
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.exit_code == 2 and len(lines) == 1 and name in lines[0], result.stderr
    assert "🤖" not in result.stderr and "🎶" not in result.stderr


@pytest.mark.integration
def test_table_cells_are_printed_as_they_are(tmp_path):
    """A run directory named with emoji codes and markup keeps its name in compare's table."""
    import shutil

    from dualarm.run import record_run

    run = record_run(TASKS / "triangle.toml", stages=["path"], out_dir=tmp_path / "rec", command=["test"]).directory
    odd = tmp_path / ":robot:[red]"
    shutil.copytree(run, odd)
    result = runner.invoke(app, ["compare", str(run), str(odd)])
    assert result.exit_code == 0, result.output
    assert f"B = {odd}" in result.stdout and "🤖" not in result.stdout


def test_a_long_user_string_is_cut(tmp_path):
    """A 100 000-character stage name: one line of at most a few hundred characters."""
    from dualarm.cli.app import MAX_LINE

    result = runner.invoke(app, ["run", TRIANGLE, "--ik", "pinv", "--stages", "path," + "x" * 100_000])
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.exit_code == 2 and len(lines) == 1 and "unknown stage" in lines[0], result.stderr[:500]
    assert len(lines[0]) <= MAX_LINE + 10 and "..." in lines[0]


def test_a_message_with_a_newline_stays_one_line(tmp_path):
    result = runner.invoke(app, ["run", TRIANGLE, "--ik", "pinv", "--timing", "slow\nerror: forged\x1b[31m"])
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.exit_code == 2 and len(lines) == 1 and "slow\\nerror: forged\\x1b[31m" in lines[0], result.stderr


def test_help_is_printed_as_written_with_the_exit_codes():
    result = runner.invoke(app, ["run", "--help"])
    assert "Planning timeout [s]" in result.output
    root = " ".join(runner.invoke(app, ["--help"]).output.split())  # as wrapped to the terminal
    for text in (
        "0 complete",
        "3 violated",
        "1 failed",
        "2 user error",
        "130 interrupted (SIGINT)",
        "143 terminated (SIGTERM)",
    ):
        assert text in root
