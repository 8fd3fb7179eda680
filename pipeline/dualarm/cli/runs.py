"""Looking at recorded runs: ``dualarm inspect``, ``view``, ``report``, ``compare`` and ``export``."""

from __future__ import annotations

import os
import stat
import sys
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich.table import Table

from dualarm.cli.app import app, err, out, user_errors
from dualarm.cli.options import _out_path, _within
from dualarm.errors import DualarmError, excerpt

#: The most characters ``inspect`` prints of a run's error or of a violation (the manifest holds them whole).
INSPECT_CHARS = 2000


@app.command()
@user_errors
def inspect(run_dir: Annotated[Path, typer.Argument(help="A run directory (recordings/<task>/<run-id>).")]) -> None:
    """Print a run's verdict (status, error, each violation), topics and metrics.

    Topics with message counts and time range.
    """
    from dualarm.record.readback import read_run

    data = read_run(run_dir)
    m = data.manifest
    out.print(f"run      {data.run_id}  ({data.status})  {run_dir.resolve()}", markup=False, soft_wrap=True)
    out.print(f"task     {m.get('task')}  ({m.get('task_file')})", markup=False)
    out.print(f"stages   {', '.join(data.stages)}", markup=False)
    if data.record != "full":
        out.print(f"record   {data.record} ({data.lacks()})", markup=False, soft_wrap=True)
    if m.get("error"):
        out.print(f"error    {excerpt(str(m['error']), INSPECT_CHARS)}", markup=False, soft_wrap=True)
    for violation in data.violations:
        out.print(f"violated {excerpt(violation, INSPECT_CHARS)}", markup=False, soft_wrap=True)
    table = Table(title="topics", title_justify="left")
    for column in ("topic", "stage", "rows", "t from [s]", "t to [s]"):
        table.add_column(column, justify="left" if column in ("topic", "stage") else "right")
    for topic, df in data.topics.items():
        table.add_row(topic, str(df["stage"].iloc[0]), str(len(df)), f"{df['t'].min():.3f}", f"{df['t'].max():.3f}")
    if data.topics:
        out.print(table)
    metrics = Table(title="metrics", title_justify="left")
    metrics.add_column("key")
    metrics.add_column("value", justify="right")
    for key, value in sorted(data.metrics.items()):
        metrics.add_row(key, "null" if value is None else f"{value:.6g}")
    out.print(metrics)


@app.command()
@user_errors
def view(
    run_dir: Annotated[
        Path, typer.Argument(help="A run directory (recordings/<task>/<run-id>), recorded with --record full or ik.")
    ],
    web: Annotated[
        bool,
        typer.Option(
            "--web",
            help=(
                "Serve the run with Rerun's web viewer on 127.0.0.1 and print "
                "the URL to open (no browser is started); serves until Ctrl-C."
            ),
        ),
    ] = False,
    stage: Annotated[
        str | None,
        typer.Option(
            metavar="STAGE",
            help=(
                "Open Rerun on this stage's robot and plots (one the run "
                "recorded: path, ik or plan, retime, smooth, execute)."
            ),
        ),
    ] = None,
) -> None:
    """Open a recorded run in Rerun's viewer, and print how to open its run.mcap in Foxglove.

    A window, or with --web the web viewer; Foxglove with the run's layout.

    The viewer is the rerun command installed with rerun-sdk (beside this Python, or on PATH).
    """
    import tempfile

    from dualarm.record.view import (
        blueprint_file,
        check_display,
        check_stage,
        open_native,
        rerun_executable,
        serve_web,
        viewable,
    )

    run = viewable(run_dir)
    if stage is not None:
        check_stage(run, stage)
    if not web:
        check_display()
    executable = rerun_executable()
    with tempfile.TemporaryDirectory(prefix="dualarm-view-") as scratch:
        files = [run.rrd, *([blueprint_file(run, stage, Path(scratch))] if stage is not None else [])]
        for line in run.foxglove:
            out.print(line, markup=False, soft_wrap=True)
        if not web:
            out.print(f"Rerun: opening {run.rrd} (close its window to end)", markup=False, soft_wrap=True)
            sys.stdout.flush()
            open_native(executable, files)
            return
        with serve_web(executable, files) as (url, process):
            out.print(f"Rerun web viewer: {url}  (serving until Ctrl-C)", markup=False, soft_wrap=True)
            sys.stdout.flush()
            process.wait()


