"""Running a study on Dask distributed: every trial with every method, one row each.

Written as the study goes.

The trials run on a Dask cluster (:func:`run_study`): a ``LocalCluster`` of worker processes (one
thread each) by default, or an existing one given by its scheduler's address (as dask-jobqueue and
dask-kubernetes clusters are used). A worker runs all the methods of one trial
(:func:`run_trial`); the robot, its CasADi functions and PyBullet's model are built once per
worker process (they are cached by robot), not once per trial. A worker writes nothing: it returns
the trial's rows and its task file's text, and this process writes them, so the workers need no
shared file system (but for ``record`` above ``metrics``, whose runs the workers record into
``DIR/runs``).

A study's directory ``DIR`` holds:

- ``study.json``: the spec (its validated values) and the dualarm version; a second study, another
  spec, into the same directory is refused.
- ``parts/trial-NNNNNN.parquet``: each finished trial's rows, written whole as it finishes (a crash
  loses at most the trials in flight); ``--resume`` skips the trials found here.
- ``trials.parquet``: every row so far (one file), rewritten from the parts every
  :data:`CONSOLIDATE_S` seconds and at the end: ``pandas.read_parquet("DIR/trials.parquet")``,
  ``duckdb.sql("select method, avg(inconsistent::int) from 'DIR/trials.parquet' group by method")``.
- ``tasks/<study>-NNNNNN.toml``: each trial's task file, so that any trial runs alone
  (``dualarm run DIR/tasks/<study>-NNNNNN.toml --ik METHOD --stages path,ik``).
- ``runs/``: the recorded runs, with ``record`` ``ik`` or ``full`` only.

A row (:data:`COLUMNS`, then the trial's features and every ``path.*`` and ``ik.*`` metric):

- ``status``: the run's verdict, ``complete`` or ``violated`` (:mod:`dualarm.violations`; an IK path through the
  robot or the scene is a violation, as in any run without the execute stage); ``failed``
  when the method raised (a :class:`~dualarm.errors.DualarmError`: no path, an unreachable start);
  ``error`` for any other exception, or a trial whose worker died :data:`~dualarm.cluster.ALLOWED_FAILURES` times.
- ``failed``: the method raised, or a repetition holds a failed IK sample (``ik.failed_reps``).
- ``inconsistent``: the spec's definition (``[inconsistent]``): ``ik.rep_joint_deviation_max_rad``
  above ``joint_deviation_rad``, or (``failed_repetition``) ``failed``.
"""

from __future__ import annotations

import json
import math
import re
import time
from collections.abc import Callable
from contextlib import nullcontext
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import pandas as pd

from dualarm.cluster import LOCAL, connect, worker_name
from dualarm.errors import DualarmError, NotSRSError, OutputError, RobotModelError, TaskFileError, excerpt
from dualarm.quiet import c_output_silenced
from dualarm.record.run_dir import claim_output_dir, write_whole
from dualarm.record.sink import record_level
from dualarm.study.spec import StudySpec
from dualarm.study.trials import ARMS, MAX_DRAWS, Trial, reachable_trial, study_robot, trial
from dualarm.version import __version__

#: The files and directories of a study's directory (module docstring).
SPEC_FILE, RESULTS, PARTS, TASKS, RUNS = "study.json", "trials.parquet", "parts", "tasks", "runs"
#: How often ``trials.parquet`` is rewritten while the study runs [s].
CONSOLIDATE_S = 30.0
#: The stages a trial's method runs, unless it is recorded ``full`` (then every stage runs).
STUDY_STAGES = ("path", "ik")
#: The first columns of every row, in order; the trial's features and the metrics follow.
COLUMNS = (
    "study",
    "seed",
    "robot",
    "trial",
    "method",
    "status",
    "failed",
    "inconsistent",
    "error",
    "violations",
    "wall_s",
    "worker",
)
#: The columns that differ from run to run of one study (times and where it ran): a comparison of
#: two runs leaves them out.
VARYING = ("wall_s", "worker", "ik.solve_time_mean_s", "ik.solve_time_median_s", "ik.solve_time_total_s")


