"""No command deletes or overwrites a file it did not write.

A user's files are planted in the output of every command that writes (run, plan, consistency,
reproduce, report, compare --csv) and must survive byte for byte; a path the system refuses is one
line naming it and the cause; a second reproduction into a directory in use is refused while the
first goes on (two real processes).
"""

import errno
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

from dualarm.cli import app
from dualarm.cli.runs import COMPARE_HEADER
from dualarm.run import record_run
from tests.helpers import TASKS

runner = CliRunner()


def tree(directory: Path) -> dict[str, bytes | None]:
    """Every entry under ``directory``: a file's bytes, None for a directory."""
    return {
        str(p.relative_to(directory)): (p.read_bytes() if p.is_file() else None) for p in sorted(directory.rglob("*"))
    }


def plant(directory: Path) -> dict[str, bytes | None]:
    """The user's files of issue 16 in ``directory``: report.md (their notes), precious.txt and sub/data.csv; returns
    the tree."""
    (directory / "sub").mkdir(parents=True, exist_ok=True)
    (directory / "report.md").write_bytes(b"# my notes\n")
    (directory / "precious.txt").write_bytes(b"keep me\n")
    (directory / "sub" / "data.csv").write_bytes(b"a,b\n1,2\n")
    return tree(directory)


def one_error_line(result) -> str:
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.exit_code == 2, (result.exit_code, result.output, result.exception)
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    assert "Traceback" not in result.output and not isinstance(
        result.exception, (AssertionError, OSError, TypeError, ValueError)
    )
    return lines[0]


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Path:
    """A recorded run of the triangle's path."""
    return record_run(
        TASKS / "triangle.toml", stages=["path"], out_dir=tmp_path_factory.mktemp("runs"), command=["test"]
    ).directory


#: Each command that writes, with its output path as ``{out}`` (``{run}``: a recorded run).
WRITERS = {
    "plan": ["plan", str(TASKS / "bowl_grasp.toml"), "--trials", "1", "--out", "{out}", "--recordings", "{rec}"],
    "consistency": ["consistency", str(TASKS / "triangle.toml"), "--methods", "mc-inverse", "--out", "{out}"],
    "reproduce": ["reproduce", "--only", "table-i", "--jobs", "1", "--out", "{out}"],
    "report": ["report", "{run}", "--out", "{out}"],
    "report of two runs": ["report", "{run}", "{run}", "--out", "{out}"],
}


def _args(command: str, out: Path | str, run: Path, tmp_path: Path) -> list[str]:
    return [a.format(out=out, run=run, rec=tmp_path / "rec") for a in WRITERS[command]]


@pytest.mark.integration
@pytest.mark.parametrize("command", list(WRITERS))
def test_a_users_directory_is_refused_and_survives(command, run, tmp_path):
    mine = tmp_path / "mine"
    before = plant(mine)
    line = one_error_line(runner.invoke(app, _args(command, mine, run, tmp_path)))
    assert (
        str(mine) in line
        and "not a" in line
        and any(f"'{name}'" in line for name in ("report.md", "precious.txt", "sub"))
    )
    assert tree(mine) == before
    assert not (tmp_path / "rec").exists()  # refused before any work


@pytest.mark.parametrize(
    ("where", "named"), [("figures/mine.txt", "figures/mine.txt"), ("runs/triangle/notes.txt", "runs")]
)  # table-i writes no runs/: the planted one is foreign whole
def test_a_file_planted_inside_an_earlier_reproduction_stops_the_next_one(where, named, tmp_path):
    out = tmp_path / "repro"
    assert runner.invoke(app, ["reproduce", "--only", "table-i", "--jobs", "1", "--out", str(out)]).exit_code == 0
    (out / where).parent.mkdir(parents=True, exist_ok=True)
    (out / where).write_bytes(b"mine\n")
    before = tree(out)
    line = one_error_line(runner.invoke(app, ["reproduce", "--only", "table-i", "--jobs", "1", "--out", str(out)]))
    assert f"holds '{named}'" in line
    assert tree(out) == before


def test_a_reproduction_replaces_its_own_outputs(tmp_path):
    out = tmp_path / "repro"
    for _ in range(2):
        result = runner.invoke(app, ["reproduce", "--only", "table-i", "--jobs", "1", "--out", str(out)])
        assert result.exit_code == 0, result.output
    assert json.loads((out / "parts.json").read_text())["parts"][0]["name"] == "table-i"


