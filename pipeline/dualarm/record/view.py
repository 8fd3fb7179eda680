"""Opening a recorded run in Rerun's viewer, native or web (``dualarm view``).

And saying how to open it in Foxglove.

The viewer is Rerun's own command line, ``rerun``, installed with rerun-sdk beside the Python
that runs dualarm (or found on ``PATH``); it runs as a child process in its own session and is
stopped (its whole process group) when the command ends, however it ends.

- Native: ``rerun RUN_DIR/run.rrd [STAGE.rbl]``, a window; needs a display.
- Web: ``rerun RUN_DIR/run.rrd [STAGE.rbl] --serve-web`` on 127.0.0.1, two free ports (gRPC and
  HTTP); no browser is opened. :func:`serve_web` yields the URL once the viewer answers on it.
- ``--stage STAGE``: a blueprint file (``.rbl``) focused on that stage, made by
  :func:`dualarm.record.rerun_sink.blueprint` from the robot the run's MCAP holds, beside the
  recording (the ``rerun`` command line takes ``.rbl`` files beside ``.rrd`` files).
"""

from __future__ import annotations

import contextlib
import functools
import importlib.util
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, TYPE_CHECKING
from urllib.parse import quote

from dualarm.errors import DualarmError, RecordingError, excerpt
from dualarm.record.readback import read_run
from dualarm.record.run_dir import FOXGLOVE_LAYOUT
from dualarm.record.verify import MCAP_FILE, RRD_FILE

if TYPE_CHECKING:
    from dualarm.model.robot import Robot

#: The Rerun application id of a run (its recording's and its blueprint's).
APP_ID = "dualarm"
#: How long the web viewer may take to answer on its port before it is given up [s].
START_TIMEOUT_S = 60.0
#: How long a stopped viewer may take to exit before it is killed [s].
STOP_TIMEOUT_S = 5.0
_ANSI = re.compile(r"\x1b\[[0-9;]*[A-Za-z]")


@dataclass(frozen=True)
class Viewable:
    """A recorded run, ready to be opened.

    Attributes:
        directory: the run directory (absolute).
        record: its recording level (``full`` or ``ik``).
        stages: the stages its recordings hold, in pipeline order.
        foxglove: the lines telling how to open its ``run.mcap`` in Foxglove, with absolute paths.
    """

    directory: Path
    record: str
    stages: tuple[str, ...]
    foxglove: tuple[str, ...]

    @property
    def rrd(self) -> Path:
        """The Rerun recording."""
        return self.directory / RRD_FILE

    @property
    def mcap(self) -> Path:
        """The MCAP recording."""
        return self.directory / MCAP_FILE


def viewable(run_dir: str | Path) -> Viewable:
    """The run in ``run_dir``, validated as :func:`~dualarm.record.readback.read_run` does.

    Raises:
        RecordingError: not a run (or a damaged one), or a run recorded with ``--record metrics``.
    """
    data = read_run(run_dir)
    directory = data.directory.absolute()
    if data.record == "metrics":
        raise RecordingError(
            f"{excerpt(directory)}: recorded with --record metrics: "
            "nothing to view (only manifest.json and metrics.json)"
        )
    layout = directory / FOXGLOVE_LAYOUT
    foxglove = [f"Foxglove (or Lichtblick): open {directory / MCAP_FILE}"]
    if layout.is_file():
        foxglove.append(f"Foxglove layout: import {layout} (Layouts > Import from file...)")
    else:
        foxglove.append(f"Foxglove layout: none in this run (no {FOXGLOVE_LAYOUT}: recorded by an earlier dualarm)")
    return Viewable(
        directory=directory, record=data.record, stages=tuple(data.recorded_stages), foxglove=tuple(foxglove)
    )


def check_stage(run: Viewable, stage: str) -> str:
    """``stage`` if ``run``'s recordings hold it.

    Raises:
        DualarmError: another stage, naming the ones the run holds (and its level when that left the stage out).
    """
    from dualarm.contracts.run import ALL_STAGES

    if stage in run.stages:
        return stage
    held = ", ".join(run.stages)
    if stage in ALL_STAGES and run.record != "full":
        raise DualarmError(
            f"--stage '{stage}': not in this run's recording (recorded with --record {run.record}; stages: {held})"
        )
    raise DualarmError(f"--stage '{excerpt(stage)}': the run has no such stage (stages: {held})")


