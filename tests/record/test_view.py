"""``dualarm view``: a recorded run opened in Rerun's viewer (web: the real one, answering over HTTP), the Foxglove
instructions, and every refusal as one line.

The web viewer is Rerun's own command line, started by the command and fetched with urllib. The
native viewer needs a display, so its launch is checked with a stand-in ``rerun`` that keeps what
it is handed; the blueprint it is handed is read back by Rerun's own ``rerun rrd print``.
"""

import itertools
import os
import re
import signal
import subprocess
import sys
import urllib.error
import urllib.request
import uuid
from pathlib import Path

import pytest
from typer.testing import CliRunner

from dualarm.cli import app
from dualarm.run import record_run
from dualarm.tasks import load_task
from tests.helpers import HUMANOID, TASKS

runner = CliRunner()
BIN = Path(sys.executable).parent


@pytest.fixture(scope="module")
def ik_run(tmp_path_factory) -> Path:
    """The triangle through path, ik and retime, recorded with ``--record ik`` (its recordings hold path and ik)."""
    return record_run(
        load_task(TASKS / "triangle.toml", 1),
        "mc-inverse",
        stages=("path", "ik", "retime"),
        out_dir=tmp_path_factory.mktemp("view"),
        record="ik",
    ).directory


@pytest.fixture(scope="module")
def metrics_run(tmp_path_factory) -> Path:
    """The triangle's path stage, recorded with ``--record metrics``."""
    return record_run(
        TASKS / "triangle.toml", stages=("path",), out_dir=tmp_path_factory.mktemp("view_metrics"), record="metrics"
    ).directory


