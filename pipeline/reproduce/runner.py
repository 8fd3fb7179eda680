"""Running the parts of a reproduction, ``jobs`` at a time, into one output directory.

The directory gets each part's files (see :mod:`dualarm.reproduce.experiments`) and
``parts.json``: every part's status, error, time and outputs. The report is written from those
files afterwards (:mod:`dualarm.reproduce.report`). The directory is claimed as a reproduction's
(:func:`dualarm.record.run_dir.claim_output_dir`): one that holds an earlier reproduction, and
nothing else at any depth, is emptied first; any other non-empty directory is refused, naming an
entry dualarm did not write; one another reproduction is writing is refused (locked).

Parts run in worker processes when ``jobs > 1``. Ctrl-C (SIGINT) and SIGTERM reach the main
process only (the workers ignore SIGINT); it stops the workers with SIGTERM, which a worker turns
into :class:`~dualarm.errors.Terminated`, so that its run is recorded as failed, and waits for
them before the interruption goes on.
"""

from __future__ import annotations

import contextlib
import functools
import json
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from queue import Empty
from typing import Any

from dualarm.errors import DualarmError, Terminated, excerpt
from dualarm.record.run_dir import MARKER, OutputDir, claim_output_dir, write_whole
from dualarm.reproduce.experiments import BY_NAME, PARTS, ROBOT, Outputs, unavailable

#: The index of a reproduction directory.
PARTS_FILE = "parts.json"
__all__ = ["MARKER", "NOT_AVAILABLE", "PARTS_FILE", "OnProgress", "PartResult", "parts_named", "prepare", "run_parts"]

#: ``(part, fraction done, text)``.
OnProgress = Callable[[str, float, str], None]


@dataclass(frozen=True)
class PartResult:
    """How one part went.

    Attributes:
        name: the part's name.
        status: ``complete``, ``failed``, or ``not available`` on this robot (not run).
        error: the error of a failed part, why one is not available ("" otherwise).
        seconds: its wall-clock time [s].
        outputs: the files it wrote, relative to the reproduction directory.
    """

    name: str
    status: str
    error: str
    seconds: float
    outputs: Outputs


def parts_named(names: Sequence[str] | None) -> tuple[str, ...]:
    """The parts to run, in report order (all when ``names`` is None).

    Raises:
        DualarmError: an unknown part.
    """
    if names is None:
        return tuple(p.name for p in PARTS)
    unknown = [n for n in names if n not in BY_NAME]
    if unknown or not names:
        raise DualarmError(f"unknown part '{excerpt((unknown or [''])[0])}' (parts: {', '.join(BY_NAME)})")
    return tuple(p.name for p in PARTS if p.name in names)


def prepare(out: Path) -> OutputDir:
    """Claim ``out`` as a reproduction's directory and empty it; returns the claim, which keeps ``out`` locked while it lives.

    Raises:
        OutputError: ``out`` is not a directory, is a non-empty directory that is not a
            reproduction's, holds an entry at any depth that dualarm does not write there (nothing
            is deleted then), or is locked by another reproduction.
    """
    claimed = claim_output_dir(out, "reproduction")
    claimed.clear()
    return claimed


#: The status of a part the robot cannot run.
NOT_AVAILABLE = "not available"


def _run_part(name: str, out: Path, robot: Path, report: Callable[[float, str], None]) -> PartResult:
    start = time.perf_counter()
    try:
        outputs = BY_NAME[name].run(out, robot, report)
        status, error = "complete", ""
    except DualarmError as exc:
        outputs, status, error = {}, "failed", str(exc)
    except Exception as exc:  # a bug in one part must not lose the others; it is reported whole
        outputs, status, error = {}, "failed", f"{type(exc).__name__}: {exc}"
    return PartResult(name, status, error, time.perf_counter() - start, outputs)


#: Whether this worker received SIGTERM.
_terminating = False


def _stop_on_sigterm(signum: int, frame: object) -> None:
    """A worker's SIGTERM handler: raise :class:`Terminated` once (a second SIGTERM must not cut short the recording of the failed run)."""
    global _terminating
    _terminating = True
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    raise Terminated()


def _unraisable(unraisable: Any) -> None:
    """A worker's ``sys.unraisablehook``: silent for :class:`Terminated` raised where Python cannot raise it (a ``__del__``: the worker raises it again between stages), Python's own hook otherwise."""
    if not issubclass(unraisable.exc_type, Terminated):
        sys.__unraisablehook__(unraisable)