@dataclass(frozen=True)
class TrialResult:
    """What a worker returns for one trial.

    Attributes:
        index: the trial's number.
        task_toml: its task file's text.
        rows: one per method, in the spec's order (module docstring).
    """

    index: int
    task_toml: str
    rows: tuple[dict[str, Any], ...]


@dataclass(frozen=True)
class StudyRun:
    """What :func:`run_study` did.

    Attributes:
        directory: the study's directory.
        results: every row of the study so far (``trials.parquet``).
        ran: the trials run now (the others were found in the directory: ``resume``).
        seconds: the wall time of the trials run now, from their submission to the last result [s]
            (each worker's first trial includes its imports and the CasADi Functions it builds).
        startup_s: the time to start the LocalCluster, or connect to the scheduler [s].
        workers: the cluster's workers when the trials were submitted.
    """

    directory: Path
    results: pd.DataFrame
    ran: int
    seconds: float
    startup_s: float
    workers: int


def run_trial(
    spec: StudySpec, base_dir: str, index: int, record: str = "metrics", runs: str | None = None
) -> TrialResult:
    """Trial ``index`` of ``spec`` run by each of its methods (a Dask task; also callable alone).

    Every method's failure is its row's (``status``, ``error``), and so is a trial whose task
    cannot be built (a waypoint beyond the arm's span): every method ``failed``.
    """
    import tomli_w

    from dualarm.errors import UnreachablePoseError

    worker = worker_name()
    # In a worker, what C libraries print (CasADi's warnings, PyBullet's banners) would reach the study's terminal.
    with c_output_silenced() if worker != LOCAL else nullcontext():
        try:
            drawn, task = reachable_trial(spec, index, base_dir)
            refused = ""
        except UnreachablePoseError as exc:  # the trial's task cannot be built: every method fails it
            drawn = trial(spec, index, MAX_DRAWS - 1 if spec.centre.reachable else 0)
            drawn.features["reachable"] = False
            task, refused = None, str(exc)
        rows = tuple(_method_row(spec, drawn, task, method, record, runs, worker, refused) for method in spec.methods)
    return TrialResult(index, tomli_w.dumps(_task_file(drawn, base_dir)), rows)


def _method_row(
    spec: StudySpec, drawn: Trial, task: Any, method: str, record: str, runs: str | None, worker: str, refused: str = ""
) -> dict[str, Any]:
    """One method's row of one trial (module docstring).

    ``refused``: why the trial has no task (then the row is ``failed``).
    """
    from dualarm.run import build_stages, record_stages, run_stages
    from dualarm.stages import IkStage

    start = time.perf_counter()
    metrics: dict[str, float] = {}
    violations: tuple[str, ...] = ()
    error, status = "", ""
    try:
        if refused:
            raise DualarmError(refused)
        stages = build_stages(task, method, stages=None if record == "full" else STUDY_STAGES)
        # Without the retime stage, the IK stage would judge joint velocities at the task's
        # sampling; a study's trial is timed afterwards like any other run, so it does not.
        stages = tuple(replace(s, retimed=True) if isinstance(s, IkStage) else s for s in stages)
        if record == "metrics":
            result = run_stages(task, stages)
        else:
            result = record_stages(
                task,
                stages,
                out_dir=runs or RUNS,
                command=["dualarm", "study", spec.name, f"trial {drawn.index}", method],
                record=record,
            )
        status, metrics = str(result.verdict.status), result.metrics
        violations = tuple(v.message for v in result.verdict.violations)
    except DualarmError as exc:
        status, error = "failed", str(exc)
    except Exception as exc:  # a bug in one method must not lose the trial or the study: it is the row's error
        status, error = "error", f"{type(exc).__name__}: {exc}"
    failed = status in ("failed", "error") or metrics.get("ik.failed_reps", 0.0) > 0
    deviation = metrics.get("ik.rep_joint_deviation_max_rad", math.nan)
    inconsistent = bool(
        deviation > spec.inconsistent.joint_deviation_rad or (failed and spec.inconsistent.failed_repetition)
    )
    row = {
        **_identity(spec, drawn.index, method),
        "status": status,
        "failed": failed,
        "inconsistent": inconsistent,
        "error": excerpt(error, 400),
        "violations": "; ".join(violations[:5]),
        "wall_s": time.perf_counter() - start,
        "worker": worker,
    }
    return {**row, **drawn.features, **metrics}