def _sigint_default() -> None:
    """In the child: Ctrl-C as in a terminal (a shell's background job inherits SIGINT ignored)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.mark.integration
def test_web_serves_rerun_s_viewer_until_ctrl_c(ik_run):
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}  # headless, as this machine
    process = subprocess.Popen(
        [str(BIN / "dualarm"), "view", str(ik_run), "--web"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        preexec_fn=_sigint_default,
    )
    try:
        lines = []
        while not lines or not lines[-1].startswith("Rerun web viewer:"):
            line = process.stdout.readline()
            assert line, (
                f"ended before printing a URL: {lines} {process.stderr.read() if process.poll() is not None else ''}"
            )
            lines.append(line.rstrip("\n"))
        url = re.search(r"http://127\.0\.0\.1:\d+/\S*", lines[-1]).group(0)
        with urllib.request.urlopen(url, timeout=60) as response:
            assert response.status == 200
            page = response.read().decode()
        assert "<!doctype html>" in page.lower() and "rerun" in page.lower()
        process.send_signal(signal.SIGINT)
        out, err = process.communicate(timeout=120)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 130
    assert err.splitlines() == ["interrupted (SIGINT)"]
    assert lines[:2] == [f"Foxglove (or Lichtblick): open {ik_run / 'run.mcap'}", lines[1]] and lines[1].startswith(
        "Foxglove layout: "
    )
    with pytest.raises(urllib.error.URLError):  # the viewer was stopped with the command
        urllib.request.urlopen(url, timeout=10)


@pytest.mark.integration
def test_the_web_viewer_dies_with_the_command_even_by_sigkill(ik_run):
    """``kill -9`` of ``view --web``: the Rerun server it started (one process, the viewer binary) is gone within 10 s
    and its URL stops answering (it kept serving, a wrapper and the binary, two orphans)."""
    import psutil

    process = subprocess.Popen(
        [str(BIN / "dualarm"), "view", str(ik_run), "--web"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    try:
        line = ""
        while not line.startswith("Rerun web viewer:"):
            line = process.stdout.readline()
            assert line, "ended before printing a URL"
        url = re.search(r"http://127\.0\.0\.1:\d+/\S*", line).group(0)
        viewers = psutil.Process(process.pid).children(recursive=True)
        assert viewers
        process.kill()
        process.wait(timeout=30)
        gone, alive = psutil.wait_procs(viewers, timeout=10)
        assert not alive, [p.cmdline() for p in alive]
        with pytest.raises(urllib.error.URLError):
            urllib.request.urlopen(url, timeout=10)
    finally:
        if process.poll() is None:
            process.kill()


def _one_line_error(args, needle: str) -> None:
    result = runner.invoke(app, ["view", *args])
    assert result.exit_code == 2, result.output
    assert len(result.output.strip().splitlines()) == 1 and result.output.startswith("error: "), result.output
    assert needle in result.output, result.output


def test_a_directory_that_is_not_a_run_is_one_line(tmp_path):
    _one_line_error([str(tmp_path)], "manifest.json")
    _one_line_error([str(tmp_path / "nothing")], "no such run directory")


@pytest.mark.integration
def test_a_metrics_run_has_nothing_to_view(metrics_run):
    _one_line_error([str(metrics_run), "--web"], "recorded with --record metrics: nothing to view")


@pytest.mark.integration
def test_an_unknown_stage_names_the_run_s_stages(ik_run):
    _one_line_error(
        [str(ik_run), "--web", "--stage", "bogus"], "--stage 'bogus': the run has no such stage (stages: path, ik)"
    )
    _one_line_error(
        [str(ik_run), "--web", "--stage", "retime"],
        "--stage 'retime': not in this run's recording (recorded with --record ik; stages: path, ik)",
    )


@pytest.mark.integration
def test_no_display_points_to_web(ik_run, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(sys, "platform", "linux")
    _one_line_error(
        [str(ik_run)],
        "no display for Rerun's native viewer (DISPLAY and WAYLAND_DISPLAY are unset): use dualarm view --web",
    )


@pytest.mark.integration
def test_no_viewer_executable_is_one_line(ik_run, tmp_path, monkeypatch):
    monkeypatch.setattr(sys, "executable", str(tmp_path / "bin" / "python"))
    monkeypatch.setenv("PATH", str(tmp_path))
    _one_line_error([str(ik_run), "--web"], "no Rerun viewer: no 'rerun' beside")


def _stand_in(tmp_path: Path, monkeypatch, exit_code: int = 0) -> Path:
    """A ``rerun`` beside a pretend Python that writes its arguments to ``kept/args`` and copies the files it is handed
    into ``kept/``; a display."""
    kept = tmp_path / "kept"
    kept.mkdir()
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    script = bin_dir / "rerun"
    script.write_text(
        f'#!/bin/sh\nprintf "%s\\n" "$@" > {kept}/args\nfor f in "$@"; do cp "$f" {kept}/; done\n'
        f'echo "something went wrong" >&2\nexit {exit_code}\n'
    )
    script.chmod(0o755)
    monkeypatch.setattr(sys, "executable", str(bin_dir / "python"))
    monkeypatch.setenv("DISPLAY", ":99")
    return kept


def _as_rerun_reads_it(rbl: Path) -> str:
    """``rerun rrd print -vvv`` of a blueprint file, without what differs between two writes of one blueprint (row,
    chunk and store ids, times, sizes, table widths)."""
    printed = subprocess.run(
        [str(BIN / "rerun"), "rrd", "print", "-vvv", str(rbl)], capture_output=True, text=True, check=True
    ).stdout
    printed = re.sub(r"\b(chunk|row|rec)_[0-9A-Za-z]+", r"\1_", printed)
    printed = re.sub(r"\d{4}-\d\d-\d\dT[\d:.]+", "T", printed)
    printed = re.sub(r"\(\d+(\.\d+)? [KMG]?i?B\)", "(size)", printed)
    return re.sub(r"[\s│┆─┌┐└┘├┤┬┴┼╞╡╪═╌┃━]+", " ", printed)


@pytest.mark.integration
def test_stage_hands_the_native_viewer_the_recording_and_a_blueprint_rerun_reads(ik_run, tmp_path, monkeypatch):
    """The viewer gets run.rrd and a .rbl that Rerun reads as a blueprint of app 'dualarm', the one focused on the stage
    asked for.

    Blueprint ids are random; they are drawn from one counter for each blueprint here, so that two
    writes of one blueprint print alike.
    """
    from dualarm.model.robot import load_robot
    from dualarm.record.rerun_sink import blueprint

    kept = _stand_in(tmp_path, monkeypatch)
    ids = itertools.count(1)
    monkeypatch.setattr(uuid, "uuid4", lambda: uuid.UUID(int=next(ids)))
    monkeypatch.chdir(ik_run.parent)
    result = runner.invoke(app, ["view", ik_run.name, "--stage", "ik"])
    assert result.exit_code == 0, result.output
    assert (
        result.output.splitlines()[0] == f"Foxglove (or Lichtblick): open {ik_run / 'run.mcap'}"
    )  # absolute, though given relative
    args = (kept / "args").read_text().splitlines()
    assert [Path(a).name for a in args] == ["run.rrd", "ik.rbl"] and Path(args[0]) == ik_run / "run.rrd"
    handed = _as_rerun_reads_it(kept / "ik.rbl")
    assert 'StoreId( Blueprint, "dualarm",' in handed
    expected = {}
    for focus in ("ik", "path"):
        ids = itertools.count(1)
        blueprint(load_robot(HUMANOID), ["path", "ik"], focus=focus).save("dualarm", tmp_path / f"{focus}.rbl")
        expected[focus] = _as_rerun_reads_it(tmp_path / f"{focus}.rbl")
    assert handed == expected["ik"]
    assert handed != expected["path"]


@pytest.mark.integration
def test_a_viewer_that_fails_is_one_line_naming_its_last_words(ik_run, tmp_path, monkeypatch):
    _stand_in(tmp_path, monkeypatch, exit_code=3)
    result = runner.invoke(app, ["view", str(ik_run)])
    assert result.exit_code == 2
    assert result.output.splitlines()[-1] == "error: Rerun's viewer stopped (exit code 3): something went wrong"
