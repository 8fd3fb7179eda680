"""The distribution: an editable install is a plain path, and a wheel installed into a fresh virtual
environment (the ``wheel_env`` fixture) works from another directory: shipped robots and tasks are
package data."""

from __future__ import annotations

import json
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[1]


def test_an_editable_install_is_a_plain_path_that_mypy_follows(tmp_path: Path):
    """The folder is the import name: the editable install adds ``pipeline/`` to the path (no import
    hook), so mypy run on a user's script outside the repository finds ``dualarm`` by itself and reports
    a wrong argument type to :func:`dualarm.solve_tvgdd`."""
    site = Path(sysconfig.get_paths()["purelib"])
    assert not list(site.glob("__editable__*dualarm*")), "an import-hook finder, not a plain path"
    assert (REPO / "pipeline") in {
        Path(line.strip()) for pth in site.glob("*.pth") for line in pth.read_text().splitlines()
    }
    script = tmp_path / "user_script.py"
    script.write_text(
        "import dualarm\n\nrobot = dualarm.load_robot('humanoid')\ndualarm.solve_tvgdd(robot, 'not a reference')\n"
    )
    done = subprocess.run(
        [sys.executable, "-m", "mypy", "--no-incremental", "--follow-imports=silent", str(script)],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 1, done.stdout + done.stderr
    assert 'Argument 2 to "solve_tvgdd" has incompatible type "str"; expected "CartesianReference"' in done.stdout, (
        done.stdout
    )


def test_wheel_holds_the_data_and_the_stub(wheel_env: Path, tmp_path: Path):
    python = wheel_env / "bin" / "python"
    code = (
        "import json, dualarm, dualarm.data as d; print(json.dumps([dualarm.__file__, str(d.robots_dir()),"
        " d.shipped_tasks(), d.shipped_robots(), len(dualarm.__all__)]))"
    )
    done = subprocess.run([str(python), "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    module, robots, tasks, shipped_robots, exported = json.loads(done.stdout)
    assert Path(module).is_relative_to(wheel_env) and Path(robots).is_relative_to(wheel_env)
    assert tasks == ["ball_game", "bowl_grasp", "carry_box", "circle", "triangle"] and shipped_robots == sorted(
        p.name for p in (REPO / "robots").iterdir() if (p / "robot.toml").is_file()
    )
    assert list(wheel_env.rglob("dualarm/__init__.pyi")) and exported > 50


def test_wheel_runs_the_cli_on_a_shipped_task_from_another_directory(wheel_env: Path, tmp_path: Path):
    """(tests/test_examples.py runs every example with the same wheel.)"""
    run = subprocess.run(
        [
            str(wheel_env / "bin" / "dualarm"),
            "run",
            "triangle",
            "--ik",
            "mc-inverse",
            "--stages",
            "path,ik",
            "--reps",
            "2",
            "--out",
            "out",
        ],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert run.returncode == 0, run.stderr
    directory = tmp_path / run.stdout.strip().splitlines()[-1]
    manifest = json.loads((directory / "manifest.json").read_text())
    assert manifest["status"] == "complete" and Path(manifest["task_file"]).is_relative_to(wheel_env)
    assert json.loads((directory / "metrics.json").read_text())["ik.rep_joint_deviation_max_rad"] < 1e-9
