"""Running the parts of a reproduction, ``jobs`` at a time, into one output directory.

The directory gets each part's files (see :mod:`dualarm.reproduce.experiments`) and
``parts.json``: every part's status, error, time and outputs. The report is written from those
files afterwards (:mod:`dualarm.reproduce.report`). The directory is claimed as a reproduction's
(:func:`dualarm.record.run_dir.claim_output_dir`): one that holds an earlier reproduction, and
nothing else at any depth, is emptied first; any other non-empty directory is refused, naming an
entry dualarm did not write; one another reproduction is writing is refused (locked).

Parts run as tasks on a Dask cluster (:mod:`dualarm.cluster`): a ``LocalCluster`` of ``jobs``
worker processes, or an existing cluster given by its scheduler's address, whose workers write
into the directory themselves (it must be on a file system they share). Ctrl-C (SIGINT) and
SIGTERM are this process's to handle (a ``LocalCluster``'s workers ignore SIGINT): it stops the
parts running on the workers with :class:`~dualarm.errors.Terminated`, so that their runs are
recorded as failed, and waits for them before the interruption goes on.
"""

from __future__ import annotations

import functools
import json
import os
import time
import uuid
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from queue import SimpleQueue

from dualarm.cluster import connect, stop_tasks
from dualarm.errors import DualarmError, TaskFileError, Terminated, excerpt
from dualarm.interrupt import held, stop_requested, stoppable
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
    """Claim ``out`` as a reproduction's directory and empty it.

    Returns the claim, which keeps ``out`` locked while it lives.

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
    except TaskFileError as exc:  # the task loaded, but its path leaves the robot's reach (the path stage's check)
        outputs, status, error = {}, NOT_AVAILABLE, f"its task's path is out of this robot's reach: {exc}"
    except DualarmError as exc:
        outputs, status, error = {}, "failed", str(exc)
    except Exception as exc:  # a bug in one part must not lose the others; it is reported whole
        outputs, status, error = {}, "failed", f"{type(exc).__name__}: {exc}"
    return PartResult(name, status, error, time.perf_counter() - start, outputs)


#: The Dask event topic of a reproduction's progress (followed by its token).
PROGRESS_TOPIC = "dualarm-reproduce-progress"


def _unseen(worker: object, out: Path) -> str:
    """Why a worker cannot run a part: it does not see ``out``."""
    return (
        f"worker {excerpt(worker, 40)} does not see {excerpt(out)}: with "
        "--scheduler, --out must be on a file system the workers share"
    )


def _part_task(name: str, out: Path, robot: Path, topic: str) -> PartResult:
    """Run part ``name`` as a Dask task: its progress logged to ``topic``, stoppable under its key.

    Stopped by :func:`dualarm.cluster.stop_tasks`, its run is then recorded as failed.
    """
    from distributed import get_worker

    worker = get_worker()
    if not (out / MARKER).is_file():  # --scheduler: a worker on another machine, without out's file system
        return PartResult(name, "failed", _unseen(worker.name, out), 0.0, {})

    def report(fraction: float, text: str) -> None:
        if (
            stop_requested()
        ):  # Terminated was swallowed by a library (CasADi turns it into a failed solve): raise it again between stages
            raise Terminated()
        worker.log_event(topic, (name, fraction, text))

    start = time.perf_counter()
    try:
        with stoppable(str(worker.get_current_task())):
            return _run_part(name, out, robot, report)
    except Terminated as exc:
        return PartResult(name, "failed", f"Terminated: {exc}", time.perf_counter() - start, {})


def _run_on_cluster(
    out: Path, names: Sequence[str], robot: Path, jobs: int, scheduler: str | None, on_progress: OnProgress
) -> tuple[dict[str, PartResult], int]:
    """Run ``names`` as Dask tasks (the longest first); returns the results and the number of workers.

    On the cluster at ``scheduler``, else a ``LocalCluster`` of ``jobs`` workers.

    Ctrl-C or SIGTERM in this process stops the parts running on the workers (their runs are
    recorded as failed) and waits for them before the interruption goes on. A part whose worker
    died :data:`~dualarm.cluster.ALLOWED_FAILURES` times is failed.

    Raises:
        DualarmError: ``scheduler`` cannot be reached, or a worker does not see ``out``.
    """
    results: dict[str, PartResult] = {}
    with connect(scheduler, jobs) as client:
        workers = client.scheduler_info(n_workers=-1)["workers"]
        blind = [workers[w]["name"] for w, sees in client.run(os.path.isfile, str(out / MARKER)).items() if not sees]
        if blind:
            raise DualarmError(_unseen(blind[0], out))
        topic = f"{PROGRESS_TOPIC}-{uuid.uuid4().hex}"
        messages: SimpleQueue[tuple[str, float, str]] = SimpleQueue()
        client.subscribe_topic(topic, lambda event: messages.put(event[1]))
        futures = {
            client.submit(
                _part_task,
                n,
                out,
                robot,
                topic,
                priority=round(BY_NAME[n].seconds),
                pure=False,
                key=f"reproduce-{n}-{uuid.uuid4().hex}",
            ): n
            for n in names
        }
        submitted = time.perf_counter()
        pending = set(futures)
        try:
            # Ctrl-C and SIGTERM are raised here, between polls, not inside Dask's code in this
            # process (its scheduler's)
            with held() as signalled:
                while pending and not signalled:
                    time.sleep(0.2)
                    done = {f for f in pending if f.done()}
                    pending -= done
                    while not messages.empty():
                        if (message := messages.get())[
                            0
                        ] not in results:  # a part's last messages may come after its result
                            on_progress(*message)
                    for future in done:
                        name = futures[future]
                        try:
                            results[name] = future.result()
                        except Exception as exc:  # its worker died ALLOWED_FAILURES times
                            results[name] = PartResult(
                                name,
                                "failed",
                                f"{type(exc).__name__}: {excerpt(str(exc), 200)}",
                                time.perf_counter() - submitted,
                                {},
                            )
                        on_progress(name, 1.0, results[name].status)
        except BaseException:
            stop_tasks(client, futures)
            raise
        return results, len(workers)


def run_parts(
    out: Path,
    names: Sequence[str],
    jobs: int,
    on_progress: OnProgress,
    robot: Path = ROBOT,
    scheduler: str | None = None,
) -> list[PartResult]:
    """Run the parts ``names`` on the robot directory ``robot`` into ``out`` and write :data:`PARTS_FILE`.

    After :func:`prepare`.

    The parts run as Dask tasks, the longest first: on the cluster at ``scheduler``
    (``tcp://HOST:PORT``; ``out`` must be on a file system its workers share), else on a
    ``LocalCluster`` of ``jobs`` worker processes; ``jobs = 1`` without ``scheduler`` runs them in
    this process, one after the other.

    A part the robot cannot run (:func:`~dualarm.reproduce.experiments.unavailable`) is not
    started: its status is :data:`NOT_AVAILABLE` and its error says why. Returns the results in
    report order.

    Raises:
        RobotModelError: ``robot`` is not a robot directory (before any part runs).
        DualarmError: ``scheduler`` cannot be reached, or a worker does not see ``out``.
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
    workers = jobs
    if jobs == 1 and scheduler is None:
        for name in runnable:
            results[name] = _run_part(name, out, robot, functools.partial(on_progress, name))
            on_progress(name, 1.0, results[name].status)
    elif runnable:
        ran, workers = _run_on_cluster(out, runnable, robot, jobs, scheduler, on_progress)
        results.update(ran)
    ordered = [results[n] for n in names]
    index = {
        "robot": {"name": name_of_robot, "directory": str(robot)},
        "jobs": workers,
        "scheduler": scheduler,
        "cpu_count": os.cpu_count(),
        "wall_time_s": time.perf_counter() - started,
        "parts": [asdict(r) for r in ordered],
    }
    write_whole(out / PARTS_FILE, json.dumps(index, indent=2) + "\n")
    return ordered