@pytest.mark.integration
@pytest.mark.parametrize(
    ("args", "written"),
    [
        (["report", "{run}", "--out", "{out}"], "summary.md"),
        (["report", "{run}", "{run}", "--out", "{out}"], "runs.csv"),
        (
            ["consistency", str(TASKS / "triangle.toml"), "--methods", "mc-inverse", "--reps", "1", "--out", "{out}"],
            "consistency.csv",
        ),
    ],
)
def test_a_command_writes_again_into_its_own_directory(args, written, run, tmp_path):
    """Every entry a command writes is one the next command into the directory accepts as its own."""
    for _ in range(2):
        result = runner.invoke(app, [a.format(run=run, out=tmp_path / "o") for a in args])
        assert result.exit_code in (0, 3), (result.output, result.exception)
    assert (tmp_path / "o" / written).is_file()


@pytest.mark.integration
def test_a_run_adds_itself_beside_a_users_files(tmp_path):
    """A recordings directory only gains runs: the user's files, even inside the task's directory, stay as they were."""
    before = plant(tmp_path / "rec")
    (tmp_path / "rec" / "triangle").mkdir()
    (tmp_path / "rec" / "triangle" / "notes.txt").write_bytes(b"mine\n")
    before = tree(tmp_path / "rec")
    result = runner.invoke(app, ["run", str(TASKS / "triangle.toml"), "--out", str(tmp_path / "rec")])
    assert result.exit_code == 0, result.output
    after = tree(tmp_path / "rec")
    assert {k: v for k, v in after.items() if k in before} == before
    (added,) = {k.split("/")[1] for k in set(after) - set(before)}
    assert json.loads((tmp_path / "rec" / "triangle" / added / "manifest.json").read_text())["status"] == "complete"


@pytest.mark.integration
def test_plan_records_beside_a_users_files(tmp_path):
    before = plant(tmp_path / "rec")
    result = runner.invoke(
        app,
        [
            "plan",
            str(TASKS / "bowl_grasp.toml"),
            "--trials",
            "1",
            "--out",
            str(tmp_path / "plan"),
            "--recordings",
            str(tmp_path / "rec"),
        ],
    )
    assert result.exit_code in (0, 3), result.output
    after = tree(tmp_path / "rec")
    assert {k: v for k, v in after.items() if k in before} == before and (tmp_path / "rec" / "bowl_grasp").is_dir()


@pytest.mark.integration
def test_compare_csv_never_overwrites_a_users_file(run, tmp_path):
    mine = tmp_path / "mine.csv"
    mine.write_bytes(b"name,value\nx,1\n")
    line = one_error_line(runner.invoke(app, ["compare", str(run), str(run), "--csv", str(mine)]))
    assert str(mine) in line and "not a table dualarm compare wrote" in line
    assert mine.read_bytes() == b"name,value\nx,1\n"


@pytest.mark.integration
def test_compare_csv_writes_a_new_file_and_replaces_its_own(run, tmp_path):
    table = tmp_path / "deep" / "compare.csv"
    for _ in range(2):  # new, then an earlier compare's table
        result = runner.invoke(app, ["compare", str(run), str(run), "--csv", str(table)])
        assert result.exit_code == 0, result.output
        read = pd.read_csv(table)
        assert table.read_text().startswith(COMPARE_HEADER) and len(read) > 0 and (read["max_difference"] == 0).all()
    assert [p.name for p in table.parent.iterdir()] == ["compare.csv"]


def _refused_paths(tmp_path: Path) -> dict[str, tuple[str, str]]:
    """case -> (an output path, the cause its message must give)."""
    a_file = tmp_path / "a_file"
    a_file.write_bytes(b"x")
    return {
        "a regular file": (str(a_file), "exists and is not a directory"),
        "through a file": (str(a_file / "out"), os.strerror(errno.ENOTDIR)),
        "too long": (str(tmp_path / ("x" * 300)), os.strerror(errno.ENAMETOOLONG)),
        "empty": ("", "an empty path"),
    }


@pytest.mark.integration
@pytest.mark.parametrize("case", ["a regular file", "through a file", "too long", "empty"])
@pytest.mark.parametrize("command", ["run", *WRITERS, "plan --recordings", "compare --csv"])
def test_a_path_the_system_refuses_is_one_line(command, case, run, tmp_path):
    path, cause = _refused_paths(tmp_path)[case]
    if command == "run":
        args = ["run", str(TASKS / "triangle.toml"), "--out", path]
    elif command == "plan --recordings":
        args = [
            "plan",
            str(TASKS / "bowl_grasp.toml"),
            "--trials",
            "1",
            "--out",
            str(tmp_path / "p"),
            "--recordings",
            path,
        ]
    elif command == "compare --csv":
        args = ["compare", str(run), str(run), "--csv", path]
        cause = {"a regular file": "not a table dualarm compare wrote"}.get(case, cause)
    else:
        args = _args(command, path, run, tmp_path)
    before = tree(tmp_path)
    line = one_error_line(runner.invoke(app, args))
    assert cause in line, line
    if case in ("a regular file", "through a file"):
        assert path in line
    assert len(line) < 300
    assert (
        tree(tmp_path) == before or command == "plan --recordings"
    )  # plan made its own --out first, empty but for its marker