def _task_file(drawn: Trial, base_dir: str) -> dict[str, Any]:
    """The trial's task as a file in ``DIR/tasks``.

    Its robot, if a directory, made absolute (it was relative to the spec).
    """
    beside = Path(base_dir) / drawn.task["robot"]
    return {**drawn.task, "robot": str(beside.resolve())} if beside.is_dir() else drawn.task


def _identity(spec: StudySpec, index: int, method: str) -> dict[str, Any]:
    """The first columns of a row: which study, trial and method."""
    return {"study": spec.name, "seed": spec.seed, "robot": spec.robot, "trial": index, "method": method}


def error_rows(spec: StudySpec, index: int, error: str) -> tuple[dict[str, Any], ...]:
    """The rows of a trial that produced none: ``status = error``, without features.

    Its worker died :data:`~dualarm.cluster.ALLOWED_FAILURES` times; its draw is not known here.
    """
    rest = {
        "status": "error",
        "failed": True,
        "inconsistent": spec.inconsistent.failed_repetition,
        "error": excerpt(error, 400),
        "violations": "",
        "wall_s": math.nan,
        "worker": "",
    }
    return tuple({**_identity(spec, index, m), **rest} for m in spec.methods)


def read_study(directory: str | Path, spec: StudySpec | None = None) -> pd.DataFrame:
    """Every row of the study in ``directory``: its parts (the trials finished so far).

    Sorted by trial and method in the spec's order; empty without any. With ``spec``, each part must be one of its
    trials: named ``trial-NNNNNN.parquet`` with N below its ``trials``, holding that trial's rows of this study, one
    per method of the spec (what ``--resume`` trusts).

    Raises:
        RecordingError: a part that is not a readable parquet file, or not one of ``spec``'s trials (named).
    """
    from dualarm.errors import RecordingError

    frames = []
    for part in sorted((Path(directory) / PARTS).glob("trial-*.parquet")):
        try:
            rows = pd.read_parquet(part)
        except Exception as exc:  # pyarrow raises its own errors for a truncated or foreign file
            raise RecordingError(
                f"{excerpt(part)}: not a readable study part ({type(exc).__name__}: "
                f"{excerpt(str(exc), 120)}); delete it to run the trial again with --resume"
            ) from None
        if spec is not None and (why := _not_a_part(part.name, rows, spec)):
            raise RecordingError(f"{excerpt(part)}: not a part of study '{spec.name}' ({why}); move it out of it")
        frames.append(rows)
    return _ordered(pd.concat(frames, ignore_index=True)) if frames else pd.DataFrame(columns=list(COLUMNS))


def _not_a_part(name: str, rows: pd.DataFrame, spec: StudySpec) -> str:
    """Why the part file ``name`` holding ``rows`` is not one of ``spec``'s trials; "" if it is."""
    match = re.fullmatch(r"trial-(\d{6})\.parquet", name)
    trial = int(match.group(1)) if match is not None else spec.trials
    if trial >= spec.trials:
        return f"its name is no trial-NNNNNN.parquet of trials 0 to {spec.trials - 1}"
    if not {"study", "trial", "method"} <= set(rows.columns):
        return "no study, trial and method columns"
    if not (rows["study"] == spec.name).all() or not (rows["trial"] == trial).all():
        return f"rows of another study or trial than {trial}"
    if sorted(rows["method"].astype(str)) != sorted(spec.methods):
        return f"its methods are not the spec's, once each ({', '.join(spec.methods)})"
    return ""


