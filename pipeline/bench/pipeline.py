"""``dualarm bench pipeline``: where the time of a whole run goes, stage by stage.

Each task runs once through every stage, as ``dualarm run TASK --ik METHOD`` does (recording
included), in this process. The recorder, like every sink, notes when each stage begins; the
wall-clock time from one stage's start to the next's is that stage's, recording of its product
included, and ``record`` is the closing of the files (the MCAP summary, the Rerun blueprint, the
manifest). Shares are of the run's total. Runs go to a temporary directory, removed afterwards.

Never used by the test suite: wall-clock numbers depend on the machine.
"""

from __future__ import annotations

import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from dualarm.run import record_run
from dualarm.tasks import load_task

#: (task file, IK method) of the benchmark: the issue's three tasks with their papers' methods.
DEFAULT_RUNS = (("tasks/triangle.toml", "mc-inverse"), ("tasks/circle.toml", "mc-inverse"), ("tasks/ball_game.toml", "tvgdd"))
#: The parts of a run, in order.
PARTS = ("path", "ik", "retime", "smooth", "execute", "record")


@dataclass(frozen=True)
class PipelineTiming:
    """One run's time per part [s] and its motion's duration [s]."""

    task: str
    ik: str
    seconds: dict[str, float]
    motion_s: float

    @property
    def total_s(self) -> float:
        """Wall-clock time of the whole run [s]."""
        return sum(self.seconds.values())


def bench_pipeline(runs: Sequence[tuple[str, str]] = DEFAULT_RUNS, progress: Callable[[str], None] = lambda text: None) -> list[PipelineTiming]:
    """Run each (task file, IK method) once through every stage and time its parts."""
    timings = []
    with tempfile.TemporaryDirectory(prefix="dualarm-bench-") as out:
        for task_file, ik in runs:
            task = load_task(task_file)
            run = record_run(task, ik, out_dir=out, progress=lambda stage: progress(f"{task.name} ({ik}): {stage}"))
            timings.append(PipelineTiming(task.name, ik, run.stage_seconds, float(run.metrics.get("execute.duration_s", 0.0))))
    return timings
