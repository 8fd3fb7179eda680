"""``dualarm bench pipeline``: where the time of a whole run goes, stage by stage.

Each task runs once through every stage, as ``dualarm run TASK --ik METHOD`` does (recording
included), in this process. The recorder, like every sink, notes when each stage begins; the
wall-clock time from one stage's start to the next's is that stage's, recording of its product
included, and ``record`` is the closing of the files (the MCAP summary, the Rerun blueprint, the
manifest). Shares are of the run's total. Runs go to a temporary directory, removed afterwards.

For each MC-Inverse run whose task chooses the arm angle with ``mode = "auto"``, the arm-angle
search alone (:func:`dualarm.ik.analytic.mc_path._auto`, inside the ik stage) is timed again per arm on the
same inputs, after one call that loads its compiled Function: the median of
:data:`SEARCH_REPEATS` calls, without and with the collision check the ik stage gives it
(:class:`~dualarm.plan.clearance.ArmClearance`, built once before the timed calls; its build timed apart).

Never used by the test suite: wall-clock numbers depend on the machine.
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from dualarm.run import record_run
from dualarm.tasks import Task, load_task

#: (task file, IK method) of the benchmark: the issue's three tasks with their papers' methods.
DEFAULT_RUNS = (
    ("tasks/triangle.toml", "mc-inverse"),
    ("tasks/circle.toml", "mc-inverse"),
    ("tasks/ball_game.toml", "tvgdd"),
)
#: The parts of a run, in order.
PARTS = ("path", "ik", "retime", "smooth", "execute", "record")
#: Timed calls of the arm-angle search per arm.
SEARCH_REPEATS = 5


@dataclass(frozen=True)
class PipelineTiming:
    """One run's time per part [s] and its motion's duration [s].

    For an MC-Inverse run with ``auto`` arm angles, each arm's search: hand -> (median time [s], the same with
    the collision check [s], the check's build [s], samples of the first repetition, grid angles).
    """

    task: str
    ik: str
    seconds: dict[str, float]
    motion_s: float
    search: dict[str, tuple[float, float, float, int, int]] = field(default_factory=dict)

    @property
    def total_s(self) -> float:
        """Wall-clock time of the whole run [s]."""
        return sum(self.seconds.values())


def bench_pipeline(
    runs: Sequence[tuple[str, str]] = DEFAULT_RUNS, progress: Callable[[str], None] = lambda text: None
) -> list[PipelineTiming]:
    """Run each (task file, IK method) once through every stage and time its parts."""
    timings = []
    with tempfile.TemporaryDirectory(prefix="dualarm-bench-") as out:
        for task_file, ik in runs:
            task = load_task(task_file)

            def on_stage(stage: str, task: Task = task, ik: str = ik) -> None:  # this iteration's task and method
                progress(f"{task.name} ({ik}): {stage}")

            run = record_run(task, ik, out_dir=out, progress=on_stage)
            search = search_seconds(task) if ik == "mc-inverse" else {}
            timings.append(
                PipelineTiming(
                    task.name, ik, run.stage_seconds, float(run.metrics.get("execute.duration_s", 0.0)), search
                )
            )
    return timings


def search_seconds(task) -> dict[str, tuple[float, float, float, int, int]]:
    """Each arm's ``auto`` arm-angle search on ``task``'s path.

    None unless its ``[arm_angle]`` mode is ``auto``. hand -> (median of :data:`SEARCH_REPEATS`
    calls [s], the same with the collision check [s], the check's build [s], samples of the first
    repetition, grid angles).
    """
    from dualarm.ik.analytic import mc_path
    from dualarm.paths.build import build_reference
    from dualarm.plan.clearance import ArmClearance

    spec = mc_path.settings_for(task)
    if spec.mode != "auto":
        return {}
    reference = build_reference(task)
    samples = int(np.sum(reference.rep == reference.rep[0]))
    searches = {}
    for arm, solver, initial in mc_path.arm_solvers(
        task.robot, reference, task.robot.configuration(task.initial_q, "q0"), spec
    ):
        inputs = (solver, arm.targets, reference, initial, arm.q0, spec, arm.hand)
        mc_path._auto(*inputs)  # loads the compiled Function
        with ArmClearance(task) as clearance:
            start = time.perf_counter()
            clearance(arm.hand, arm.q0[None])  # builds the arm's checker
            build = time.perf_counter() - start
            clear = mc_path.arm_clearance(clearance, arm.hand)
            times: dict[bool, list[float]] = {False: [], True: []}
            for _ in range(SEARCH_REPEATS):
                for checked in (False, True):
                    start = time.perf_counter()
                    mc_path._auto(*inputs, clear if checked else None)
                    times[checked].append(time.perf_counter() - start)
        searches[arm.hand] = (
            float(np.median(times[False])),
            float(np.median(times[True])),
            build,
            samples,
            len(mc_path.AUTO_GRID),
        )
    return searches