@app.command()
@user_errors
def report(
    run_dirs: Annotated[
        list[Path],
        typer.Argument(
            help="One or more run directories (recordings/<task>/<run-id>), from this machine or copied from another."
        ),
    ],
    out_text: Annotated[
        str | None,
        typer.Option(
            "--out",
            help=(
                "Report directory (default reports/<task>/<run-id> for one "
                "run, reports/<task or runs>/<first run-id>+<n-1> for several)."
            ),
        ),
    ] = None,
) -> None:
    """Write a markdown summary and the figures each run's recording allows.

    For several runs also runs.csv and runs.md (a row per run, every metric), figures setting them
    side by side and report.md linking it all.

    Prints the report directory.
    """
    from dualarm.report.run_report import write_report, write_runs_report

    out_dir = _out_path(out_text, "--out") if out_text is not None else None
    with err.status(f"reporting {len(run_dirs)} run{'s' if len(run_dirs) > 1 else ''} ..."):
        directory = write_report(run_dirs[0], out_dir) if len(run_dirs) == 1 else write_runs_report(run_dirs, out_dir)
    out.print(str(directory), markup=False, soft_wrap=True)


@app.command()
@user_errors
def compare(
    run_a: Annotated[Path, typer.Argument(help="A run directory.")],
    run_b: Annotated[Path, typer.Argument(help="Another run directory.")],
    tol: Annotated[
        float,
        typer.Option(
            help="Largest absolute difference accepted, in each field's own unit (a finite number >= 0; 0: identical)."
        ),
    ] = 0.0,
    csv_text: Annotated[
        str | None,
        typer.Option(
            "--csv",
            help=(
                "Also write the whole table (a row per topic and field) to "
                "this CSV file (a new file, or one an earlier compare wrote)."
            ),
        ),
    ] = None,
) -> None:
    """Per topic and field, the largest difference between two runs, aligned on repetition and time.

    Exits 0 when every field is within --tol and 1 otherwise, naming where they differ first.

    Wall-clock measurements (solve, planning, collision-check times) are listed, never judged.
    """
    from dualarm.record.run_dir import write_whole
    from dualarm.report.compare import compare_runs

    _within(tol, "--tol", 0.0)
    csv = _compare_csv(csv_text) if csv_text is not None else None
    with err.status(f"comparing {run_a} and {run_b} ..."):
        result = compare_runs(run_a, run_b, tol)
    table = Table(title=f"A = {run_a}\nB = {run_b}", title_justify="left")
    for column in (
        "topic",
        "rows A",
        "rows B",
        "aligned",
        "largest |A - B|",
        "in field",
        "at t [s]",
        "rep",
        f"within {tol:g}",
    ):
        table.add_column(
            column, justify="left" if column in ("topic", "in field") else "right", no_wrap=column == "topic"
        )
    judged = result.table[~result.table["wall_clock"]]
    for topic, rows in judged.groupby("topic", sort=False):
        worst = rows.iloc[rows["max_difference"].fillna(-np.inf).argmax()]
        located = (
            ("", "", "")
            if worst["max_difference"] == 0
            else (
                str(worst["field"]),
                "" if _missing(worst["t"]) else f"{worst['t']:.3f}",
                "" if _missing(worst["rep"]) else str(int(worst["rep"])),
            )
        )
        table.add_row(
            str(topic),
            str(worst["rows_a"]),
            str(worst["rows_b"]),
            str(worst["aligned"]),
            f"{worst['max_difference']:.3g}",
            *located,
            "yes" if worst["max_difference"] <= tol else "NO",
        )
    out.print(table)
    clock = result.table[result.table["wall_clock"]]
    if len(clock):
        out.print(
            f"not judged (wall clock): {', '.join(f'{r.topic} {r.field}' for r in clock.itertuples())}",
            markup=False,
            soft_wrap=True,
        )
    if csv is not None:
        write_whole(csv, result.table.to_csv(index=False))
    if result.within:
        out.print(f"identical within {tol:g} in every judged field", markup=False)
        return
    beyond = result.beyond
    first = beyond.iloc[0]
    where = (
        f"at t = {first['first_beyond_t']:.4f} s, rep {int(first['first_beyond_rep'])}"
        if not _missing(first["first_beyond_t"])
        else "(whole topic or field)"
    )
    out.print(
        f"differ first: {first['topic']} {first['field']} {where}"
        + (f" ({first['note']})" if first["note"] else f" (largest |A - B| = {first['max_difference']:.3g})"),
        markup=False,
        soft_wrap=True,
    )
    out.print(
        f"{len(beyond)} fields beyond {tol:g}, earliest first: "
        + ", ".join(f"{r.topic} {r.field}" for r in beyond.head(12).itertuples())
        + (" ..." if len(beyond) > 12 else ""),
        markup=False,
        soft_wrap=True,
    )
    raise typer.Exit(1)