@pytest.mark.integration
def test_a_second_reproduction_into_a_directory_in_use_is_refused(tmp_path):
    """Two real processes: the first holds its lock (its part paused until the test lets it go on); the second exits 2;
    the first then finishes with its outputs intact."""
    out, held, release = tmp_path / "repro", tmp_path / "held", tmp_path / "release"
    first_code = f"""
import dataclasses, pathlib, sys, time
from dualarm.reproduce import experiments
part = experiments.BY_NAME["table-i"]
def paused(out, robot, progress):
    outputs = part.run(out, robot, progress)
    pathlib.Path({str(held)!r}).touch()
    while not pathlib.Path({str(release)!r}).exists():
        time.sleep(0.05)
    return outputs
experiments.BY_NAME["table-i"] = dataclasses.replace(part, run=paused)
sys.argv = ["dualarm", "reproduce", "--only", "table-i", "--jobs", "1", "--out", {str(out)!r}]
from dualarm.cli import app
app()
"""
    first = subprocess.Popen(
        [sys.executable, "-c", first_code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        deadline = time.monotonic() + 300
        while not held.exists():
            assert first.poll() is None and time.monotonic() < deadline, first.communicate()
            time.sleep(0.05)
        before = tree(out)
        assert "table_i.json" in before
        second = subprocess.run(
            [
                sys.executable,
                "-c",
                "from dualarm.cli import app; app()",
                "reproduce",
                "--only",
                "table-i",
                "--jobs",
                "1",
                "--out",
                str(out),
            ],
            capture_output=True,
            text=True,
            timeout=300,
        )
        lines = [line for line in second.stderr.splitlines() if line.strip()]
        assert (
            second.returncode == 2
            and len(lines) == 1
            and "in use by another dualarm process" in lines[0]
            and str(out) in lines[0]
        ), second.stderr
        assert tree(out) == before
    finally:
        release.touch()
        stdout, stderr = first.communicate(timeout=300)
    assert first.returncode == 0, stderr
    assert stdout.splitlines()[-1] == str(out / "report.md")
    assert (out / "table_i.json").read_bytes() == before["table_i.json"]
    assert [p["status"] for p in json.loads((out / "parts.json").read_text())["parts"]] == ["complete"]


@pytest.mark.integration
def test_the_next_run_removes_the_staging_directories_of_killed_runs_only(tmp_path):
    """A run killed by SIGKILL leaves its hidden staging directory; the next run into the recordings directory
    removes it (once STALE_STAGING_S old), and leaves the staging directory of a run still being written (its writer
    holds it, though as old) and a fresh one (between a writer's mkdir and its lock)."""
    from dualarm.record.run_dir import STALE_STAGING_S, RunDirectory

    writer = (
        "import os, signal, sys, time\n"
        "from pathlib import Path\n"
        "from dualarm.record.run_dir import RunDirectory\n"
        f"run = RunDirectory.create(Path({str(tmp_path)!r}), sys.argv[1], {{}})\n"
        "(run.staging / 'run.mcap').write_bytes(b'half')\n"
        "print(run.staging, flush=True)\n"
        "os.kill(os.getpid(), signal.SIGKILL) if sys.argv[1] == 'killed' else time.sleep(60)\n"
    )
    killed = subprocess.run([sys.executable, "-c", writer, "killed"], capture_output=True, text=True, timeout=60)
    assert killed.returncode == -9
    running = subprocess.Popen([sys.executable, "-c", writer, "running"], stdout=subprocess.PIPE, text=True)
    try:
        stale, live = Path(killed.stdout.strip()), Path(running.stdout.readline().strip())
        fresh = live.parent.parent / "fresh" / live.name
        fresh.mkdir(parents=True)
        old = time.time() - 2 * STALE_STAGING_S
        for staging in (stale, live):
            os.utime(staging, (old, old))
        assert stale.is_dir() and stale.name.endswith(".partial")
        run = RunDirectory.create(tmp_path, "next", {})
        assert not stale.exists() and live.is_dir() and fresh.is_dir()
        assert (live / "run.mcap").read_bytes() == b"half"
        assert run.finish(None).is_dir()
    finally:
        running.kill()
        running.wait()
