"""``dualarm consistency``, ``analyze`` and ``study``: repeated motion, in runs, bags and studies."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table
from rich.text import Text

from dualarm.cli.app import _update, app, err, out, user_errors
from dualarm.cli.options import _out_path, _record, _seed
from dualarm.errors import DualarmError, excerpt


@app.command()
@user_errors
def consistency(
    task: Annotated[Path, typer.Argument(help="Task file (TOML), e.g. tasks/triangle.toml.")],
    methods: Annotated[
        str | None,
        typer.Option(
            help=(
                "Comma-separated IK methods to compare (default: "
                "mc-inverse,trac-ik,ikfast-style,pybullet,dls-svd,tvgdd,pinv, those that run on the task's robot)."
            )
        ),
    ] = None,
    reps: Annotated[int | None, typer.Option(min=1, help="Repetitions (default: the task file's).")] = None,
    out_text: Annotated[
        str | None, typer.Option("--out", help="Output directory (default consistency/<task>).")
    ] = None,
    seed: Annotated[int, typer.Option(help="Random seed (an integer >= 0), recorded in each run's manifest.")] = 0,
    robot_dir: Annotated[
        Path | None,
        typer.Option(
            "--robot", help="Robot directory (or shipped robot's name) to run the task on instead of the one it names."
        ),
    ] = None,
) -> None:
    """Run each IK method on a repeated task as a recorded run and compare repetition by repetition.

    Writes consistency.csv, consistency.md and figures; prints the table (with each run's verdict)
    and the directory.

    Exits 0 when every run is complete, 3 when one is violated (its first violation is printed), 1 when one failed.
    """
    from dualarm.report.consistency import method_label, run_consistency

    out_dir = _out_path(out_text, "--out") if out_text is not None else None
    _seed(seed)
    chosen = (
        [m.strip() for m in methods.split(",") if m.strip()] if methods is not None else None
    )  # None: DEFAULT_METHODS that run on the task's robot
    directory = out_dir or Path("consistency") / task.stem
    with err.status("consistency ...") as status:
        result = run_consistency(
            task, chosen, directory, reps, seed, progress=lambda text: _update(status, text), robot=robot_dir
        )
    shown = {
        "rep_joint_deviation_max_rad": "rep Δq max rad",
        "rep_arm_angle_deviation_max_rad": "rep Δψ max rad",
        "orientation_error_max_rad": "orient. err max rad",
        "closure_error_max_rad": "closure rad",
        "failed_reps": "failed reps",
        "failures": "failed samples",
        "max_joint_step_rad": "max step rad",
        "solve_time_mean_s": "solve ms/sample",
    }
    shown = {c: label for c, label in shown.items() if c in result.table.columns}  # no arm angle on a non-S-R-S robot
    table = Table(title=f"{task}: consistency over repetitions (all columns in {result.csv})", title_justify="left")
    for column in ("method", "verdict", *shown.values()):
        table.add_column(
            column,
            justify="left" if column in ("method", "verdict") else "right",
            no_wrap=column in ("method", "verdict"),
        )
    for _, row in result.table.iterrows():
        if row["status"] == "failed":
            table.add_row(row["method"], f"failed: {row['error']}", *[""] * len(shown))
            continue
        table.add_row(
            method_label(row), row["status"], *(f"{row[c] * (1e3 if c.endswith('_s') else 1):.3g}" for c in shown)
        )
    out.print(table)
    for _, row in result.table.iterrows():
        if row["status"] != "complete":
            err.print(
                f"{row['method']}: {row['status']}: {row['error'] or row['violation']}", markup=False, soft_wrap=True
            )
    out.print(str(directory), markup=False, soft_wrap=True)
    raise typer.Exit(_worst(result.table["status"]))


@app.command()
@user_errors
def analyze(
    bag: Annotated[Path, typer.Argument(help="A ROS 2 bag: a rosbag2 directory (MCAP or sqlite3) or an MCAP file.")],
    robot_dir: Annotated[
        Path, typer.Option("--robot", help="Robot directory (or shipped robot's name) the bag was recorded on.")
    ],
    task: Annotated[
        Path | None,
        typer.Option(help="The task the robot repeated: its start pose cuts the repetitions, its path is compared."),
    ] = None,
    reps: Annotated[
        int | None, typer.Option(min=2, help="How many repetitions the bag holds (refused if the cut finds another).")
    ] = None,
    period: Annotated[
        float | None, typer.Option(help="Cut every PERIOD seconds instead of where the hands pass the start pose.")
    ] = None,
    topic: Annotated[str, typer.Option(help="The sensor_msgs/msg/JointState topic.")] = "/joint_states",
    joint_map: Annotated[
        str | None,
        typer.Option(
            "--joint-map",
            metavar="BAG=URDF,...",
            help="Joint names of the bag mapped to the URDF's, for a driver that names them otherwise.",
        ),
    ] = None,
    threshold: Annotated[
        float, typer.Option(help="Joint deviation above the noise floor that makes repetitions inconsistent [rad].")
    ] = 0.01,
    out_text: Annotated[
        str | None, typer.Option("--out", help="Output directory (default analysis/<bag name>).")
    ] = None,
) -> None:
    """Judge a real robot's repeated motion from a ROS 2 bag, as ``dualarm consistency`` judges a run.

    Cuts the joint states into repetitions, compares each with the first where the hands pass the same place, beyond
    the noise estimated from the data; checks the velocity, acceleration and jerk limits. Writes analysis.csv,
    repetitions.csv, analysis.md and figures; prints the table and the directory. See docs/real-robot.md.

    Exits 0 when the repetitions are consistent and within every limit, 3 when they are inconsistent or a limit is
    exceeded beyond the noise.
    """
    from dualarm.report.analyze import analyze_bag

    if reps is not None and period is not None:
        raise DualarmError("analyze: give --reps or --period, not both")
    rename = {}
    for pair in (joint_map or "").split(","):
        if pair.strip():
            name, sep, urdf = pair.partition("=")
            if not sep or not name.strip() or not urdf.strip():
                raise DualarmError(f"--joint-map: '{excerpt(pair, 80)}' is not BAG_NAME=URDF_NAME")
            rename[name.strip()] = urdf.strip()
    directory = _out_path(out_text, "--out") if out_text is not None else Path("analysis") / bag.name
    with err.status(f"analyzing {bag} ..."):
        result = analyze_bag(bag, robot_dir, directory, task, reps, period, topic, rename, threshold)
    table = Table(title=f"{bag}: repetitions (all columns in {directory / 'analysis.csv'})", title_justify="left")
    table.add_column("metric", no_wrap=True)
    table.add_column("value", justify="right")
    for key, value in result.metrics.items():
        table.add_row(key, f"{value:.4g}" if isinstance(value, float) else str(value))
    out.print(table)
    for line in result.violations:
        err.print(f"limit: {line}", markup=False, soft_wrap=True)
    out.print(str(directory), markup=False, soft_wrap=True)
    raise typer.Exit(0 if result.consistent and not result.violations else 3)


@app.command()
@user_errors
def study(
    spec_or_report: Annotated[
        str,
        typer.Argument(
            metavar="SPEC.toml | report",
            help="A study spec file (studies/inconsistency.toml) to run, or the word report.",
        ),
    ],
    directory_text: Annotated[
        str | None, typer.Argument(metavar="[DIR]", help="With report: the study's directory.")
    ] = None,
    scheduler: Annotated[
        str | None,
        typer.Option(
            help=(
                "An existing Dask cluster's scheduler (tcp://HOST:PORT) to "
                "run the trials on; default a LocalCluster on this machine."
            )
        ),
    ] = None,
    workers: Annotated[
        int | None,
        typer.Option(min=1, help="The LocalCluster's worker processes (one thread each; default one per core)."),
    ] = None,
    out_text: Annotated[
        str | None, typer.Option("--out", help="The study's directory (default studies/results/<name>).")
    ] = None,
    resume: Annotated[
        bool,
        typer.Option("--resume", help="Run only the trials not yet in --out (a study stopped or crashed half-way)."),
    ] = False,
    record: Annotated[
        str,
        typer.Option(
            help=(
                "metrics (no recordings, the default), ik or full: "
                "each trial's runs in DIR/runs (full runs every stage)."
            )
        ),
    ] = "metrics",
) -> None:
    """Run a study, or write a study's report.

    Every generated trial of SPEC.toml with every method, on Dask (dualarm study SPEC.toml); or a
    study's report (dualarm study report DIR).

    A run writes DIR/trials.parquet (one row per trial and method: the trial's features, every ik.*
    metric, the verdict, wall time, worker), one task file per trial in DIR/tasks, and prints per
    method P(inconsistent) and P(failed) with 95 % Wilson intervals and its violated rows (a hand off
    its pose, a joint beyond a limit, an IK path through the robot or the scene). A report writes DIR/report.md,
    its tables (csv) and figures from DIR/trials.parquet alone.

    Exits 0 when every trial has its rows (a method that failed a trial is the study's data, counted
    in the table), 1 when a row is an error (an exception other than dualarm's, or a trial whose
    worker died 3 times), 2 on a bad spec or --out (another study's directory, or this study's
    without --resume).
    """
    from dualarm.study import load_study
    from dualarm.study.report import method_rates, write_study_report
    from dualarm.study.run import run_study

    if spec_or_report == "report":
        if directory_text is None:
            raise DualarmError("dualarm study report DIR: give the study's directory")
        out.print(str(write_study_report(_out_path(directory_text, "DIR"))), markup=False, soft_wrap=True)
        return
    if directory_text is not None:
        raise DualarmError(
            f"unexpected argument '{excerpt(directory_text)}': dualarm "
            "study SPEC.toml [--out DIR], or dualarm study report DIR"
        )
    spec, base = load_study(spec_or_report)
    level = _record(record)
    directory = _out_path(out_text, "--out") if out_text is not None else Path("studies") / "results" / spec.name
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    columns = (
        TextColumn(f"study {spec.name}", markup=False),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[text]}", markup=False),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
    )
    with Progress(*columns, console=err, transient=not err.is_terminal) as bar:
        task = bar.add_task("trials", total=None, text="starting the cluster")

        def on_trial(done: int, failed: int, total: int, errors: int) -> None:
            seconds = bar.tasks[task].elapsed or 1e-9
            bar.update(
                task,
                completed=done,
                total=total,
                text=f"{failed} with a failed method, {errors} errors, {done / seconds:.2f} trials/s",
            )

        result = run_study(
            spec, base, directory, scheduler=scheduler, workers=workers, resume=resume, record=level, progress=on_trial
        )
    rates = method_rates(result.results)
    table = Table(
        title=(
            f"study {spec.name}: {result.results['trial'].nunique()} trials ({result.ran} now in "
            f"{result.seconds:.1f} s on {result.workers} workers, after {result.startup_s:.1f} s starting them)"
        ),
        title_justify="left",
    )
    for column in ("method", "trials", "P(inconsistent) [95 %]", "P(failed) [95 %]", "violated", "errors"):
        table.add_column(column, justify="left" if column == "method" else "right")
    for r in rates.itertuples():
        table.add_row(
            str(r.method),
            str(r.trials),
            f"{r.p_inconsistent:.3f} [{r.p_inconsistent_low:.3f}, {r.p_inconsistent_high:.3f}]",
            Text(f"{r.p_failed:.3f} [{r.p_failed_low:.3f}, {r.p_failed_high:.3f}]", style="yellow" if r.failed else ""),
            Text(str(r.violated), style="yellow" if r.violated else ""),
            Text(str(r.errors), style="red" if r.errors else ""),
        )
    out.print(table)
    out.print(f"{directory / 'trials.parquet'} (dualarm study report {directory})", markup=False, soft_wrap=True)
    errors = result.results[result.results["status"] == "error"]
    if len(errors):
        first = errors.iloc[0]
        err.print(
            f"error: {len(errors)} rows are errors, the first trial "
            f"{first['trial']} {first['method']}: {first['error']}",
            markup=False,
            soft_wrap=True,
        )
        raise typer.Exit(1)


def _worst(statuses) -> int:
    """The exit code of several runs' verdicts: 1 if one failed, else 3 if one was violated, else 0."""
    from dualarm.contracts.verdict import EXIT_CODES

    return max((EXIT_CODES[s] for s in statuses), key=lambda code: (code == 1, code), default=0)
