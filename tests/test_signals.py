"""Ctrl-C (SIGINT) and SIGTERM on real ``dualarm`` processes: one line, exit 130 or 143, the run kept as failed, nothing
hidden left, workers stopped and reaped.

Each process is stopped (SIGSTOP) as soon as the state to interrupt is on disk, signalled, then
continued (SIGCONT): the signal lands there whatever the machine's speed.
"""

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

CLI = [sys.executable, "-c", "import sys; sys.argv[0] = 'dualarm'; from dualarm.cli import app; app()"]
#: Longest wait for a process to reach the state the test interrupts [s] (a bound against hanging, not a measurement).
PATIENCE_S = 300


def _default_sigint() -> None:
    """In the child before exec: SIGINT as a terminal's foreground job has it (a shell may start background jobs with it
    ignored)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _wait_for(condition, process: subprocess.Popen) -> None:
    deadline = time.monotonic() + PATIENCE_S
    while not condition():
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline, "the state to interrupt never came"
        time.sleep(0.01)


def _stagings(recordings: Path) -> list[Path]:
    """The run directories being written in ``recordings`` (``<task>/.<run-id>.partial``)."""
    return [p for p in recordings.glob("*/.*.partial") if p.is_dir()]


def _partials(directory: Path) -> list[Path]:
    """Anything under ``directory`` left half-written: a run's staging, a file's ``.<name>.partial``."""
    return list(directory.rglob("*.partial"))


def _error_lines(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if line.strip()]


@pytest.mark.integration
@pytest.mark.parametrize(
    ("signum", "code", "line", "error"),
    [
        (signal.SIGINT, 130, "interrupted (SIGINT)", "KeyboardInterrupt"),
        (signal.SIGTERM, 143, "terminated (SIGTERM)", "Terminated: SIGTERM"),
    ],
)
def test_a_signalled_run_is_kept_as_failed(tmp_path, signum, code, line, error):
    out = tmp_path / "out"
    process = subprocess.Popen(
        [*CLI, "run", "triangle", "--ik", "mc-inverse", "--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=_default_sigint,
    )
    _wait_for(lambda: bool(_stagings(out)), process)
    process.send_signal(signal.SIGSTOP)
    assert _stagings(out), "the run ended before it could be interrupted"
    process.send_signal(signum)
    process.send_signal(signal.SIGCONT)
    stdout, stderr = process.communicate(timeout=PATIENCE_S)

    assert process.returncode == code, stderr
    assert _error_lines(stderr) == [line] and "Traceback" not in stderr + stdout, stderr
    (run,) = (out / "triangle").iterdir()
    manifest = json.loads((run / "manifest.json").read_text())
    assert manifest["status"] == "failed" and manifest["error"].startswith(error) and manifest["run_id"] == run.name
    assert not (run / "metrics.json").exists()
    assert not _partials(out)


def _workers(pid: int) -> dict[int, str]:
    """The reproduction's worker processes (spawned children of ``pid``, by any of its threads: Dask's nannies start
    them from its event loop's): pid -> its start time, which tells a pid's later owner apart."""
    found = {}
    for child in " ".join(p.read_text() for p in Path(f"/proc/{pid}/task").glob("*/children")).split():
        cmdline = Path(f"/proc/{child}/cmdline").read_bytes()
        if b"multiprocessing.spawn" in cmdline:
            found[int(child)] = Path(f"/proc/{child}/stat").read_text().rsplit(")", 1)[1].split()[19]
    return found


def _alive(pid: int, started: str) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[19] == started
    except FileNotFoundError:
        return False


@pytest.mark.integration
@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="finds the workers in /proc (Linux)")
@pytest.mark.parametrize(
    ("signum", "group", "code", "line"),
    [(signal.SIGINT, True, 130, "interrupted (SIGINT)"), (signal.SIGTERM, False, 143, "terminated (SIGTERM)")],
)
def test_an_interrupted_reproduction_stops_its_workers(tmp_path, signum, group, code, line):
    """Ctrl-C reaches the whole process group (as from a terminal); SIGTERM the main process alone."""
    out = tmp_path / "repro"
    process = subprocess.Popen(
        [*CLI, "reproduce", "--only", "ball-game-tvgdd,ball-game-pinv", "--jobs", "2", "--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        preexec_fn=_default_sigint,
    )
    try:
        _wait_for(lambda: bool(_stagings(out / "runs")), process)
        os.killpg(process.pid, signal.SIGSTOP)
        workers = _workers(process.pid)
        assert len(workers) == 2 and _stagings(out / "runs")
        if group:
            os.killpg(process.pid, signum)
        else:
            process.send_signal(signum)
        os.killpg(process.pid, signal.SIGCONT)
        stdout, stderr = process.communicate(timeout=PATIENCE_S)
    finally:  # a failed assertion must not leave the stopped group behind
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.communicate()

    assert process.returncode == code, stderr
    assert _error_lines(stderr) == [line] and "Traceback" not in stderr + stdout, stderr
    assert not [pid for pid, started in workers.items() if _alive(pid, started)]
    assert not _partials(out)
    runs = list((out / "runs" / "ball_game").iterdir())
    assert runs and all(json.loads((run / "manifest.json").read_text())["status"] == "failed" for run in runs)


def test_a_signal_while_the_rerun_stream_is_built_is_raised_after_it():
    """The signal arrives inside the block (as it did inside ``rr.RecordingStream()``): the block completes, then the
    handler raises."""
    from dualarm.interrupt import held

    def handler(signum, frame):
        raise RuntimeError(signum)

    previous = signal.signal(signal.SIGTERM, handler)
    finished = []
    try:
        with pytest.raises(RuntimeError, match=str(int(signal.SIGTERM))):
            with held():
                signal.raise_signal(signal.SIGTERM)
                finished.append(True)
        assert finished == [True] and signal.getsignal(signal.SIGTERM) is handler
    finally:
        signal.signal(signal.SIGTERM, previous)


def test_an_ignored_signal_stays_ignored_in_a_held_block():
    """A command started in the background ignores SIGINT: inside held() it is neither held (a reproduction's loop
    watching the list ended on it, its parts unfinished, and a KeyError's traceback followed) nor raised after."""
    from dualarm.interrupt import held

    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with held() as signals:
            signal.raise_signal(signal.SIGINT)
            assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
        assert signals == [] and signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, previous)