def blueprint_file(run: Viewable, stage: str, directory: Path) -> Path:
    """Write the Rerun blueprint of ``run`` focused on ``stage`` to ``directory/<stage>.rbl``.

    Returns its path.

    The robot is the one the run's MCAP holds (its robot.toml and URDF attachments), so a run
    copied from another machine is shown as it was recorded.

    Raises:
        RecordingError: the MCAP holds no robot.toml or URDF.
    """
    from dualarm.record.rerun_sink import blueprint

    path = directory / f"{stage}.rbl"
    blueprint(_recorded_robot(run.mcap, directory / "robot"), run.stages, focus=stage).save(APP_ID, path)
    return path


def _recorded_robot(mcap: Path, directory: Path) -> Robot:
    """The robot whose robot.toml and URDF ``mcap`` holds as attachments, unpacked into ``directory``."""
    from mcap.reader import make_reader

    from dualarm.model.robot import load_robot

    with mcap.open("rb") as stream:
        attachments = {a.name: a.data for a in make_reader(stream).iter_attachments()}
    if "robot.toml" not in attachments or not any(name.endswith(".urdf") for name in attachments):
        raise RecordingError(f"{excerpt(mcap)}: holds no robot.toml and URDF, which --stage needs")
    directory.mkdir()
    for name, data in attachments.items():
        if name == "robot.toml" or name.endswith(".urdf"):
            (directory / Path(name).name).write_bytes(data)
    return load_robot(directory)


def rerun_executable() -> Path:
    """Rerun's command line: ``rerun`` beside the running Python (from rerun-sdk), else on ``PATH``.

    Where that is rerun-sdk's script, which runs the viewer binary in a process of its own, the binary itself
    (:func:`_binary`): the viewer is then one process, which :func:`_viewer` can tie to this one's life.

    Raises:
        DualarmError: neither exists.
    """
    beside = Path(sys.executable).parent / "rerun"
    if beside.is_file() and os.access(beside, os.X_OK):
        return _binary(beside)
    found = shutil.which("rerun")
    if found is None:
        raise DualarmError(
            f"no Rerun viewer: no 'rerun' beside {excerpt(sys.executable)} "
            "nor on PATH (it comes with rerun-sdk: pip install rerun-sdk)"
        )
    return _binary(Path(found))


def _binary(script: Path) -> Path:
    """The viewer binary rerun-sdk's ``script`` runs (``rerun_cli/rerun``); else ``script`` itself."""
    with contextlib.suppress(OSError):
        with script.open("rb") as head:
            if b"from rerun_cli" in head.read(4096):
                spec = importlib.util.find_spec("rerun_cli")
                binary = Path(spec.origin).parent / "rerun" if spec is not None and spec.origin else script
                if binary.is_file() and os.access(binary, os.X_OK):
                    return binary
    return script


