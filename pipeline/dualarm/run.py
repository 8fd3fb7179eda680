"""Running a task through the pipeline: in memory (:func:`run_task`) or recorded (:func:`record_run`).

Data flows one way, task -> reference -> joint path -> timed trajectory -> smoothed trajectory ->
executed log; each stage (:mod:`dualarm.stages`) is a function from one contract to the next, and
the sink sees each product once. With an IK method every stage but plan runs by default, with a
planner every stage but ik; ``stages`` picks a subset, each with the stage it needs.

    >>> import dualarm
    >>> result = dualarm.run_task("triangle", "mc-inverse", stages=("path", "ik"))  # doctest: +SKIP
    >>> result.metrics["ik.rep_joint_deviation_max_rad"]  # doctest: +SKIP
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from dualarm.contracts.run import ALL_STAGES, RunResult
from dualarm.contracts.trajectory import JointTrajectory
from dualarm.contracts.verdict import Checks, Verdict, Violation
from dualarm.errors import DualarmError, StageError
from dualarm.methods import IK_METHODS, PLANNERS, refuse_unsuited
from dualarm.methods import method as registered
from dualarm.paths import CartesianReference
from dualarm.record.run_dir import RunDirectory, package_versions, sha256_file
from dualarm.record.sink import NullSink, Sink, record_level, recorded_stages
from dualarm.stages import ApproachStage, ExecuteStage, IkStage, PathStage, PlanStage, RetimeStage, SmoothStage, Stage
from dualarm.tasks import Task, load_task
from dualarm.tasks.schema import Retime
from dualarm.version import __version__

if TYPE_CHECKING:
    from dualarm.execute.simulate import ExecutionSettings

#: Every stage of the pipeline, in order (a run makes its joint path by ik or by plan).
#: The stages one of which each stage needs (execute plays the smoothed trajectory when smooth
#: runs, else the retimed one, after the approach from the task's initial configuration when
#: ``approach`` runs).
NEEDS = {
    "ik": ("path",),
    "plan": ("path",),
    "retime": ("ik", "plan"),
    "smooth": ("retime",),
    "approach": ("retime",),
    "execute": ("retime",),
}
#: Timings of the retime stage (a task's ``retime.timing``).
TIMINGS = ("jerk-limited", "optimal", "task")


#: Which RunResult field each stage's product fills.
_PRODUCT = {
    "path": "reference",
    "ik": "joint_path",
    "plan": "joint_path",
    "retime": "retimed",
    "smooth": "smoothed",
    "approach": "approached",
    "execute": "execution",
}


def resolve_stages(stages: Sequence[str] | None, ik: str | None = None, planner: str | None = None) -> tuple[str, ...]:
    """Validate a stage list, in pipeline order.

    Without one: every stage but plan when an IK method is named, every stage but ik when a planner
    is, else the path stage alone.

    Raises:
        DualarmError: an unknown stage or method, or a stage without one it needs.
    """
    if ik is not None:
        registered(ik, "ik")
    if planner is not None:
        registered(planner, "planner")
    if ik is not None and planner is not None:
        raise DualarmError("give either --ik METHOD or --planner PLANNER: both make the joint path")
    if not stages:
        return (
            tuple(s for s in ALL_STAGES if s != "plan")
            if ik
            else tuple(s for s in ALL_STAGES if s != "ik")
            if planner
            else ("path",)
        )
    for stage in stages:
        if stage not in ALL_STAGES:
            raise DualarmError(f"unknown stage '{stage}' (stages: {', '.join(ALL_STAGES)})")
        if stage in NEEDS and not any(need in stages for need in NEEDS[stage]):
            raise DualarmError(
                f"stage '{stage}' needs stage '{' or '.join(NEEDS[stage])}' (stages: {', '.join(ALL_STAGES)})"
            )
    if "ik" in stages and "plan" in stages:
        raise DualarmError("stages 'ik' and 'plan' both make the joint path: choose one")
    if "ik" in stages and ik is None:
        raise DualarmError(f"stage 'ik' needs --ik METHOD (methods: {', '.join(IK_METHODS)})")
    if "plan" in stages and planner is None:
        raise DualarmError(f"stage 'plan' needs --planner PLANNER (planners: {', '.join(PLANNERS)})")
    return tuple(s for s in ALL_STAGES if s in stages)


def _as_task(task: Task | str | Path) -> Task:
    return task if isinstance(task, Task) else load_task(task)


def default_method(task: Task, method: str | None, stages: Sequence[str] | None = None) -> str | None:
    """``method``, or ``mcikrrt`` for a task with Workspace Target Areas when none is given.

    Such a task is planned, unless an ``ik`` stage is asked for.
    """
    if method is None and task.spec.wta and not (stages and "ik" in stages):
        return "mcikrrt"
    return method


def build_stages(
    task: Task,
    method: str | None = None,
    *,
    settings: Any = None,
    stages: Sequence[str] | None = None,
    retime: Retime | None = None,
    execution: ExecutionSettings | None = None,
    checks: Checks | None = None,
    seed: int = 0,
) -> tuple[Stage, ...]:
    """The stages of a run of ``task``, validated before anything runs.

    Args:
        task: the task.
        method: an IK method or a planner of :data:`dualarm.methods.METHODS`; a task with Workspace
            Target Areas and no method (and no ``ik`` stage asked for) is planned with ``mcikrrt``.
        settings: the method's settings (default: from the task, see :meth:`Method.settings_for`).
        stages: the stages to run (default: see :func:`resolve_stages`).
        retime: the retime stage's settings (default the task's ``[retime]`` table).
        execution: the simulation's settings (default :class:`~dualarm.execute.simulate.ExecutionSettings`).
        checks: the bounds the run is judged against (default :class:`~dualarm.contracts.verdict.Checks`).
        seed: the planner's seed.

    Raises:
        DualarmError: an unknown stage or method, settings of the wrong class, a planning start in collision.
    """
    method = default_method(task, method, stages)
    m = registered(method) if method is not None else None
    chosen = resolve_stages(
        stages, m.name if m and m.kind == "ik" else None, m.name if m and m.kind == "planner" else None
    )
    if m is not None:
        if m.kind == "ik":
            refuse_unsuited(m, task.robot, task.spec.hands)  # the robot first: its settings may not apply to it either
        settings = m.settings_for(task) if settings is None else settings
        if not isinstance(settings, m.settings_type):
            raise DualarmError(f"{m.name} takes {m.settings_type.__name__} settings, not {type(settings).__name__}")
    checks = checks or Checks()
    built: list[Stage[Any, Any]] = [PathStage(task)]
    if "ik" in chosen and m is not None:
        built.append(IkStage(task, m, settings, checks, retimed="retime" in chosen, executed="execute" in chosen))
    if "retime" in chosen:  # the back half's imports (toppra, ruckig, pybullet) wait until it runs
        built.append(RetimeStage(task, retime or task.spec.retime))
    if "smooth" in chosen:
        built.append(SmoothStage(task, (retime or task.spec.retime).timing))
    if "approach" in chosen:
        built.append(ApproachStage(task))
    if "execute" in chosen:
        from dualarm.execute.simulate import ExecutionSettings

        built.append(ExecuteStage(task, execution or ExecutionSettings(), checks))
    if "plan" in chosen and m is not None:  # last: it opens a PyBullet client, refusing a start in collision
        from dualarm.plan.problem import PlanningProblem

        built.insert(1, PlanStage(PlanningProblem(task, settings), m.name, seed))
    return tuple(built)


def run_stages(
    task: Task, stages: Sequence[Stage[Any, Any]], sink: Sink | None = None, violations: list[Violation] | None = None
) -> RunResult:
    """Run ``stages`` in order on ``task``, handing every product to ``sink``, then the metrics.

    ``sink`` is by default a :class:`~dualarm.record.sink.NullSink`. Each product is judged (the verdict).

    Stages holding resources (the plan stage's PyBullet client) are closed afterwards, whatever
    happens. ``violations``, when given, receives each stage's violations as they are found, so a
    caller still has them when a later stage raises.
    """
    sink = sink if sink is not None else NullSink()
    products: dict[str, Any] = {}
    metrics: dict[str, float] = {}
    violations = [] if violations is None else violations
    product: Any = task
    end = 0.0
    try:
        for stage in stages:
            product, stage_metrics = stage(product, sink)
            products[_PRODUCT[stage.name]] = product
            metrics.update(stage_metrics)
            violations += stage.violations(product)
            if isinstance(product, (CartesianReference, JointTrajectory)):
                end = product.duration_s
        sink.metrics(metrics, end)
    finally:
        _close(stages)
    seconds = sink.stage_seconds if isinstance(sink, NullSink) else {}
    return RunResult(task=task, metrics=metrics, verdict=Verdict.of(violations), stage_seconds=seconds, **products)


def run_task(
    task: Task | str | Path,
    method: str | None = None,
    *,
    settings: Any = None,
    stages: Sequence[str] | None = None,
    retime: Retime | None = None,
    execution: ExecutionSettings | None = None,
    seed: int = 0,
    sink: Sink | None = None,
) -> RunResult:
    """Run ``task`` through the pipeline in memory; with ``sink`` the products go to it too.

    ``task`` is a :class:`Task`, a task file or a shipped task's name. See :func:`record_run` for files.

    The arguments are those of :func:`build_stages`; the result holds every product and the metrics.
    """
    task = _as_task(task)
    return run_stages(
        task,
        build_stages(task, method, settings=settings, stages=stages, retime=retime, execution=execution, seed=seed),
        sink,
    )


def record_run(
    task: Task | str | Path,
    method: str | None = None,
    *,
    out_dir: str | Path = "recordings",
    command: Sequence[str] | None = None,
    progress: Callable[[str], None] | None = None,
    record: str = "full",
    **options: Any,
) -> RunResult:
    """Run ``task`` as :func:`run_task` does and record it in ``out_dir/<task>/<run-id>/``.

    ``options`` are :func:`run_task`'s keyword arguments. The files are run.mcap, run.rrd, manifest.json
    and metrics.json; the result's ``directory`` is the run directory.

    ``command`` is recorded in the manifest (default ``sys.argv``); ``progress`` is told each
    stage's name as it starts, and ``record`` when the files are being closed. ``record`` is how
    much is recorded (:data:`~dualarm.record.sink.RECORD_LEVELS`): ``full``; ``ik``, run.mcap and
    run.rrd holding the path and ik (or plan) stages' products only; ``metrics``, no run.mcap and
    no run.rrd. Every stage runs and is judged whatever the level: the metrics and the verdict are
    the same.

    The task and the options are validated before anything is written: a malformed task leaves no
    run behind. The manifest holds the verdict (``status``, ``violations``) and the level
    (``record``); a stage that fails leaves a run marked ``failed`` and re-raises.

    Raises:
        InvalidArgumentError: an unknown ``record`` level (before anything runs).
    """
    record_level(record)
    task = _as_task(task)
    return record_stages(
        task,
        build_stages(task, method, **options),
        out_dir=out_dir,
        seed=options.get("seed", 0),
        command=command,
        progress=progress,
        record=record,
    )


def record_stages(
    task: Task,
    stages: Sequence[Stage[Any, Any]],
    *,
    out_dir: str | Path = "recordings",
    seed: int = 0,
    command: Sequence[str] | None = None,
    progress: Callable[[str], None] | None = None,
    record: str = "full",
) -> RunResult:
    """Run ``stages`` on ``task`` into a new recorded run, at recording level ``record``.

    See :func:`record_run`.
    """
    try:
        record_level(record)
        run = RunDirectory.create(Path(out_dir), task.name, _manifest(task, stages, seed, command or sys.argv, record))
    except BaseException:
        _close(stages)
        raise
    try:
        recorder = _recorder(task, run, stages, record, progress)
    except BaseException as exc:
        # stopped (Ctrl-C, SIGTERM) before any stage ran: kept as failed, without the recorder's unfinished files
        _close(stages)
        for unfinished in run.staging.iterdir():
            unfinished.unlink()
        run.conclude(Verdict.failure(str(exc) if isinstance(exc, DualarmError) else f"{type(exc).__name__}: {exc}"))
        run.finish(None)
        raise
    found: list[Violation] = []
    try:
        result = run_stages(task, stages, recorder, found)
        recorder.begin("record")
    except BaseException as exc:
        refused = exc.violations if isinstance(exc, StageError) else ()
        run.conclude(
            Verdict.failure(
                str(exc) if isinstance(exc, DualarmError) else f"{type(exc).__name__}: {exc}", [*found, *refused]
            )
        )
        recorder.close(run.manifest)
        directory = run.finish(None)
        exc.add_note(f"the run is kept as failed in {directory}")
        if isinstance(exc, StageError):
            exc.run_directory = directory
        raise
    run.manifest["settings"] = _settings(stages, result)  # with what the IK method chose (MC-Inverse's arm angles)
    run.conclude(result.verdict)
    recorder.close(run.manifest)
    return replace(result, directory=run.finish(result.metrics), stage_seconds=recorder.stage_seconds)


def _recorder(
    task: Task,
    run: RunDirectory,
    stages: Sequence[Stage[Any, Any]],
    record: str,
    progress: Callable[[str], None] | None,
) -> NullSink:
    """The sink that writes the run's files at level ``record``.

    A Recorder of the recorded stages (it drops the others' products), or (``metrics``) a sink that
    writes nothing.
    """
    kept = recorded_stages(record, [s.name for s in stages])
    if record == "metrics":
        return NullSink(on_begin=progress)
    from dualarm.record.recorder import Recorder

    return Recorder(run.staging, run.run_id, task.robot, _attachments(task), stages=kept, on_begin=progress)


def _close(stages: Sequence[Stage[Any, Any]]) -> None:
    for stage in stages:
        close = getattr(stage, "close", None)
        if close is not None:
            close()


def _attachments(task: Task) -> dict[str, str]:
    """The task's source, the URDF and robot.toml, by file name."""
    attachments = {task.source_name: task.text, task.robot.urdf.path.name: task.robot.urdf.path.read_text()}
    if task.robot.directory is not None:
        attachments["robot.toml"] = (task.robot.directory / "robot.toml").read_text()
    return attachments


def _settings(stages: Sequence[Stage[Any, Any]], result: RunResult | None = None) -> dict[str, dict[str, Any]]:
    """Each stage's settings by name, in pipeline order.

    With ``result``, the IK stage's also hold what its method chose.

    What the method chose while running is its joint path's ``chosen`` (MC-Inverse's arm angles).
    """
    records = {s.name: s.settings_record() for s in sorted(stages, key=lambda s: ALL_STAGES.index(s.name))}
    if result is not None and result.joint_path is not None and "ik" in records:
        records["ik"] = {**records["ik"], **result.joint_path.chosen}
    return records


def _manifest(
    task: Task, stages: Sequence[Stage[Any, Any]], seed: int, command: Sequence[str], record: str = "full"
) -> dict[str, object]:
    robot = task.robot
    robot_files = {robot.urdf.path.name: sha256_file(robot.urdf.path)}
    if robot.directory is not None:
        robot_files["robot.toml"] = sha256_file(robot.directory / "robot.toml")
    ordered = sorted(stages, key=lambda s: ALL_STAGES.index(s.name))
    return {
        "dualarm_version": __version__,
        "command": list(command),
        "task": task.name,
        "task_file": str(task.file) if task.file is not None else "<dict>",
        "task_sha256": task.sha256,
        "robot": robot.name,
        "robot_dir": str(robot.directory),
        "robot_sha256": robot_files,
        "seed": seed,
        "stages": [s.name for s in ordered],
        "record": record,
        "settings": _settings(stages),
        "packages": package_versions(),
    }
