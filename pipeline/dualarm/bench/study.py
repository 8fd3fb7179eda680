"""``dualarm bench study``: a study's throughput on Dask, and the whole example study's time.

The throughput from 1 to 2 workers and on two workers started apart.

1. **Scaling.** The spec's first ``scaling_trials`` trials on a ``LocalCluster`` of 1 worker, then of
   ``workers``: trials per second per worker, from the submission of the trials to the last result
   (each worker's first trial includes its imports and the CasADi Functions it builds), and the ratio
   of the two (the target: within 10 %).
2. **Two nodes.** The same trials on a scheduler and ``workers`` ``dask worker`` processes started
   apart on 127.0.0.1, as separate nodes would be (:func:`loopback_cluster`), compared row by row with
   the ``LocalCluster``'s: equal bit for bit but for the columns that vary from run to run
   (:data:`~dualarm.study.run.VARYING`) and TRAC-IK's rows (its timeout is wall-clock).
3. **The whole study.** Every trial of the spec on the ``LocalCluster`` of ``workers``, and the
   trials' sizes (shapes, repetitions, IK samples per trial).
4. **The machine without Dask.** The scaling trials in one plain Python process, then split among
   ``workers`` plain processes side by side (:func:`plain_run`): the ratio this machine gives
   without any engine, the peer of the ``LocalCluster``'s. Each run's share of CPU time the
   hypervisor took (``steal`` in ``/proc/stat``) is reported beside it: a virtual machine's cores
   are not always its own.

Each run goes to a temporary directory, removed afterwards. Never used by the test suite: wall-clock
numbers depend on the machine.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

import pandas as pd

from dualarm.cluster import WORKER_ENVIRON, local_cores, pin_to_core
from dualarm.errors import DualarmError
from dualarm.study.run import VARYING, StudyRun, claim_study_dir, run_study
from dualarm.study.spec import StudySpec

T = TypeVar("T")
#: The method whose rows are not compared between runs (its timeout is wall-clock: not repeatable).
UNREPEATABLE = ("trac-ik",)


@dataclass(frozen=True)
class StudyBench:
    """What :func:`bench_study` measured.

    Attributes:
        one, many: the scaling runs on 1 and on ``workers`` workers.
        nodes: the run on the workers started apart.
        nodes_differ: the columns in which the two-node run's rows differ from the ``LocalCluster``'s
            (but for :data:`~dualarm.study.run.VARYING` and TRAC-IK's rows); empty when identical.
        compared_rows: the rows compared.
        whole: the whole study, or None when not asked.
        plain_one, plain_many: the scaling trials in 1 and in ``workers`` plain processes.
        steal: per run (``one``, ``many``, ``nodes``, ``whole``, ``plain_one``, ``plain_many``), the
            share of the machine's CPU time the hypervisor took while it ran (NaN without ``/proc/stat``).
    """

    one: StudyRun
    many: StudyRun
    nodes: StudyRun
    nodes_differ: tuple[str, ...]
    compared_rows: int
    whole: StudyRun | None
    plain_one: PlainRun
    plain_many: PlainRun
    steal: dict[str, float]

    @staticmethod
    def rate(run: StudyRun) -> float:
        """Trials per second per worker."""
        return run.ran / run.seconds / max(run.workers, 1)


@contextmanager
def loopback_cluster(workers: int = 2, directory: Path | None = None) -> Iterator[str]:
    """A Dask scheduler and ``workers`` ``dask worker`` processes started apart on 127.0.0.1.

    One thread each, named ``node-a``, ``node-b``, ..., as separate nodes; yields the scheduler's
    address, and stops them all at the end.

    Raises:
        DualarmError: the scheduler did not write its address, or the workers did not join, within 60 s.
    """
    from distributed import Client

    with tempfile.TemporaryDirectory(dir=directory) as tmp:
        file = Path(tmp) / "scheduler.json"
        scheduler = [
            sys.executable,
            "-m",
            "distributed.cli.dask_scheduler",
            "--host",
            "127.0.0.1",
            "--port",
            "0",
            "--no-dashboard",
            "--scheduler-file",
            str(file),
        ]
        processes = [subprocess.Popen(scheduler, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
        try:
            deadline = time.monotonic() + 60
            while not (file.is_file() and file.stat().st_size):
                if time.monotonic() > deadline or processes[0].poll() is not None:
                    raise DualarmError("the Dask scheduler did not start within 60 s")
                time.sleep(0.1)
            address = json.loads(file.read_text())["address"]
            for k in range(workers):
                name = f"node-{chr(ord('a') + k)}"
                command = [
                    sys.executable,
                    "-m",
                    "distributed.cli.dask_worker",
                    address,
                    "--nthreads",
                    "1",
                    "--nworkers",
                    "1",
                    "--name",
                    name,
                    "--host",
                    "127.0.0.1",
                    "--no-dashboard",
                ]
                processes.append(subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
            with Client(address, timeout="60s") as client:
                try:
                    client.wait_for_workers(workers, timeout=60) if workers else None
                except TimeoutError:
                    raise DualarmError(f"{workers} Dask workers did not join the scheduler within 60 s") from None
            yield address
        finally:
            for process in reversed(processes):
                process.terminate()
            for process in processes:
                try:
                    process.wait(timeout=30)
                except subprocess.TimeoutExpired:
                    process.kill()


def differing_columns(a: pd.DataFrame, b: pd.DataFrame) -> tuple[str, ...]:
    """The columns in which two runs' rows of the same trials differ (NaN equals NaN).

    But for :data:`~dualarm.study.run.VARYING` and the :data:`UNREPEATABLE` methods' rows.
    """
    keep_a, keep_b = (r[~r["method"].isin(UNREPEATABLE)].reset_index(drop=True) for r in (a, b))
    if len(keep_a) != len(keep_b) or list(keep_a.columns) != list(keep_b.columns):
        return ("rows or columns",)
    return tuple(c for c in keep_a.columns if c not in VARYING and not keep_a[c].equals(keep_b[c]))


@dataclass(frozen=True)
class PlainRun:
    """Trials run by plain Python processes side by side, without Dask (:func:`plain_run`).

    Attributes:
        trials: each process's trials, (P,).
        seconds: each process's time from its first trial's start to its last's end [s], (P,).
    """

    trials: tuple[int, ...]
    seconds: tuple[float, ...]

    @property
    def rate(self) -> float:
        """Trials per second per process (the mean over the processes)."""
        return sum(n / t for n, t in zip(self.trials, self.seconds, strict=True)) / len(self.trials)


def plain_run(spec: StudySpec, base_dir: Path, processes: int) -> PlainRun:
    """Run the trials of ``spec`` in ``processes`` plain Python processes side by side.

    Process p runs the trials p, p + P, ... one after another with
    :func:`~dualarm.study.run.run_trial`, in the environment a ``LocalCluster``'s worker has (one
    thread for OpenMP and BLAS, pinned to a core of its own).

    Raises:
        DualarmError: a process failed.
    """
    environment = {**os.environ, **WORKER_ENVIRON}
    code = "import sys; from dualarm.bench.study import _plain_process; _plain_process(*sys.argv[1:])"
    runs = [
        subprocess.Popen(
            [sys.executable, "-c", code, spec.model_dump_json(), str(base_dir), str(p), str(processes)],
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
            env=environment,
        )
        for p in range(processes)
    ]
    answers = [run.communicate()[0] for run in runs]
    if any(run.returncode for run in runs):
        raise DualarmError(f"a plain process of the benchmark failed (exit codes {[run.returncode for run in runs]})")
    measured = [json.loads(answer.strip().splitlines()[-1]) for answer in answers]
    return PlainRun(tuple(m["trials"] for m in measured), tuple(m["seconds"] for m in measured))


def _plain_process(spec_json: str, base_dir: str, first: str, step: str) -> None:
    """One process of :func:`plain_run`: prints ``{"trials": n, "seconds": s}`` last."""
    from dualarm.study.run import run_trial

    spec = StudySpec.model_validate_json(spec_json)
    if cores := local_cores(int(step)):  # as a LocalCluster's worker is
        pin_to_core(cores[int(first)])
    indices = range(int(first), spec.trials, int(step))
    start = time.perf_counter()
    for i in indices:
        run_trial(spec, base_dir, i)
    print(json.dumps({"trials": len(indices), "seconds": time.perf_counter() - start}))


def _cpu_ticks() -> tuple[int, int]:
    """The machine's CPU time so far and the hypervisor's share of it, from ``/proc/stat`` [ticks].

    (0, 0) without it.
    """
    try:
        fields = [int(x) for x in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
    except (OSError, ValueError):
        return 0, 0
    return sum(fields[:8]), fields[7]  # user nice system idle iowait irq softirq steal


def _with_steal(steal: dict[str, float], name: str, run: Callable[[], T]) -> T:
    """``run()``, with the share of CPU time the hypervisor took meanwhile in ``steal[name]``."""
    total, stolen = _cpu_ticks()
    result = run()
    total2, stolen2 = _cpu_ticks()
    steal[name] = (stolen2 - stolen) / (total2 - total) if total2 > total else math.nan
    return result


def bench_study(
    spec: StudySpec,
    base_dir: Path,
    *,
    workers: int = 2,
    scaling_trials: int = 100,
    whole: bool = True,
    whole_out: Path | None = None,
    progress: Callable[[str], None] | None = None,
) -> StudyBench:
    """Run the benchmark (module docstring) on ``spec``.

    Its first ``scaling_trials`` trials on 1 and ``workers`` workers, on a loopback cluster and in
    plain processes, then (``whole``) every trial, into ``whole_out`` (kept; claimed as
    :func:`~dualarm.study.run.run_study` claims it) or a temporary directory.
    """
    say = progress or (lambda text: None)
    if whole and whole_out is not None:  # refused now rather than after the scaling runs
        claim_study_dir(whole_out, spec, resume=False).release()
    first = spec.model_copy(update={"trials": min(scaling_trials, spec.trials)})
    steal: dict[str, float] = {}
    with tempfile.TemporaryDirectory(prefix="dualarm-bench-study-") as tmp:
        out = Path(tmp)
        say(f"{first.trials} trials on 1 worker")
        one = _with_steal(steal, "one", lambda: run_study(first, base_dir, out / "one", workers=1))
        say(f"{first.trials} trials on {workers} workers")
        many = _with_steal(steal, "many", lambda: run_study(first, base_dir, out / "many", workers=workers))
        say(f"{first.trials} trials in 1 plain process")
        plain_one = _with_steal(steal, "plain_one", lambda: plain_run(first, base_dir, 1))
        say(f"{first.trials} trials in {workers} plain processes")
        plain_many = _with_steal(steal, "plain_many", lambda: plain_run(first, base_dir, workers))
        say(f"{first.trials} trials on {workers} workers started apart")
        with loopback_cluster(workers, out) as address:
            nodes = _with_steal(steal, "nodes", lambda: run_study(first, base_dir, out / "nodes", scheduler=address))
        kept = many.results[~many.results["method"].isin(UNREPEATABLE)]
        differ = differing_columns(many.results, nodes.results)
        done = None
        if whole:
            say(f"the whole study: {spec.trials} trials on {workers} workers")
            done = _with_steal(
                steal, "whole", lambda: run_study(spec, base_dir, whole_out or out / "whole", workers=workers)
            )
    return StudyBench(one, many, nodes, differ, len(kept), done, plain_one, plain_many, steal)


def method_seconds(one: StudyRun, many: StudyRun) -> pd.DataFrame:
    """Per method, its mean time per trial [s] on 1 worker and on more, and their ratio.

    Which methods slow down when the workers share the machine.
    """
    a, b = (r.results.groupby("method", sort=False)["wall_s"].mean() for r in (one, many))
    return pd.DataFrame({"one_s": a, "many_s": b, "ratio": b / a})


def trial_sizes(results: pd.DataFrame) -> dict[str, str]:
    """The trials' sizes, from one method's rows.

    Shapes (share of each kind), repetitions, IK samples per trial and per repetition (range and
    mean).
    """
    rows = results.drop_duplicates("trial")
    samples = (
        results.groupby("trial")["path.samples"].max().dropna()
        if "path.samples" in results.columns
        else pd.Series(dtype=float)
    )
    per_rep = (samples / rows.set_index("trial")["repetitions"]).dropna()
    shares = rows["kind"].value_counts(normalize=True)
    return {
        "shapes": ", ".join(f"{kind} {share:.0%}" for kind, share in shares.items()),
        "repetitions": (
            f"{rows['repetitions'].min()}-{rows['repetitions'].max()} (mean {rows['repetitions'].mean():.2f})"
        ),
        "IK samples per trial": f"{samples.min():.0f}-{samples.max():.0f} (mean {samples.mean():.0f})"
        if len(samples)
        else "-",
        "IK samples per repetition": f"{per_rep.min():.0f}-{per_rep.max():.0f} (mean {per_rep.mean():.1f})"
        if len(per_rep)
        else "-",
        "cores": str(os.cpu_count()),
    }
