"""``dualarm run`` and ``dualarm plan``: a task through the pipeline, recorded."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer

from dualarm.cli.app import _update, app, err, out, user_errors
from dualarm.cli.options import (
    MAX_TIMEOUT_S,
    MAX_TRIALS,
    RECORD_HELP,
    _execution,
    _method,
    _out_path,
    _record,
    _seed,
    _stages,
    _within,
)
from dualarm.errors import DualarmError, excerpt
from dualarm.methods import IK_METHODS


@app.command()
@user_errors
def run(
    task: Annotated[
        Path, typer.Argument(help="Task file (TOML), e.g. tasks/triangle.toml, or a shipped task's name (triangle).")
    ],
    stages: Annotated[
        str | None,
        typer.Option(
            help=(
                "Comma-separated stages to run: path, ik or plan, retime, smooth, approach (from the task's "
                "initial configuration to the motion's start), execute (default: all of them when --ik or "
                "--planner is given, else path)."
            )
        ),
    ] = None,
    ik: Annotated[
        str | None,
        typer.Option(
            "--ik",
            help="IK method of the ik stage: tvgdd, pinv, mc-inverse, sew, trac-ik, pybullet, dls-svd or ikfast-style.",
        ),
    ] = None,
    scheme: Annotated[
        str,
        typer.Option(
            help="TV-GDD scheme: mvn (minimum velocity norm), rmp (repetitive motion) or mke (minimum kinetic energy)."
        ),
    ] = "mvn",
    qp_backend: Annotated[
        str,
        typer.Option(
            help="TV-GDD QP solver: casadi (DAQP through CasADi conic) or lvi (the paper's projection solver)."
        ),
    ] = "casadi",
    lvi_tolerance: Annotated[
        float,
        typer.Option(
            help=(
                "Stop of the lvi backend on ||eps(u)||_2 (the paper's 1e-5; its velocity error can be ~35x this, "
                "see docs)."
            )
        ),
    ] = 1e-5,
    out_text: Annotated[
        str,
        typer.Option(
            "--out",
            help=(
                "Directory that receives <task>/<run-id>/ (a recordings directory: runs are added, nothing in it "
                "is deleted or overwritten)."
            ),
        ),
    ] = "recordings",
    seed: Annotated[int, typer.Option(help="Random seed (an integer >= 0), recorded in the manifest.")] = 0,
    reps: Annotated[int | None, typer.Option(min=1, help="Repetitions (default: the task file's).")] = None,
    timing: Annotated[
        str | None,
        typer.Option(
            help=(
                "Retime: jerk-limited (on the path, within the velocity, acceleration and jerk limits), "
                "optimal (TOPP-RA, then Ruckig tracking) or task (the task's own timing, checked against "
                "the limits); default: the task file's retime.timing."
            )
        ),
    ] = None,
    gui: Annotated[
        bool, typer.Option("--gui", help="Show the execution in a PyBullet window (needs a display).")
    ] = False,
    execute_anyway: Annotated[
        bool,
        typer.Option(
            "--execute-anyway",
            help=(
                "Play a trajectory that fails its validation (limits, collisions) for diagnosis; the run is "
                "then at best 'violated'."
            ),
        ),
    ] = False,
    planner: Annotated[
        str | None,
        typer.Option(
            help=(
                "Planner of the plan stage: mcikrrt or ompl-rrtconnect (default for a task with [[wta]] and no "
                "--ik: mcikrrt)."
            )
        ),
    ] = None,
    timeout: Annotated[float | None, typer.Option(help="Planning timeout [s] (default 5).")] = None,
    record: Annotated[str, typer.Option("--record", metavar="LEVEL", help=RECORD_HELP)] = "full",
    robot_dir: Annotated[
        Path | None,
        typer.Option(
            "--robot", help="Robot directory (or shipped robot's name) to run the task on instead of the one it names."
        ),
    ] = None,
) -> None:
    """Run a task through the pipeline and record it; prints the run directory as the last line.

    TASK is a task file, or the name of a shipped task (ball_game, bowl_grasp, carry_box, circle,
    triangle) when no such file exists.
    """
    from dualarm.run import TIMINGS, default_method, record_run
    from dualarm.settings import with_overrides
    from dualarm.tasks import load_task

    out_dir = _out_path(out_text, "--out")
    _seed(seed)
    _within(lvi_tolerance, "--lvi-tolerance", 0.0, 1.0, above_low=True)
    if timeout is not None:
        _within(timeout, "--timeout", 0.0, MAX_TIMEOUT_S, above_low=True)
    chosen = _stages(stages)
    _record(record)
    if ik is not None:
        _method(ik, "ik", "--ik")
    if planner is not None:
        _method(planner, "planner", "--planner")
    if ik is not None and planner is not None:
        raise DualarmError("give either --ik METHOD or --planner PLANNER: both make the joint path")
    if timing is not None and timing not in TIMINGS:
        raise DualarmError(f"unknown timing '{excerpt(timing)}' (timings: {', '.join(TIMINGS)})")
    loaded = load_task(task, reps, robot_dir)
    method = default_method(loaded, ik or planner, chosen)
    settings = None
    if method is not None:  # each method takes the options it has (TV-GDD its scheme and backend, planners --timeout)
        m = _method(method)
        options = {"scheme": scheme, "qp_backend": qp_backend, "lvi_tolerance": lvi_tolerance, "timeout": timeout}
        settings = m.with_options(m.settings_for(loaded), options)
    retime = with_overrides(loaded.spec.retime, {"timing": timing}) if timing is not None else None
    with err.status(f"running {task} ...") as status:
        result = record_run(
            loaded,
            method,
            settings=settings,
            stages=chosen,
            retime=retime,
            execution=_execution(gui, execute_anyway),
            seed=seed,
            out_dir=out_dir,
            command=["dualarm", *sys.argv[1:]],
            progress=lambda stage: _update(status, f"running {task}: {stage} ..."),
            record=record,
        )
    _print_choices(result)
    for line in result.verdict.lines():
        err.print(line, markup=False, soft_wrap=True)
    out.print(str(result.directory), markup=False, soft_wrap=True)
    if result.verdict.exit_code:
        raise typer.Exit(result.verdict.exit_code)


def _print_choices(result) -> None:
    """What the IK method chose along the path, one line per hand on stderr.

    For MC-Inverse, its arm-angle profile.
    """
    path = result.joint_path
    if path is not None and path.method in IK_METHODS:
        m = _method(path.method)
        for line in m.record(path, result.task.robot, m.settings_for(result.task)).lines:
            err.print(line, markup=False, soft_wrap=True)


@app.command()
@user_errors
def plan(
    task: Annotated[Path, typer.Argument(help="Task file (TOML) with [[wta]] tables, e.g. tasks/bowl_grasp.toml.")],
    planner: Annotated[
        str, typer.Option(help="mcikrrt (Li & Liang) or ompl-rrtconnect (OMPL's RRTConnect, same checker and goals).")
    ] = "mcikrrt",
    trials: Annotated[
        int, typer.Option(min=1, help=f"Planning trials (at most {MAX_TRIALS}); trial i uses seed SEED + i.")
    ] = 100,
    seed: Annotated[int, typer.Option(help="Seed of the first trial (an integer >= 0).")] = 0,
    timeout: Annotated[float | None, typer.Option(help="Planning timeout per trial [s] (default 5).")] = None,
    out_text: Annotated[
        str | None,
        typer.Option(
            "--out", help="Directory for plan_trials.csv and plan_summary.json (default plans/<task>-<planner>)."
        ),
    ] = None,
    recordings_text: Annotated[
        str, typer.Option("--recordings", help="Directory that receives the recorded run of the first successful plan.")
    ] = "recordings",
    robot_dir: Annotated[
        Path | None,
        typer.Option(
            "--robot", help="Robot directory (or shipped robot's name) to plan the task on instead of the one it names."
        ),
    ] = None,
) -> None:
    """Plan a task repeatedly: per-trial CSV, summary JSON, and the first successful plan as a run.

    The first successful plan is retimed, smoothed, executed and recorded as a run; exits 1 when no
    trial succeeded, else with the verdict of that run (0 complete, 3 violated, 1 failed).
    """
    from dualarm.plan.problem import PlanningSettings
    from dualarm.study.planning import run_trials

    out_dir = _out_path(out_text, "--out") if out_text is not None else None
    recordings = _out_path(recordings_text, "--recordings")
    _seed(seed)
    _within(trials, "--trials", 1, MAX_TRIALS)
    if timeout is not None:
        _within(timeout, "--timeout", 0.0, MAX_TIMEOUT_S, above_low=True)
    _method(planner, "planner", "--planner")  # an unknown planner is named before anything runs
    directory = out_dir or Path("plans") / f"{task.stem}-{planner}"
    with err.status(f"planning {task} ...") as status:
        result = run_trials(
            task,
            planner,
            trials,
            seed,
            directory,
            PlanningSettings().with_timeout(timeout),
            recordings,
            ["dualarm", *sys.argv[1:]],
            progress=lambda done, total: _update(
                status,
                f"planning {task}: trial {done}/{total}" + (" (recording the first plan)" if done == total else ""),
            ),
            robot=robot_dir,
        )
    s = result.summary
    out.print(
        f"{planner} on {task}: {s['success_rate'] * 100:.0f} % of {s['trials']} trials; "
        f"planning time median {s['planning_time_median_s'] * 1e3:.1f} ms, "
        f"p95 {s['planning_time_p95_s'] * 1e3:.1f} ms "
        f"(paper: {s['paper_planning_time_mean_s'] * 1e3:.2f} ms mean); "
        f"{s['collision_check_time_mean_s'] * 1e6:.1f} µs per collision check",
        markup=False,
        soft_wrap=True,
    )
    out.print(str(result.directory / "plan_summary.json"), markup=False, soft_wrap=True)
    if result.verdict is None:
        err.print(f"error: no trial found a path: {'; '.join(s['failures'])}", markup=False, soft_wrap=True)
        raise typer.Exit(1)
    for line in result.verdict.lines():
        err.print(f"first plan's run: {line}" if line.startswith("verdict") else line, markup=False, soft_wrap=True)
    if result.run is not None:
        out.print(str(result.run), markup=False, soft_wrap=True)
    if result.verdict.exit_code:
        raise typer.Exit(result.verdict.exit_code)
