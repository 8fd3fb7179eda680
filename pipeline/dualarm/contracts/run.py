"""``RunResult``: what a run made, stage by stage, and the names of the stages."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from dualarm.contracts.execution import ExecutionLog
from dualarm.contracts.joint_path import JointPath
from dualarm.contracts.reference import CartesianReference
from dualarm.contracts.trajectory import JointTrajectory
from dualarm.contracts.verdict import Verdict

if TYPE_CHECKING:
    from dualarm.tasks import Task

#: Every stage, in the order a run runs them.
ALL_STAGES = ("path", "ik", "plan", "retime", "smooth", "approach", "execute")


@dataclass(frozen=True)
class RunResult:
    """What a run made: each stage's product (None for a stage that did not run) and the metrics.

    Attributes:
        task: the task.
        reference: the path stage's Cartesian reference.
        joint_path: the IK or plan stage's joint path.
        retimed: the retime stage's trajectory.
        smoothed: the smooth stage's trajectory.
        approached: the trajectory handed to execute, carrying its ``approach`` from the task's
            initial configuration (the approach stage's product).
        execution: the execute stage's log.
        metrics: ``<stage>.<name>`` -> value (units in the names).
        verdict: ``complete`` or ``violated`` with the failed checks (:mod:`dualarm.violations`); a
            run that fails raises instead (a recorded one is kept as ``failed``).
        stage_seconds: each stage's wall time [s] (with ``record``, the closing of the files, for a recorded run).
        directory: the run directory of a recorded run (:func:`record_run`), else None.
    """

    task: Task
    reference: CartesianReference | None = None
    joint_path: JointPath | None = None
    retimed: JointTrajectory | None = None
    smoothed: JointTrajectory | None = None
    approached: JointTrajectory | None = None
    execution: ExecutionLog | None = None
    metrics: dict[str, float] = field(default_factory=dict)
    verdict: Verdict = field(default_factory=lambda: Verdict("complete"))
    stage_seconds: dict[str, float] = field(default_factory=dict)
    directory: Path | None = None