def _in_thread(target) -> list:
    """Run ``target`` in a thread; returns what it appends (and an exception's type name when it raises), and the
    thread."""
    seen: list = []

    def run():
        try:
            target(seen)
        except BaseException as exc:
            seen.append(type(exc).__name__)

    thread = threading.Thread(target=run)
    thread.start()
    return seen, thread


def test_a_stop_raises_terminated_in_the_thread_running_the_work_and_waits_for_a_held_block():
    """dualarm.interrupt: stop(token) raises Terminated in the thread inside stoppable(token) (and in no other work), at
    once outside held() and at the block's end inside it; work started under a stopped token stops at once."""
    from dualarm.interrupt import held, stop, stoppable

    events = {name: threading.Event() for name in ("busy", "holding", "release")}

    def busy(seen):
        with stoppable("busy"):
            events["busy"].set()
            while True:
                time.sleep(0.001)

    def holding(seen):
        with stoppable("holding"):
            with held():
                events["holding"].set()
                events["release"].wait(60)
                seen.append("block ended")
            seen.append("after the block")

    busy_seen, busy_thread = _in_thread(busy)
    held_seen, held_thread = _in_thread(holding)
    assert events["busy"].wait(60) and events["holding"].wait(60)
    assert stop(["busy"]) == 1
    busy_thread.join(60)
    assert busy_seen == ["Terminated"] and not busy_thread.is_alive()
    assert stop(["holding"]) == 1 and held_thread.is_alive()
    events["release"].set()
    held_thread.join(60)
    assert held_seen == ["block ended", "Terminated"]
    late_seen, late_thread = _in_thread(busy)
    late_thread.join(60)
    assert late_seen == ["Terminated"] and stop(["busy"]) == 0