def _worker(name: str, out: Path, robot: Path, queue: Any) -> None:
    """A worker process: run part ``name``; put ``("progress", name, fraction, text)`` while it runs, then ``("result", PartResult)``.

    Ctrl-C is the main process's to handle; SIGTERM ends the part with :class:`Terminated` (its
    run recorded as failed) and the process with exit code 143, without a traceback.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _stop_on_sigterm)
    sys.unraisablehook = _unraisable

    def report(fraction: float, text: str) -> None:
        if _terminating:  # Terminated was swallowed by a library (CasADi turns it into a failed solve): raise it again between stages
            raise Terminated()
        queue.put(("progress", name, fraction, text))

    queue.put(("result", _run_part(name, out, robot, report)))


@contextlib.contextmanager
def _sigint_ignored() -> Iterator[None]:
    """Ignore SIGINT while a worker starts, so that it inherits SIGINT ignored from its first instruction (a Ctrl-C in these milliseconds is lost; called outside the main thread, nothing changes)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _run_in_workers(out: Path, names: Sequence[str], robot: Path, jobs: int, on_progress: OnProgress) -> dict[str, PartResult]:
    """Run ``names`` in worker processes, ``jobs`` at a time, the longest first.

    A process per part rather than a pool: a pool worker that dies loses its task for good
    (``multiprocessing.Pool`` then waits forever) and ``ProcessPoolExecutor`` cannot stop its
    workers before Python 3.14; here a worker that dies is a failed part, and on any exception in
    this process (Ctrl-C, SIGTERM) every worker is sent SIGTERM and waited for before it goes on.
    """
    context = multiprocessing.get_context("spawn")  # no fork of a process with live threads
    queue = context.Queue()
    waiting = sorted(names, key=lambda n: -BY_NAME[n].seconds)
    running: dict[str, Any] = {}
    started: dict[str, float] = {}
    results: dict[str, PartResult] = {}

    def receive(timeout: float | None, report: bool = True) -> None:
        """Take the workers' messages (waiting up to ``timeout`` [s] for the first); progress goes to ``on_progress`` when ``report``."""
        with contextlib.suppress(Empty):
            while True:
                message = queue.get(timeout=timeout) if timeout else queue.get_nowait()
                timeout = None
                if message[0] == "progress":
                    if report:
                        on_progress(*message[1:])
                else:
                    results[message[1].name] = message[1]

    try:
        while waiting or running:
            while waiting and len(running) < jobs:
                name = waiting.pop(0)
                process = context.Process(target=_worker, args=(name, out, robot, queue), name=f"dualarm reproduce {name}")
                running[name], started[name] = process, time.perf_counter()
                with _sigint_ignored():
                    process.start()
            receive(0.2)
            for name, process in list(running.items()):
                if process.exitcode is None:
                    continue
                process.join()
                receive(None)  # what it put before it ended
                if name not in results:
                    results[name] = PartResult(name, "failed", f"its worker process ended with exit code {process.exitcode}", time.perf_counter() - started[name], {})
                del running[name]
                on_progress(name, 1.0, results[name].status)
    except BaseException:
        started_processes = [p for p in running.values() if p.pid is not None]
        for process in started_processes:
            process.terminate()  # SIGTERM: the worker records its run as failed and exits
        for process in started_processes:
            while process.is_alive():
                process.join(0.1)
                receive(None, report=False)  # keep its queue flowing, so that it can exit
        raise
    finally:
        queue.close()
    return results


def run_parts(out: Path, names: Sequence[str], jobs: int, on_progress: OnProgress, robot: Path = ROBOT) -> list[PartResult]:
    """Run the parts ``names`` on the robot directory ``robot`` into ``out`` (after :func:`prepare`), ``jobs`` processes at a time (the longest first; ``jobs = 1`` runs them in this process), and write :data:`PARTS_FILE`.

    A part the robot cannot run (:func:`~dualarm.reproduce.experiments.unavailable`) is not
    started: its status is :data:`NOT_AVAILABLE` and its error says why. Returns the results in
    report order.

    Raises:
        RobotModelError: ``robot`` is not a robot directory (before any part runs).
    """
    from dualarm.model.robot import load_robot

    started = time.perf_counter()
    name_of_robot = load_robot(robot).name
    results: dict[str, PartResult] = {}
    for name in names:
        if reason := unavailable(BY_NAME[name], robot):
            results[name] = PartResult(name, NOT_AVAILABLE, reason, 0.0, {})
            on_progress(name, 1.0, NOT_AVAILABLE)
    runnable = [n for n in names if n not in results]
    if jobs == 1:
        for name in runnable:
            results[name] = _run_part(name, out, robot, functools.partial(on_progress, name))
            on_progress(name, 1.0, results[name].status)
    elif runnable:
        results.update(_run_in_workers(out, runnable, robot, jobs, on_progress))
    ordered = [results[n] for n in names]
    index = {
        "robot": {"name": name_of_robot, "directory": str(robot)},
        "jobs": jobs,
        "cpu_count": os.cpu_count(),
        "wall_time_s": time.perf_counter() - started,
        "parts": [asdict(r) for r in ordered],
    }
    write_whole(out / PARTS_FILE, json.dumps(index, indent=2) + "\n")
    return ordered
