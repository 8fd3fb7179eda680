"""``dualarm run``: a task through the pipeline's stages into one recorded run.

Data flows one way, task -> reference -> joint path -> timed trajectory -> smoothed trajectory ->
executed log; each stage is a function from one contract to the next, and the recorder sees each
product once. With an IK method every stage runs by default; ``stages`` picks a subset, each with
the stage it needs.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from dataclasses import asdict, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from pipeline import __version__
from pipeline.errors import DualarmError
from pipeline.ik.metrics import arm_angles, consistency_metrics, ik_metrics
from pipeline.ik.pointwise import POINTWISE_METHODS
from pipeline.ik.tvgdd import LVI_TOLERANCE
from pipeline.paths import CartesianReference, build_reference
from pipeline.record.recorder import Recorder
from pipeline.record.run_dir import RunDirectory, package_versions, sha256_file
from pipeline.tasks import Task, load_task

if TYPE_CHECKING:
    from pipeline.plan.mcikrrt import PlanResult
    from pipeline.plan.problem import PlanningSettings

#: Every stage of the pipeline, in order (a run makes its joint path by ik or by plan).
ALL_STAGES = ("path", "ik", "plan", "retime", "smooth", "execute")
#: The stages one of which each stage needs (execute plays the smoothed trajectory when smooth
#: runs, else the retimed one).
NEEDS = {"ik": ("path",), "plan": ("path",), "retime": ("ik", "plan"), "smooth": ("retime",), "execute": ("retime",)}
#: Timings of the retime stage (the task file's ``retime.timing`` unless given).
TIMINGS = ("optimal", "task")
#: IK methods of the ``ik`` stage.
IK_METHODS = ("tvgdd", "pinv", "mc-inverse", *POINTWISE_METHODS)


def path_metrics(ref: CartesianReference) -> dict[str, float]:
    """``path.*`` metrics of a reference: samples, duration [s], repetitions, the longest hand path
    [m] and the highest hand speed [m/s]."""
    lengths = [float(np.linalg.norm(np.diff(h.position, axis=0), axis=1).sum()) for h in ref.hands.values()]
    speeds = [float(np.linalg.norm(h.linear_velocity, axis=1).max()) for h in ref.hands.values()]
    return {
        "path.samples": float(len(ref)),
        "path.duration_s": ref.duration_s,
        "path.repetitions": float(ref.rep.max() + 1),
        "path.length_max_m": max(lengths),
        "path.speed_max_m_s": max(speeds),
    }


def resolve_stages(stages: Sequence[str] | None, ik: str | None = None, planner: str | None = None) -> tuple[str, ...]:
    """Validate a stage list, in pipeline order. Without one: every stage but plan when an IK
    method is named, every stage but ik when a planner is, else the path stage alone."""
    from pipeline.plan import PLANNERS

    if ik is not None and ik not in IK_METHODS:
        raise DualarmError(f"unknown IK method '{ik}' (methods: {', '.join(IK_METHODS)})")
    if planner is not None and planner not in PLANNERS:
        raise DualarmError(f"unknown planner '{planner}' (planners: {', '.join(PLANNERS)})")
    if ik is not None and planner is not None:
        raise DualarmError("give either --ik METHOD or --planner PLANNER: both make the joint path")
    if not stages:
        return tuple(s for s in ALL_STAGES if s != "plan") if ik else tuple(s for s in ALL_STAGES if s != "ik") if planner else ("path",)
    for stage in stages:
        if stage not in ALL_STAGES:
            raise DualarmError(f"unknown stage '{stage}' (stages: {', '.join(ALL_STAGES)})")
        if stage in NEEDS and not any(need in stages for need in NEEDS[stage]):
            raise DualarmError(f"stage '{stage}' needs stage '{' or '.join(NEEDS[stage])}' (stages: {', '.join(ALL_STAGES)})")
    if "ik" in stages and "plan" in stages:
        raise DualarmError("stages 'ik' and 'plan' both make the joint path: choose one")
    if "ik" in stages and ik is None:
        raise DualarmError(f"stage 'ik' needs --ik METHOD (methods: {', '.join(IK_METHODS)})")
    if "plan" in stages and planner is None:
        raise DualarmError(f"stage 'plan' needs --planner PLANNER (planners: {', '.join(PLANNERS)})")
    return tuple(s for s in ALL_STAGES if s in stages)


def _manifest(task: Task, stages: tuple[str, ...], seed: int, command: Sequence[str], ik_settings: dict, back_half: dict) -> dict[str, object]:
    robot = task.robot
    robot_files = {robot.urdf.path.name: sha256_file(robot.urdf.path)}
    if robot.directory is not None:
        robot_files["robot.toml"] = sha256_file(robot.directory / "robot.toml")
    return {
        "dualarm_version": __version__,
        "command": list(command),
        "task": task.name,
        "task_file": str(task.file),
        "task_sha256": task.sha256,
        "robot": robot.name,
        "robot_dir": str(robot.directory),
        "robot_sha256": robot_files,
        "seed": seed,
        "stages": list(stages),
        "settings": {
            "path": {"control_period_s": task.spec.control_period_s, "time_scaling": "quintic", "repetitions": task.spec.repetitions},
            **({"ik": ik_settings} if "ik" in stages else {}),
            **{stage: settings for stage, settings in back_half.items() if stage in stages},
        },
        "packages": package_versions(),
    }


def _ik_settings(task: Task, ik: str | None, scheme: str, qp_backend: str, lvi_tolerance: float):
    """The IK stage's settings (recorded in the manifest) and the function that runs it."""
    from pipeline.ik.pinv import solve_pinv
    from pipeline.ik.tvgdd import SCHEMES, settings_for, solve_tvgdd

    if ik == "tvgdd":
        if scheme not in SCHEMES:
            raise DualarmError(f"unknown TV-GDD scheme '{scheme}' (schemes: {', '.join(SCHEMES)})")
        if qp_backend not in ("casadi", "lvi"):
            raise DualarmError(f"unknown QP backend '{qp_backend}' (backends: casadi, lvi)")
        if not lvi_tolerance > 0:
            raise DualarmError(f"the LVI tolerance must be positive, not {lvi_tolerance}")
        settings = replace(settings_for(task, scheme=scheme), lvi_tolerance=lvi_tolerance)
        return {"method": ik, "backend": qp_backend, **asdict(settings)}, lambda ref: solve_tvgdd(task, ref, settings, qp_backend)
    if ik == "mc-inverse":
        from pipeline.ik.mc_path import solve_mc_inverse

        return {"method": ik, **task.spec.arm_angle.model_dump()}, lambda ref: solve_mc_inverse(task, ref)
    if ik in POINTWISE_METHODS:
        from pipeline.ik.pointwise import pointwise_settings, solve_pointwise

        return {"method": ik, **pointwise_settings(ik)}, lambda ref: solve_pointwise(ik, task, ref)
    gain = settings_for(task).feedback_gain
    return {"method": ik, "feedback_gain": gain}, lambda ref: solve_pinv(task, ref, gain)


