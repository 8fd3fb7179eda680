"""``dualarm bench ...``: speed as ratios against peers measured in the same run."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.table import Table
from rich.text import Text

from dualarm.cli.app import _update, bench_app, err, out, user_errors
from dualarm.cli.options import MAX_POSES, MAX_REPEATS, MAX_TRIALS, _out_path, _seed, _within


@bench_app.command("tvgdd")
@user_errors
def bench_tvgdd_command(
    task: Annotated[Path, typer.Option(help="Task to run TV-GDD on.")] = Path("tasks/ball_game.toml"),
    repeats: Annotated[
        int, typer.Option(min=1, help=f"Repeats of the one-call rollout (best is kept; at most {MAX_REPEATS}).")
    ] = 5,
    plugins: Annotated[
        str,
        typer.Option(help="Comma-separated CasADi conic plugins to compare with DAQP, e.g. qpoases,osqp,proxqp,qrqp."),
    ] = "",
) -> None:
    """TV-GDD per-step median and p99 of the casadi and LVI backends, their ratio, and the whole-task time.

    The whole-task IK time against the paper's T_ave = 1 ms and T_sum = 1.12 s (optionally other
    conic plugins for the casadi backend).
    """
    from dualarm.bench.tvgdd import PAPER_T_AVE_S, PAPER_T_SUM_S, bench_tvgdd

    _within(repeats, "--repeats", 1, MAX_REPEATS)
    with err.status("benchmarking ...") as status:
        rows = bench_tvgdd(
            task,
            repeats,
            tuple(p.strip() for p in plugins.split(",") if p.strip()),
            progress=lambda text: status.update(text),
        )
    table = Table(title=f"TV-GDD on {task} ({rows[0].steps} steps)", title_justify="left")
    for column in ("solver", "median µs", "p99 µs", "task s", "T_ave/ours", "T_sum/ours", "max |Δq̇| rad/s"):
        table.add_column(column, justify="left" if column == "solver" else "right")
    for r in rows:
        table.add_row(
            r.name,
            f"{r.median_s * 1e6:.1f}",
            f"{r.p99_s * 1e6:.1f}",
            f"{r.total_s:.4f}",
            f"{PAPER_T_AVE_S / r.median_s:.1f}x",
            f"{PAPER_T_SUM_S / r.total_s:.1f}x",
            f"{r.velocity_gap_rad_s:.2g}",
        )
    out.print(table)
    for r in rows:
        if r.failure:
            out.print(f"{r.name} failed: {r.failure}", markup=False, soft_wrap=True)
    out.print(f"per-step median, lvi / casadi: {rows[1].median_s / rows[0].median_s:.1f}x", markup=False)
    out.print(
        "max |Δq̇|: largest joint-velocity difference from the first row "
        "along the task (lvi stops at ||eps|| <= 1e-5, as published)",
        markup=False,
    )


@bench_app.command("ik")
@user_errors
def bench_ik_command(
    robot_dir: Annotated[Path, typer.Argument(help="Robot directory.")] = Path("robots/humanoid"),
    arm: Annotated[str, typer.Option(help="Arm whose chain is solved: left or right.")] = "left",
    poses: Annotated[int, typer.Option(min=1, help=f"Random reachable poses (at most {MAX_POSES}).")] = 10_000,
    seed: Annotated[int, typer.Option(help="Seed of the random configurations (an integer >= 0).")] = 0,
) -> None:
    """The arm's analytic IK time per pose against its peers' time and success rate, with ratios.

    The analytic IK called singly and batched (MC-Inverse's 8 candidates on an S-R-S arm, SEW's
    solutions on an arm of the SEW family such as the Panda) and its analytic peer IK-Geo's, and
    DLS-SVD, TRAC-IK and PyBullet IK time and success rate, on the same random reachable poses, with
    ratios.
    """
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TaskID, TextColumn, TimeElapsedColumn

    from dualarm.bench.ik import (
        IK_GEO,
        MC_BATCHED,
        MC_SINGLE,
        SEW_BATCHED,
        TARGET_BATCHED_S,
        TARGET_DLS_SUCCESS,
        TARGET_SINGLE_S,
        bench_ik,
        ratios,
    )
    from dualarm.model.robot import load_robot

    _seed(seed)
    _within(poses, "--poses", 1, MAX_POSES)
    model = load_robot(robot_dir)
    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=err,
        transient=True,
    ) as bar:
        tasks: dict[str, TaskID] = {}

        def progress(name: str, done: int, total: int) -> None:
            if name not in tasks:
                tasks[name] = bar.add_task(name, total=total)
            bar.update(tasks[name], completed=done)

        rows = bench_ik(model, arm, poses, seed, progress)
    ratio = ratios(rows)
    by_name = {r.name: r for r in rows}
    reference = MC_BATCHED if MC_BATCHED in by_name else SEW_BATCHED
    table = Table(
        title=f"IK of the {arm} arm of {model.name} on {poses} random reachable poses (seed {seed})",
        title_justify="left",
    )
    for column in ("solver", "mean µs/pose", "median µs/pose", "success", f"time / {reference}"):
        table.add_column(column, justify="left" if column == "solver" else "right")
    for r in rows:
        table.add_row(
            r.name, f"{r.mean_s * 1e6:.2f}", f"{r.median_s * 1e6:.2f}", f"{r.success_rate:.2%}", f"{ratio[r.name]:.3g}x"
        )
    out.print(table)
    for r in rows:
        out.print(f"- {r.name}: {r.note}", markup=False, soft_wrap=True)
    if MC_BATCHED in by_name:
        single, batched = by_name[MC_SINGLE], by_name[MC_BATCHED]
        out.print(
            f"targets: MC-Inverse single <= {TARGET_SINGLE_S * 1e6:.0f} µs median ({single.median_s * 1e6:.2f}; "
            f"{single.median_s / by_name[IK_GEO].median_s:.2f}x IK-Geo's median), "
            f"batched <= {TARGET_BATCHED_S * 1e6:.0f} µs/pose ({batched.mean_s * 1e6:.2f}), "
            f"DLS-SVD success >= {TARGET_DLS_SUCCESS:.1%} ({by_name['DLS-SVD'].success_rate:.2%})"
        )


@bench_app.command("pipeline")
@user_errors
def bench_pipeline_command() -> None:
    """Each stage's share of a whole recorded run, and MC-Inverse's auto arm-angle search alone.

    On the triangle and the circle (MC-Inverse) and the ball game (TV-GDD).
    """
    from dualarm.bench.pipeline import PARTS, SEARCH_REPEATS, bench_pipeline

    with err.status("benchmarking ...") as status:
        timings = bench_pipeline(progress=lambda text: status.update(f"benchmarking {text} ..."))
    table = Table(title="share of a whole run (dualarm run TASK --ik METHOD, recording included)", title_justify="left")
    for column in ("task", "ik", *PARTS, "total s", "motion s", "run / motion"):
        table.add_column(column, justify="left" if column in ("task", "ik") else "right")
    for r in timings:
        table.add_row(
            r.task,
            r.ik,
            *(f"{r.seconds.get(p, 0.0) / r.total_s:.1%}" for p in PARTS),
            f"{r.total_s:.2f}",
            f"{r.motion_s:.2f}",
            f"{r.total_s / r.motion_s:.2f}x" if r.motion_s else "-",
        )
    out.print(table)
    for r in timings:
        for hand, (seconds, checked, build, samples, angles) in r.search.items():
            out.print(
                f"{r.task}, {hand} arm: the auto arm-angle search alone {seconds * 1e3:.0f} ms, with the collision "
                f"check {checked * 1e3:.0f} ms = {checked / seconds:.2f}x, the check built once in "
                f"{build * 1e3:.0f} ms (medians of {SEARCH_REPEATS}; {samples} samples x {angles} angles x 8 branches)",
                markup=False,
            )


@bench_app.command("study")
@user_errors
def bench_study_command(
    spec_file: Annotated[
        Path, typer.Argument(help="A study spec (default the example, studies/inconsistency.toml).")
    ] = Path("studies/inconsistency.toml"),
    workers: Annotated[int, typer.Option(min=1, help="Workers of the scaling, two-node and whole runs.")] = 2,
    scaling_trials: Annotated[
        int, typer.Option(min=1, help="Trials of the scaling and two-node runs (the spec's first).")
    ] = 100,
    whole: Annotated[
        bool, typer.Option(help="Also run every trial of the spec (the example: 1,000 trials x 7 methods).")
    ] = True,
    whole_out: Annotated[
        str | None,
        typer.Option(
            "--out",
            help=(
                "Keep the whole study's directory here (as dualarm study --out writes "
                "it; dualarm study report reads it); default a temporary directory."
            ),
        ),
    ] = None,
) -> None:
    """A study on Dask: trials per second per worker on 1 and on --workers workers (LocalCluster).

    Per method; the same trials in plain processes without Dask (what the machine gives) and on
    workers started apart on 127.0.0.1 (two nodes) compared row by row; the whole study's time with
    the trials' sizes; the hypervisor's share of CPU time (steal) during each run.

    Exits 1 when the two-node run's rows differ from the LocalCluster's (but for times, workers and
    TRAC-IK's rows, whose timeout is wall-clock).
    """
    from dualarm.bench.study import StudyBench, bench_study, method_seconds, trial_sizes
    from dualarm.study import load_study

    spec, base = load_study(spec_file)
    with err.status("benchmarking ...") as status:
        kept = _out_path(whole_out, "--out") if whole_out is not None else None
        bench = bench_study(
            spec,
            base,
            workers=workers,
            scaling_trials=scaling_trials,
            whole=whole,
            whole_out=kept,
            progress=lambda text: _update(status, f"benchmarking: {text} ..."),
        )
    table = Table(title=f"study {spec.name} on this machine ({os.cpu_count()} cores)", title_justify="left")
    for column in ("run", "workers", "trials", "startup s", "trials s", "trials/s per worker", "x 1 worker", "steal"):
        table.add_column(column, justify="left" if column == "run" else "right")
    runs = [
        ("LocalCluster", "one", bench.one),
        ("LocalCluster", "many", bench.many),
        ("workers started apart", "nodes", bench.nodes),
    ] + ([("whole study", "whole", bench.whole)] if bench.whole else [])
    for name, key, r in runs:
        rate = StudyBench.rate(r)
        table.add_row(
            name,
            str(r.workers),
            str(r.ran),
            f"{r.startup_s:.1f}",
            f"{r.seconds:.1f}",
            f"{rate:.3f}",
            f"{rate / StudyBench.rate(bench.one):.3f}",
            f"{bench.steal[key]:.1%}",
        )
    for key, p in (("plain_one", bench.plain_one), ("plain_many", bench.plain_many)):
        table.add_row(
            "plain processes, no Dask",
            str(len(p.trials)),
            str(sum(p.trials)),
            "-",
            f"{max(p.seconds):.1f}",
            f"{p.rate:.3f}",
            f"{p.rate / bench.plain_one.rate:.3f}",
            f"{bench.steal[key]:.1%}",
        )
    out.print(table)
    methods = Table(
        title=f"mean time per trial on 1 and on {bench.many.workers} workers (LocalCluster)", title_justify="left"
    )
    for column in ("method", "1 worker s", f"{bench.many.workers} workers s", "ratio"):
        methods.add_column(column, justify="left" if column == "method" else "right")
    for method, row in method_seconds(bench.one, bench.many).iterrows():
        methods.add_row(str(method), f"{row.one_s:.3f}", f"{row.many_s:.3f}", f"{row.ratio:.2f}")
    out.print(methods)
    for what, value in trial_sizes((bench.whole or bench.many).results).items():
        out.print(f"{what}: {value}", markup=False, soft_wrap=True)
    if bench.whole is not None:
        out.print(
            f"whole study: {bench.whole.ran} trials x {len(spec.methods)} methods in "
            f"{(bench.whole.startup_s + bench.whole.seconds) / 60:.1f} min, cluster start included",
            markup=False,
        )
    if bench.nodes_differ:
        err.print(
            f"the two-node run's rows differ from the LocalCluster's in: {', '.join(bench.nodes_differ)}",
            markup=False,
            soft_wrap=True,
        )
        raise typer.Exit(1)
    out.print(
        f"two nodes: {bench.compared_rows} rows identical bit for bit to "
        "the LocalCluster's (times, workers and TRAC-IK's rows left out)",
        markup=False,
    )


@bench_app.command("trajectory")
@user_errors
def bench_trajectory_command() -> None:
    """The jerk-limited timing against TOPP-RA (0.9/0.3 and 1.0/1.0) with Ruckig tracking.

    On the triangle, the circle, the ball game and the bowl grasp: duration and its ratio to TOPP-RA
    at full limits and to a lower bound of a jerk-limited motion resting where the jerk-limited timing
    rests, limit ratios by finite differences (red above 1 + 1e-6), path deviation per joint and at the
    hands, compute time. Exits 1 if a method failed, 3 if a motion exceeds a limit.
    """
    from dualarm.bench.trajectory import bench_trajectory
    from dualarm.limits import LIMIT_TOLERANCE

    with err.status("benchmarking ...") as status:
        rows = bench_trajectory(progress=lambda text: status.update(f"benchmarking {text} ..."))
    table = Table(
        title=(
            "trajectory generation on each task's joint path: velocity, acceleration and jerk "
            "limit ratios by finite differences of the motion's positions (its jerk-limited timing's jerk: of its "
            "accelerations; red above 1 + 1e-6); "
            "deviation from the path per joint and at the hands; compute time per second of motion"
        ),
        title_justify="left",
    )
    for column in (
        "task",
        "method",
        "duration s",
        "× TOPP-RA 1.0/1.0",
        "× bound",
        "v",
        "a",
        "j",
        "Δq rad",
        "Δhand µm",
        "ms / s",
    ):
        table.add_column(column, justify="left" if column in ("task", "method") else "right", no_wrap=True)
    for r in rows:
        if r.failure:
            table.add_row(r.task, r.method, "failed", *["-"] * 8)
            continue
        table.add_row(
            r.task,
            r.method,
            f"{r.duration_s:.3f}",
            f"{r.duration_s / r.optimal_s:.3f}" if r.optimal_s else "-",
            f"{r.duration_s / r.bound_s:.3f}" if r.bound_s else "-",
            *(Text(f"{x:.6f}", style="bold red" if x > 1 + LIMIT_TOLERANCE else "") for x in r.ratios),
            f"{r.deviation_rad:.2e}",
            f"{r.hand_deviation_m * 1e6:.3g}" if r.hand_deviation_m < 1e-3 else f"{r.hand_deviation_m * 1e6:.0f}",
            f"{r.compute_s / r.duration_s * 1e3:.1f}" if r.duration_s else "-",
        )
    Console(highlight=False, emoji=False, width=max(out.width, 170), file=out.file).print(
        table
    )  # eleven columns of numbers, none cut
    exceeded = [
        f"- {r.task}, {r.method}: its {kind} reaches {x:.7f} times the limit"
        for r in rows
        if not r.failure
        for kind, x in zip(("velocity", "acceleration", "jerk"), r.ratios, strict=True)
        if x > 1 + LIMIT_TOLERANCE
    ]
    for line in [f"- {r.task}, {r.method}: {r.failure}" for r in rows if r.failure] + exceeded:
        out.print(line, soft_wrap=True)
    if any(r.failure for r in rows) or exceeded:
        raise typer.Exit(1 if any(r.failure for r in rows) else 3)  # as a run's verdict: failed, or a limit exceeded


@bench_app.command("plan")
@user_errors
def bench_plan_command(
    task: Annotated[Path, typer.Option(help="Task with [[wta]] tables.")] = Path("tasks/bowl_grasp.toml"),
    trials: Annotated[int, typer.Option(min=1, help=f"Trials per planner (interleaved; at most {MAX_TRIALS}).")] = 30,
    seed: Annotated[int, typer.Option(help="Seed of the first trial (an integer >= 0).")] = 0,
) -> None:
    """MCIKRRT against OMPL RRTConnect on the same problem, checker and goals.

    Planning times and their ratio, collision checks and the time of one check; then the time of one
    check by PyBullet's narrow phase (the reference) and by the planners' closed-form checker, on
    the same configurations.
    """
    from dualarm.bench.plan import bench_plan
    from dualarm.study.planning import PAPER_PLANNING_TIME_S

    _seed(seed)
    _within(trials, "--trials", 1, MAX_TRIALS)
    with err.status("benchmarking ...") as status:
        bench = bench_plan(task, trials, seed, progress=lambda text: status.update(f"benchmarking {text} ..."))
    table = Table(title=f"planning {task} ({trials} trials each, interleaved)", title_justify="left")
    for column in (
        "planner",
        "success",
        "median ms",
        "p95 ms",
        "mean ms",
        "checks (median)",
        "µs / check",
        "path rad (median)",
        "paper mean / ours",
    ):
        table.add_column(column, justify="left" if column == "planner" else "right", no_wrap=column == "planner")
    for r in bench.planners:
        table.add_row(
            r.planner,
            f"{r.success_rate:.0%}",
            f"{r.median_s * 1e3:.1f}",
            f"{r.p95_s * 1e3:.1f}",
            f"{r.mean_s * 1e3:.1f}",
            f"{r.checks_median:.0f}",
            f"{r.check_time_s * 1e6:.1f}",
            f"{r.path_length_median_rad:.2f}",
            f"{PAPER_PLANNING_TIME_S / r.mean_s:.0f}x",
        )
    out.print(table)
    mcikrrt, ompl = bench.planners[0], bench.planners[1]
    out.print(f"median planning time, ompl-rrtconnect / mcikrrt: {ompl.median_s / mcikrrt.median_s:.2f}x", markup=False)
    checks = Table(
        title=(
            f"one collision check, the same {bench.configurations} "
            "configurations of planner-like edges (fastest of the rounds)"
        ),
        title_justify="left",
    )
    for column in ("checker", "configurations given", "per call", "µs / check", "pybullet / this"):
        checks.add_column(
            column, justify="left" if column in ("checker", "configurations given") else "right", no_wrap=True
        )
    reference = bench.checkers[0].check_time_s
    for c in bench.checkers:
        checks.add_row(
            c.checker, c.batch, str(c.batch_size), f"{c.check_time_s * 1e6:.2f}", f"{reference / c.check_time_s:.1f}x"
        )
    out.print(checks)
    out.print(
        f"verdicts that differ between the two checkers: {bench.disagreements} of {bench.configurations}", markup=False
    )