def has_display() -> bool:
    """Whether a native window can open.

    Always on macOS and Windows; on Linux and other systems, when ``DISPLAY`` or ``WAYLAND_DISPLAY``
    is set.
    """
    if sys.platform == "darwin" or sys.platform.startswith("win"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def web_url(web_port: int, grpc_port: int) -> str:
    """The address of Rerun's web viewer on ``web_port``, connecting to its gRPC server on ``grpc_port``.

    Both on 127.0.0.1.
    """
    return f"http://127.0.0.1:{web_port}/?url=" + quote(f"rerun+http://127.0.0.1:{grpc_port}/proxy", safe="")


def _free_ports(count: int) -> list[int]:
    """``count`` distinct TCP ports free on 127.0.0.1 now (the system's choice)."""
    with contextlib.ExitStack() as stack:
        sockets = [stack.enter_context(socket.socket(socket.AF_INET, socket.SOCK_STREAM)) for _ in range(count)]
        for s in sockets:
            s.bind(("127.0.0.1", 0))
        return [s.getsockname()[1] for s in sockets]


def _last_line(log: IO[bytes]) -> str:
    """The last non-empty line a viewer wrote to ``log``, without colours."""
    log.flush()
    log.seek(0)
    lines = [line for line in _ANSI.sub("", log.read().decode("utf-8", errors="replace")).splitlines() if line.strip()]
    return lines[-1].strip() if lines else "(it printed nothing)"


@contextlib.contextmanager
def _viewer(executable: Path, arguments: Sequence[str]) -> Iterator[tuple[subprocess.Popen, IO[bytes]]]:
    """Rerun's command line ``executable`` with ``arguments``, in its own session.

    Its output kept in a temporary file; its process group is stopped when the block ends, and on Linux the viewer is
    sent SIGTERM when this process dies (``PR_SET_PDEATHSIG``), even by SIGKILL: no server outlives the command.
    """
    with tempfile.TemporaryFile() as log:
        process = subprocess.Popen(
            [str(executable), *arguments],
            stdin=subprocess.DEVNULL,
            stdout=log,
            stderr=log,
            start_new_session=True,
            env={**os.environ, "NO_COLOR": "1"},
            preexec_fn=_dies_with_parent(),
        )
        try:
            yield process, log
        finally:
            _stop(process)


def _dies_with_parent() -> Callable[[], object] | None:
    """What a child runs between fork and exec to be sent SIGTERM when its parent dies; None but on Linux.

    Linux's ``prctl(PR_SET_PDEATHSIG)``, looked up here, before the fork: the child only calls it.
    """
    if sys.platform != "linux":
        return None
    import ctypes

    pr_set_pdeathsig = 1
    return functools.partial(ctypes.CDLL(None).prctl, pr_set_pdeathsig, int(signal.SIGTERM), 0, 0, 0)


def _stop(process: subprocess.Popen) -> None:
    """Stop ``process`` and every process of its group.

    Rerun's wrapper script and the viewer it runs: SIGTERM, then SIGKILL to what is left after
    :data:`STOP_TIMEOUT_S`.
    """
    for signum in (signal.SIGTERM, signal.SIGKILL):
        try:
            os.killpg(process.pid, signum)
        except ProcessLookupError:  # the whole group has exited
            break
        deadline = time.monotonic() + STOP_TIMEOUT_S
        while _group_alive(process) and time.monotonic() < deadline:
            time.sleep(0.05)
        if not _group_alive(process):
            break
    process.wait()


def _group_alive(process: subprocess.Popen) -> bool:
    """Whether a process of ``process``'s group is still running (``process`` itself reaped once it exits)."""
    process.poll()
    try:
        os.killpg(process.pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _failed(process: subprocess.Popen, log: IO[bytes], what: str) -> DualarmError:
    return DualarmError(f"{what} stopped (exit code {process.returncode}): {excerpt(_last_line(log), 200)}")


def check_display() -> None:
    """Refuse to open a native window without a display.

    Raises:
        DualarmError: no display (:func:`has_display`), pointing to ``--web``.
    """
    if not has_display():
        raise DualarmError(
            "no display for Rerun's native viewer (DISPLAY and WAYLAND_DISPLAY are unset): use dualarm view --web"
        )


def open_native(executable: Path, files: Sequence[Path]) -> None:
    """Open ``files`` in Rerun's native viewer and wait until its window is closed.

    ``files``: a ``.rrd``, and ``.rbl`` blueprints; the viewer: the command line ``executable``.

    Raises:
        DualarmError: no display, or the viewer stopped with an error.
    """
    check_display()
    with _viewer(executable, [str(f) for f in files]) as (process, log):
        if process.wait() != 0:
            raise _failed(process, log, "Rerun's viewer")


@contextlib.contextmanager
def serve_web(executable: Path, files: Sequence[Path]) -> Iterator[tuple[str, subprocess.Popen]]:
    """Serve ``files`` with Rerun's web viewer on 127.0.0.1; yields its URL, once it answers there.

    ``files``: a ``.rrd``, and ``.rbl`` blueprints; the viewer: the command line ``executable``.
    Also yields the server's process (stopped when the block ends).

    Raises:
        DualarmError: the viewer stopped, or did not answer within :data:`START_TIMEOUT_S`.
    """
    grpc_port, web_port = _free_ports(2)
    arguments = [
        *(str(f) for f in files),
        "--serve-web",
        "--bind",
        "127.0.0.1",
        "--port",
        str(grpc_port),
        "--web-viewer-port",
        str(web_port),
    ]
    with _viewer(executable, arguments) as (process, log):
        deadline = time.monotonic() + START_TIMEOUT_S
        while not all(_answers(port) for port in (grpc_port, web_port)):
            if process.poll() is not None:
                raise _failed(process, log, "Rerun's web viewer")
            if time.monotonic() > deadline:
                raise DualarmError(
                    f"Rerun's web viewer did not answer on port {web_port} within "
                    f"{START_TIMEOUT_S:g} s: {excerpt(_last_line(log), 200)}"
                )
            time.sleep(0.05)
        yield web_url(web_port, grpc_port), process
        if process.poll() not in (None, 0):
            raise _failed(process, log, "Rerun's web viewer")


def _answers(port: int) -> bool:
    """Whether something accepts TCP connections on 127.0.0.1:``port``."""
    with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), timeout=1.0):
        return True
    return False