#: How a table ``dualarm compare`` wrote begins.
COMPARE_HEADER = "topic,field,max_difference,"


@app.command()
@user_errors
def export(
    run_dir: Annotated[
        Path, typer.Argument(help="A run directory (recordings/<task>/<run-id>), recorded with --record full.")
    ],
    ros2: Annotated[
        str | None,
        typer.Option(
            "--ros2",
            metavar="DIR",
            help=(
                "Write a ROS 2 bag directory (metadata.yaml and an MCAP file): /joint_trajectory for a joint "
                "trajectory controller, /joint_states, /tf, /tf_static and /robot_description to play in RViz or "
                "Foxglove."
            ),
        ),
    ] = None,
    csv: Annotated[
        str | None,
        typer.Option(
            "--csv",
            metavar="FILE",
            help="Write the timed trajectory as CSV: t_s, then one <joint>_rad column per joint.",
        ),
    ] = None,
) -> None:
    """Export a run for a real robot: its timed trajectory and executed motion as a ROS 2 bag, or CSV.

    Prints each file written. See docs/real-robot.md.
    """
    from dualarm.record.readback import read_run
    from dualarm.record.ros2 import export_bag, export_csv

    if ros2 is None and csv is None:
        raise DualarmError("export: give --ros2 DIR, --csv FILE, or both")
    targets = [
        (_out_path(text, option), write)
        for text, option, write in ((ros2, "--ros2", export_bag), (csv, "--csv", export_csv))
        if text is not None
    ]
    run = read_run(run_dir)
    for target, write in targets:
        with err.status(f"writing {target} ..."):
            out.print(str(write(run, target)), markup=False, soft_wrap=True)


def _compare_csv(text: str) -> Path:
    """The ``--csv`` path of compare: a new file, or an earlier compare's table.

    A regular file whose first line is :data:`COMPARE_HEADER`; anything else is refused, untouched.
    """
    path = _out_path(text, "--csv")
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return path
    except OSError as exc:  # through a file, too long, no permission
        raise DualarmError(f"--csv {excerpt(path)}: {exc.strerror}; give another file name") from None
    if stat.S_ISDIR(mode):
        raise DualarmError(f"--csv {excerpt(path)}: is a directory; give a file name")
    first = ""
    if stat.S_ISREG(mode):
        try:
            with path.open("rb") as f:
                first = f.readline(len(COMPARE_HEADER)).decode("utf-8", errors="replace")
        except OSError as exc:
            raise DualarmError(
                f"--csv {excerpt(path)}: cannot read it ({exc.strerror}); give another file name"
            ) from None
    if not first.startswith(COMPARE_HEADER):
        raise DualarmError(
            f"--csv {excerpt(path)}: exists and is not a table dualarm compare "
            f"wrote (it does not begin '{COMPARE_HEADER}'); give another file name"
        )
    return path


def _missing(value) -> bool:
    """Whether a table cell is missing (NaN or None)."""
    return value is None or (isinstance(value, float) and np.isnan(value))
