"""``dualarm plan``: repeated planning trials on one task, their table and summary.

And the first successful plan recorded as a run.

Trial ``i`` plans from seed ``seed + i`` on one planning problem (one collision checker for all
trials). ``DIR/plan_trials.csv`` has a row per trial; ``DIR/plan_summary.json`` the success rate,
the planning time's median, 95th percentile and mean, the medians of nodes, goals, collision
checks and path length, the mean time of one collision check, the paper's figure, and the run
directory of the recorded plan. Both files are written whole or not at all (written beside, then
renamed). ``DIR`` is a plan directory and the recordings directory a recordings one, both claimed
before the first trial (:func:`~dualarm.record.run_dir.claim_output_dir`): a directory holding
files dualarm did not write is refused, and ``DIR`` stays locked until the command ends.
"""

from __future__ import annotations

import contextlib
import json
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd

from dualarm.contracts.verdict import Verdict
from dualarm.errors import StageError
from dualarm.plan.problem import PlanningProblem, PlanningSettings
from dualarm.record.run_dir import claim_output_dir, write_whole
from dualarm.settings import as_record
from dualarm.tasks import Task, load_task

#: Li & Liang's average planning time for their bowl grasp [s].
PAPER_PLANNING_TIME_S = 4.21088
#: The default settings of :func:`run_trials` (frozen: one instance serves every call).
_DEFAULT_SETTINGS = PlanningSettings()


@dataclass(frozen=True)
class TrialsResult:
    """What ``dualarm plan`` produced.

    Attributes:
        table: one row per trial (the CSV's contents).
        summary: the JSON summary's contents.
        directory: where the CSV and the JSON are.
        run: the recorded run of the first successful plan (None when no trial succeeded).
        verdict: that run's verdict (None when no trial succeeded).
    """

    table: pd.DataFrame
    summary: dict
    directory: Path
    run: Path | None
    verdict: Verdict | None = None


def run_trials(
    task_file: str | Path,
    planner: str,
    trials: int,
    seed: int,
    out_dir: Path,
    settings: PlanningSettings = _DEFAULT_SETTINGS,
    recordings: Path = Path("recordings"),
    command: list[str] | None = None,
    progress: Callable[[int, int], None] = lambda done, total: None,
    robot: str | Path | None = None,
) -> TrialsResult:
    """Plan ``trials`` times with ``planner``, write the CSV and the summary into ``out_dir``.

    And record the first successful plan through retime, smooth and execute under ``recordings``.

    ``progress`` is told the trials done and the total after each trial; ``robot`` (a robot
    directory or shipped robot's name) replaces the one the task names.

    Raises:
        OutputError: ``out_dir`` or ``recordings`` cannot be used (before any trial).
    """
    task = load_task(task_file, robot=robot)
    with contextlib.ExitStack() as claims:
        claims.enter_context(claim_output_dir(out_dir, "plan"))
        claims.enter_context(claim_output_dir(recordings, "recordings"))
        return _run_trials(task, planner, trials, seed, Path(out_dir), settings, recordings, command, progress)


def _run_trials(
    task: Task,
    planner: str,
    trials: int,
    seed: int,
    out_dir: Path,
    settings: PlanningSettings,
    recordings: Path,
    command: list[str] | None,
    progress: Callable[[int, int], None],
) -> TrialsResult:
    from dualarm.run import build_stages, record_stages
    from dualarm.stages import PlanStage

    rows, first = [], None
    with PlanningProblem(task, settings) as problem:
        for i in range(trials):
            result = problem.solve(planner, seed + i)
            rows.append(
                {
                    "trial": i,
                    "seed": seed + i,
                    "planner": planner,
                    "success": result.success,
                    "planning_time_s": result.planning_time_s,
                    "nodes": result.nodes,
                    "goals": result.goals,
                    "collision_checks": result.collision_checks,
                    "path_length_rad": result.path_length_rad,
                    "raw_path_length_rad": result.raw_path_length_rad,
                    "waypoints": len(result.path),
                    "reason": result.reason,
                }
            )
            if result.success and first is None:
                first = (seed + i, result)
            progress(i + 1, trials)
        check_time_s = problem.checker.check_time_s / max(problem.checker.checks, 1)
    table = pd.DataFrame(rows)
    ok = table[table.success]
    times = table.planning_time_s.to_numpy()
    summary = {
        "task": task.name,
        "planner": planner,
        "trials": trials,
        "seed": seed,
        "success_rate": float(table.success.mean()),
        "planning_time_median_s": float(np.median(times)),
        "planning_time_p95_s": float(np.percentile(times, 95)),
        "planning_time_mean_s": float(times.mean()),
        "successful_planning_time_median_s": float(ok.planning_time_s.median()) if len(ok) else None,
        "nodes_median": float(table.nodes.median()),
        "goals_median": float(table.goals.median()),
        "collision_checks_median": float(table.collision_checks.median()),
        "collision_check_time_mean_s": check_time_s,
        "path_length_median_rad": float(ok.path_length_rad.median()) if len(ok) else None,
        "paper_planning_time_mean_s": PAPER_PLANNING_TIME_S,
        "settings": as_record(settings),
        "failures": sorted(set(table.reason[~table.success])),
        "run": None,
    }
    run: Path | None = None
    if first is not None:
        trial_seed, result = first
        stages = build_stages(task, planner, settings=settings, seed=trial_seed)
        stages = tuple(replace(s, planned=result) if isinstance(s, PlanStage) else s for s in stages)
        try:
            recorded = record_stages(task, stages, out_dir=recordings, seed=trial_seed, command=command)
            run, verdict = recorded.directory, recorded.verdict
        except StageError as exc:  # the plan could not be played (refused before execution, ...): a failed run, kept
            verdict = Verdict.failure(str(exc), exc.violations)
            run = exc.run_directory
        summary["run"] = str(run)
        summary["run_seed"] = trial_seed
        summary["run_status"] = verdict.status
        summary["run_first_violation"] = verdict.first
    write_whole(out_dir / "plan_trials.csv", table.to_csv(index=False))
    write_whole(out_dir / "plan_summary.json", json.dumps(summary, indent=2) + "\n")
    return TrialsResult(table, summary, out_dir, run, verdict if first is not None else None)
