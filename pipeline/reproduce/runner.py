"""Running the parts of a reproduction, ``jobs`` at a time, into one output directory.

The directory gets each part's files (see :mod:`dualarm.reproduce.experiments`) and
``parts.json``: every part's status, error, time and outputs. The report is written from those
files afterwards (:mod:`dualarm.reproduce.report`). A directory that already holds a reproduction
is emptied first; any other non-empty directory is refused.
"""

from __future__ import annotations

import functools
import json
import multiprocessing
import os
import shutil
import time
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import asdict, dataclass
from pathlib import Path
from queue import Empty

from dualarm.errors import DualarmError
from dualarm.record.run_dir import write_whole
from dualarm.reproduce.experiments import BY_NAME, PARTS, Outputs

#: The index of a reproduction directory.
PARTS_FILE = "parts.json"
#: Written first into a reproduction directory, so that an interrupted one is still recognised.
MARKER = ".dualarm-reproduction"
#: Files that mark a directory as a reproduction's.
MARKERS = (MARKER, PARTS_FILE, "report.md")

#: ``(part, fraction done, text)``.
OnProgress = Callable[[str, float, str], None]


@dataclass(frozen=True)
class PartResult:
    """How one part went.

    Attributes:
        name: the part's name.
        status: ``complete`` or ``failed``.
        error: the error of a failed part ("" otherwise).
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
        raise DualarmError(f"unknown part '{(unknown or [''])[0]}' (parts: {', '.join(BY_NAME)})")
    return tuple(p.name for p in PARTS if p.name in names)


def prepare(out: Path) -> None:
    """Make ``out`` an empty directory; refuse a non-empty one that is not a reproduction's.

    Raises:
        DualarmError: ``out`` is a file, or a non-empty directory without :data:`MARKERS`.
    """
    if out.exists() and not out.is_dir():
        raise DualarmError(f"{out}: exists and is not a directory")
    if out.is_dir() and any(out.iterdir()):
        if not any((out / m).exists() for m in MARKERS):
            raise DualarmError(f"{out}: not empty and not a reproduction (no {' or '.join(MARKERS[1:])}); give another --out")
        shutil.rmtree(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / MARKER).write_text("written by dualarm reproduce; this directory is emptied when it runs again\n")


def _run_part(name: str, out: Path, report: Callable[[float, str], None]) -> PartResult:
    start = time.perf_counter()
    try:
        outputs = BY_NAME[name].run(out, report)
        status, error = "complete", ""
    except DualarmError as exc:
        outputs, status, error = {}, "failed", str(exc)
    except Exception as exc:  # a bug in one part must not lose the others; it is reported whole
        outputs, status, error = {}, "failed", f"{type(exc).__name__}: {exc}"
    return PartResult(name, status, error, time.perf_counter() - start, outputs)


def _run_part_in_worker(name: str, out: Path, queue) -> PartResult:
    return _run_part(name, out, lambda fraction, text: queue.put((name, fraction, text)))


def run_parts(out: Path, names: Sequence[str], jobs: int, on_progress: OnProgress) -> list[PartResult]:
    """Run the parts ``names`` into ``out`` (after :func:`prepare`), ``jobs`` processes at a time (the longest first; ``jobs = 1`` runs them in this process), and write :data:`PARTS_FILE`.

    Returns the results in report order.
    """
    started = time.perf_counter()
    results: dict[str, PartResult] = {}
    if jobs == 1:
        for name in names:
            results[name] = _run_part(name, out, functools.partial(on_progress, name))
            on_progress(name, 1.0, results[name].status)
    else:
        longest_first = sorted(names, key=lambda n: -BY_NAME[n].seconds)
        context = multiprocessing.get_context("spawn")  # no fork of a process with live threads
        with context.Manager() as manager, ProcessPoolExecutor(max_workers=jobs, mp_context=context) as pool:
            queue = manager.Queue()
            pending = {pool.submit(_run_part_in_worker, name, out, queue): name for name in longest_first}
            while pending:
                done, _ = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
                while True:
                    try:
                        on_progress(*queue.get_nowait())
                    except Empty:
                        break
                for future in done:
                    name = pending.pop(future)
                    results[name] = future.result()
                    on_progress(name, 1.0, results[name].status)
    ordered = [results[n] for n in names]
    index = {"jobs": jobs, "cpu_count": os.cpu_count(), "wall_time_s": time.perf_counter() - started, "parts": [asdict(r) for r in ordered]}
    write_whole(out / PARTS_FILE, json.dumps(index, indent=2) + "\n")
    return ordered