def _ordered(rows: pd.DataFrame) -> pd.DataFrame:
    """``rows`` sorted by trial, then method as the spec lists them.

    With :data:`COLUMNS` first and the metrics last, by name.
    """
    order = {m: i for i, m in enumerate(dict.fromkeys(rows["method"]))}
    rows = rows.sort_values(
        ["trial", "method"], key=lambda c: c.map(order) if c.name == "method" else c, kind="stable", ignore_index=True
    )
    metrics = sorted(
        c for c in rows.columns if c.startswith(("path.", "ik.", "retime.", "smooth.", "approach.", "execute."))
    )
    features = [c for c in rows.columns if c not in COLUMNS and c not in metrics]
    return rows[[*COLUMNS, *features, *metrics]]


def claim_study_dir(directory: Path, spec: StudySpec, resume: bool) -> Any:
    """Claim ``directory`` for ``spec``; returns the claim (a lock held while it lives).

    Refuses another study's directory, and one with results unless ``resume``.
    """
    claimed = claim_output_dir(directory, "study")
    recorded = {"spec": spec.model_dump(mode="json"), "dualarm_version": __version__}
    file = directory / SPEC_FILE
    if file.is_file():
        try:
            theirs = json.loads(file.read_text())["spec"]
        except (OSError, ValueError, KeyError, TypeError):
            raise OutputError(f"{excerpt(file)}: not a study's spec record; give another --out") from None
        if theirs != recorded["spec"]:
            raise OutputError(
                f"{excerpt(directory)}: holds study '{excerpt(theirs.get('name', '?'), 40)}' "
                "of another spec; give another --out (one study per directory)",
                str(directory),
            )
        if not resume and any((directory / PARTS).glob("trial-*.parquet")):
            raise OutputError(
                f"{excerpt(directory)}: already holds trials of study "
                f"'{spec.name}'; continue it with --resume, or give another --out",
                str(directory),
            )
    else:
        write_whole(file, json.dumps(recorded, indent=2) + "\n")
    return claimed


#: Trials submitted per worker at a time: the queue stays full, and a study of a million trials starts at once (it
#: submitted every trial first, 60 s of nothing on the screen for a million).
IN_FLIGHT_PER_WORKER = 4