def _back_half_settings(task: Task, timing: str | None, gui: bool):
    """The retime, smooth and execute stages' settings (recorded in the manifest), and the
    simulation's. Imported only by runs that retime: toppra, ruckig and pybullet load slowly."""
    from pipeline.execute.simulate import ExecutionSettings
    from pipeline.stages import CONTROL_PERIOD_S

    execution = ExecutionSettings(gui=gui)
    return {
        "retime": {**task.spec.retime.model_dump(), "timing": timing or task.spec.retime.timing, "sample_period_s": CONTROL_PERIOD_S, "parametrizer": "ParametrizeConstAccel"},
        "smooth": {"method": "ruckig online tracking", "control_period_s": CONTROL_PERIOD_S},
        "execute": {**asdict(execution), "simulator": "pybullet"},
    }, execution


def _planning_problem(task: Task, settings: "PlanningSettings | None"):
    """The task's planning problem (imports PyBullet, and OMPL only when it plans with it)."""
    from pipeline.plan.problem import PlanningProblem, PlanningSettings

    return PlanningProblem(task, settings or PlanningSettings())


def run_task(
    task_file: str | Path,
    *,
    stages: Sequence[str] | None = None,
    ik: str | None = None,
    scheme: str = "mvn",
    qp_backend: str = "casadi",
    lvi_tolerance: float = LVI_TOLERANCE,
    out_dir: str | Path = "recordings",
    seed: int = 0,
    repetitions: int | None = None,
    timing: str | None = None,
    gui: bool = False,
    planner: str | None = None,
    planning: "PlanningSettings | None" = None,
    planned: "PlanResult | None" = None,
    command: Sequence[str] | None = None,
    progress: Callable[[str], None] = lambda stage: None,
) -> Path:
    """Run ``task_file`` through ``stages`` and record it; returns the run directory.

    The task and the options are validated before anything is written: a malformed task leaves no
    run behind. A stage that fails leaves a run marked ``failed`` and re-raises. ``repetitions``
    overrides the task file's, ``timing`` its ``retime.timing``; ``gui`` shows the execution in a
    PyBullet window. A task with Workspace Target Areas and no ``ik`` is planned, by ``planner``
    (default MCIKRRT) with ``planning`` settings from ``seed``; ``planned`` is a plan already
    made for it (``dualarm plan`` records its first successful trial so). ``progress`` is told each
    stage's name as it starts, and ``record`` when the files are being closed.
    """
    task = load_task(task_file, repetitions)
    if ik is None and planner is None and task.spec.wta and not (stages and "ik" in stages):
        planner = "mcikrrt"
    chosen = resolve_stages(stages, ik, planner)
    if timing is not None and timing not in TIMINGS:
        raise DualarmError(f"unknown timing '{timing}' (timings: {', '.join(TIMINGS)})")
    ik_settings, solve_ik = _ik_settings(task, ik, scheme, qp_backend, lvi_tolerance) if "ik" in chosen else ({}, None)
    back_half, execution = _back_half_settings(task, timing, gui) if "retime" in chosen else ({}, None)
    problem = _planning_problem(task, planning) if "plan" in chosen else None  # refuses a start in collision before writing
    if problem is not None:
        back_half = {"plan": {"planner": planner, **asdict(problem.settings)}, **back_half}
    np.random.seed(seed)
    run = RunDirectory.create(Path(out_dir), task.name, _manifest(task, chosen, seed, command or sys.argv, ik_settings, back_half))
    attachments = {task.file.name: task.text, task.robot.urdf.path.name: task.robot.urdf.path.read_text()}
    if task.robot.directory is not None:
        attachments["robot.toml"] = (task.robot.directory / "robot.toml").read_text()
    recorder = Recorder(run.staging, run.run_id, task.robot, attachments)
    metrics: dict[str, float] = {}
    try:
        progress("path")
        recorder.robot_state("path", 0.0, task.initial_q)
        recorder.environment(task.spec.environment)
        reference = build_reference(task)
        recorder.reference(reference)
        metrics.update(path_metrics(reference))
        end = reference.duration_s
        if solve_ik is not None:
            progress("ik")
            joint_path = solve_ik(reference)
            angles = arm_angles(joint_path, task)
            recorder.joint_path(joint_path, task.velocity_limits(joint_path.joint_names), angles)
            metrics.update(ik_metrics(joint_path, task))
            metrics.update(consistency_metrics(joint_path, reference, angles))
        if problem is not None:
            from pipeline.plan.stage import plan_stage

            progress("plan")
            joint_path, stage_metrics = plan_stage(task, recorder, problem, planner, seed, planned)
            metrics.update(stage_metrics)
        if "retime" in chosen:  # smooth and execute need it (NEEDS): their imports are made here
            from pipeline.stages import execute_stage, retime_stage, smooth_stage

            progress("retime")
            trajectory, stage_metrics = retime_stage(task, joint_path, recorder, timing)
            metrics.update(stage_metrics)
            end = trajectory.duration_s
        if "smooth" in chosen:
            progress("smooth")
            trajectory, stage_metrics = smooth_stage(task, trajectory, recorder)
            metrics.update(stage_metrics)
            end = trajectory.duration_s
        if "execute" in chosen:
            progress("execute")
            _, stage_metrics = execute_stage(task, trajectory, recorder, execution)
            metrics.update(stage_metrics)
        recorder.metrics(metrics, end)
        progress("record")
    except BaseException as exc:
        message = str(exc) if isinstance(exc, DualarmError) else f"{type(exc).__name__}: {exc}"
        run.conclude(message)
        recorder.close(run.manifest)
        run.finish(None)
        raise
    finally:
        if problem is not None:
            problem.close()
    run.conclude(None)
    recorder.close(run.manifest)
    return run.finish(metrics)
