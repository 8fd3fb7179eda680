"""``dualarm run``: a task through the pipeline's stages into one recorded run.

Data flows one way, task -> reference -> joint path -> timed trajectory -> smoothed trajectory ->
executed log; each stage is a function from one contract to the next, and the recorder sees each
product once. Stages that have not landed yet are refused by name.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import asdict, replace
from pathlib import Path

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

#: Every stage of the pipeline, in order.
ALL_STAGES = ("path", "ik", "retime", "smooth", "execute")
#: The stages this version can run.
AVAILABLE_STAGES = ("path", "ik")
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


def resolve_stages(stages: Sequence[str] | None, ik: str | None = None) -> tuple[str, ...]:
    """Validate a stage list, in pipeline order. Without one: the path stage, and IK when a method
    is named."""
    if ik is not None and ik not in IK_METHODS:
        raise DualarmError(f"unknown IK method '{ik}' (methods: {', '.join(IK_METHODS)})")
    if not stages:
        return ("path", "ik") if ik else ("path",)
    if "ik" in stages and ik is None:
        raise DualarmError(f"stage 'ik' needs --ik METHOD (methods: {', '.join(IK_METHODS)})")
    for stage in stages:
        if stage not in ALL_STAGES:
            raise DualarmError(f"unknown stage '{stage}' (stages: {', '.join(ALL_STAGES)})")
        if stage not in AVAILABLE_STAGES:
            raise DualarmError(f"stage '{stage}' is not available yet (available: {', '.join(AVAILABLE_STAGES)})")
    return tuple(s for s in ALL_STAGES if s in stages)


def _manifest(task: Task, stages: tuple[str, ...], seed: int, command: Sequence[str], ik_settings: dict) -> dict[str, object]:
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
    command: Sequence[str] | None = None,
) -> Path:
    """Run ``task_file`` through ``stages`` and record it; returns the run directory.

    The task and the options are validated before anything is written: a malformed task leaves no
    run behind. A stage that fails leaves a run marked ``failed`` and re-raises. ``repetitions``
    overrides the task file's.
    """
    task = load_task(task_file, repetitions)
    chosen = resolve_stages(stages, ik)
    ik_settings, solve_ik = _ik_settings(task, ik, scheme, qp_backend, lvi_tolerance) if "ik" in chosen else ({}, None)
    np.random.seed(seed)
    run = RunDirectory.create(Path(out_dir), task.name, _manifest(task, chosen, seed, command or sys.argv, ik_settings))
    attachments = {task.file.name: task.text, task.robot.urdf.path.name: task.robot.urdf.path.read_text()}
    if task.robot.directory is not None:
        attachments["robot.toml"] = (task.robot.directory / "robot.toml").read_text()
    recorder = Recorder(run.staging, run.run_id, task.robot, attachments)
    metrics: dict[str, float] = {}
    try:
        recorder.robot_state("path", 0.0, task.initial_q)
        reference = build_reference(task)
        recorder.reference(reference)
        metrics.update(path_metrics(reference))
        if solve_ik is not None:
            joint_path = solve_ik(reference)
            angles = arm_angles(joint_path, task)
            recorder.joint_path(joint_path, task.velocity_limits(joint_path.joint_names), angles)
            metrics.update(ik_metrics(joint_path, task))
            metrics.update(consistency_metrics(joint_path, reference, angles))
        recorder.metrics(metrics, reference.duration_s)
    except BaseException as exc:
        message = str(exc) if isinstance(exc, DualarmError) else f"{type(exc).__name__}: {exc}"
        run.conclude(message)
        recorder.close(run.manifest)
        run.finish(None)
        raise
    run.conclude(None)
    recorder.close(run.manifest)
    return run.finish(metrics)