def run_study(
    spec: StudySpec,
    base_dir: str | Path,
    out: str | Path,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    resume: bool = False,
    record: str = "metrics",
    progress: Callable[[int, int, int, int], None] | None = None,
) -> StudyRun:
    """Run every trial of ``spec`` not yet in ``out`` on a Dask cluster (module docstring).

    Args:
        spec: the study.
        base_dir: the directory the spec's ``robot`` is relative to (the spec file's).
        out: the study's directory.
        scheduler: an existing cluster's scheduler address, else a ``LocalCluster`` (:func:`connect`).
        workers: the ``LocalCluster``'s worker processes (default one per core).
        resume: run the trials not found in ``out`` (else ``out`` must hold none).
        record: ``metrics`` (no recordings), ``ik`` or ``full`` (each trial's runs in ``out/runs``).
        progress: told ``(done, failed, total, errors)`` after each trial: trials finished, those of
            them with a failed method, the trials to run now, and rows with ``status = error``.

    Raises:
        OutputError: ``out`` holds another study, or this one's trials without ``resume``, or is in use.
        RecordingError: a part in ``out`` that is not one of ``spec``'s trials (:func:`read_study`).
        DualarmError: ``scheduler`` cannot be reached, an unknown ``record`` level.
    """
    record_level(record)
    try:  # a robot that does not load, or cannot be checked for reach, is refused before anything is written
        robot = study_robot(spec.robot, str(Path(base_dir).resolve()))
    except RobotModelError as exc:
        raise TaskFileError(f"robot: {exc}") from None
    arms = dict.fromkeys(arm for hand in spec.hands for arm in ARMS[hand])
    for arm in arms:
        if arm not in robot.hands:
            raise TaskFileError(
                f"hands: robot '{excerpt(robot.name, 40)}' has no {arm} hand (hands: {', '.join(robot.hands)})"
            )
    if spec.centre.reachable:
        from dualarm.ik.analytic.mc_inverse import McInverse

        for hand in arms:
            try:
                McInverse.of(robot.hand_chain(hand))
            except NotSRSError as exc:
                raise TaskFileError(
                    f"centre.reachable: the reach check needs S-R-S arms ({exc}); set [centre] reachable = false"
                ) from None
    directory = Path(out)
    claim = claim_study_dir(directory, spec, resume)
    done = read_study(directory, spec)
    finished = (
        set(done.groupby("trial")["method"].nunique().loc[lambda n: n == len(spec.methods)].index)
        if len(done)
        else set()
    )
    todo = [i for i in range(spec.trials) if i not in finished]
    rows: list[dict[str, Any]] = [{str(k): v for k, v in row.items()} for row in done.to_dict("records")]
    failed = errors = count = 0
    begin = start = time.perf_counter()
    n_workers = 0
    try:
        if todo:
            from distributed import as_completed

            with connect(scheduler, workers) as client:
                n_workers = len(client.scheduler_info(n_workers=-1)["workers"])
                start = time.perf_counter()
                base, runs = str(Path(base_dir).resolve()), str((directory / RUNS).resolve())
                waiting, index, running = iter(todo), {}, as_completed()

                def submit_next() -> None:  # at most IN_FLIGHT_PER_WORKER per worker are submitted at a time
                    i = next(waiting, None)
                    if i is not None:
                        future = client.submit(run_trial, spec, base, i, record, runs, pure=False)
                        index[future.key] = i
                        running.add(future)

                for _ in range(IN_FLIGHT_PER_WORKER * max(n_workers, 1)):
                    submit_next()
                written = time.perf_counter()
                for future in running:
                    submit_next()
                    try:
                        result = future.result()
                    except Exception as exc:  # the trial took ALLOWED_FAILURES workers down, or could not be built
                        i = index[future.key]
                        result = TrialResult(i, "", error_rows(spec, i, f"{type(exc).__name__}: {exc}"))
                    future.release()
                    _write_trial(directory, spec, result)
                    rows.extend(result.rows)
                    count += 1
                    failed += any(r["failed"] for r in result.rows)
                    errors += sum(r["status"] == "error" for r in result.rows)
                    if progress is not None:
                        progress(count, failed, len(todo), errors)
                    if time.perf_counter() - written > CONSOLIDATE_S:
                        _consolidate(directory, rows)
                        written = time.perf_counter()
    finally:
        results = _consolidate(directory, rows)
        claim.release()
    return StudyRun(directory, results, count, time.perf_counter() - start, start - begin, n_workers)


def _write_trial(directory: Path, spec: StudySpec, result: TrialResult) -> None:
    """The trial's task file, then its part (the part last: a trial with a part is complete)."""
    if result.task_toml:
        write_whole(directory / TASKS / f"{spec.name}-{result.index:06d}.toml", result.task_toml)
    write_whole(
        directory / PARTS / f"trial-{result.index:06d}.parquet", pd.DataFrame(list(result.rows)).to_parquet(index=False)
    )


def _consolidate(directory: Path, rows: list[dict[str, Any]]) -> pd.DataFrame:
    """Write ``trials.parquet``: ``rows``, one per trial and method, whole, then renamed; returns them.

    Without rows nothing is written: a study that ran no trial (its cluster unreachable) leaves no
    empty table that looks like results.
    """
    if not rows:
        return pd.DataFrame(columns=list(COLUMNS))
    table = _ordered(pd.DataFrame(rows))
    twice = table[table.duplicated(["trial", "method"])]
    if len(twice):  # the parts are checked (read_study): a second row of a trial and method is a bug, not data
        from dualarm.errors import RecordingError

        raise RecordingError(
            f"{excerpt(directory / RESULTS)}: trial {twice['trial'].iloc[0]} has two rows of method "
            f"{twice['method'].iloc[0]}; not written"
        )
    write_whole(directory / RESULTS, table.to_parquet(index=False))
    return table
