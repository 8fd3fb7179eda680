"""The distribution: the package list matches the tree, and a wheel installed into a fresh virtual
environment (the ``wheel_env`` fixture) works from another directory: shipped robots and tasks are
package data."""

from __future__ import annotations

import json
import subprocess
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_every_package_of_the_tree_is_listed():
    config = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(config["packages"])
    tree = {
        "dualarm" + "".join(f".{part}" for part in d.relative_to(REPO / "pipeline").parts) for d in [REPO / "pipeline", *(REPO / "pipeline").rglob("*")] if d.is_dir() and (d / "__init__.py").is_file()
    }
    assert tree | {"dualarm.data.robots", "dualarm.data.tasks"} == listed
    assert config["package-dir"] == {"dualarm": "pipeline", "dualarm.data.robots": "robots", "dualarm.data.tasks": "tasks"}


def test_wheel_holds_the_data_and_the_stub(wheel_env: Path, tmp_path: Path):
    python = wheel_env / "bin" / "python"
    code = "import json, dualarm, dualarm.data as d; print(json.dumps([dualarm.__file__, str(d.robots_dir()), d.shipped_tasks(), d.shipped_robots(), len(dualarm.__all__)]))"
    done = subprocess.run([str(python), "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    module, robots, tasks, shipped_robots, exported = json.loads(done.stdout)
    assert Path(module).is_relative_to(wheel_env) and Path(robots).is_relative_to(wheel_env)
    assert tasks == ["ball_game", "bowl_grasp", "carry_box", "circle", "triangle"] and shipped_robots == sorted(p.name for p in (REPO / "robots").iterdir() if (p / "robot.toml").is_file())
    assert list(wheel_env.rglob("dualarm/__init__.pyi")) and exported > 50


def test_wheel_runs_the_cli_on_a_shipped_task_from_another_directory(wheel_env: Path, tmp_path: Path):
    """(tests/test_examples.py runs every example with the same wheel.)"""
    run = subprocess.run(
        [str(wheel_env / "bin" / "dualarm"), "run", "triangle", "--ik", "mc-inverse", "--stages", "path,ik", "--reps", "2", "--out", "out"], cwd=tmp_path, capture_output=True, text=True, timeout=600
    )
    assert run.returncode == 0, run.stderr
    directory = tmp_path / run.stdout.strip().splitlines()[-1]
    manifest = json.loads((directory / "manifest.json").read_text())
    assert manifest["status"] == "complete" and Path(manifest["task_file"]).is_relative_to(wheel_env)
    assert json.loads((directory / "metrics.json").read_text())["ik.rep_joint_deviation_max_rad"] < 1e-9
