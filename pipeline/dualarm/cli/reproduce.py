"""``dualarm reproduce``: the three papers' experiments and the report of their claims."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from dualarm.cli.app import _raise_swallowed, app, err, out, user_errors
from dualarm.cli.options import _out_path


@app.command()
@user_errors
def reproduce(
    out_text: Annotated[
        str | None,
        typer.Option(
            "--out",
            help=(
                "Directory that receives every run, table and figure, and report.md (emptied first if it holds only "
                "an earlier reproduction); default reports/reproduction, or reports/reproduction-NAME with --robot."
            ),
        ),
    ] = None,
    only: Annotated[
        str | None,
        typer.Option(
            help=(
                "Comma-separated parts to run (default: all): ball-game-tvgdd, "
                "ball-game-pinv, table-i, triangle, circle, carry-box, bowl-grasp."
            )
        ),
    ] = None,
    jobs: Annotated[
        int,
        typer.Option(
            "--jobs",
            "--workers",
            min=1,
            help=(
                "Parts run at once: the worker processes of a Dask LocalCluster (default: "
                "2, or 1 on a 1-core machine, which runs the parts in this process)."
            ),
        ),
    ] = min(2, os.cpu_count() or 1),
    scheduler: Annotated[
        str | None,
        typer.Option(
            help=(
                "An existing Dask cluster's scheduler (tcp://HOST:PORT) to run the parts on "
                "instead of a LocalCluster; --out must be on a file system its workers share."
            )
        ),
    ] = None,
    robot_dir: Annotated[
        Path | None,
        typer.Option(
            "--robot",
            help=(
                "Robot directory (or shipped robot's name) to run the experiments on instead of "
                "the humanoid; a part it cannot run is reported as not available, with the reason."
            ),
        ),
    ] = None,
) -> None:
    """Run every experiment of the three papers, record it, and write DIR/report.md.

    The report: each paper claim against ours (read back from the recordings), the figures, the runs
    and the time of each part.

    Exits 1 if a part failed to produce its runs (the report says which and why), else 3 if a claim
    rests on a run whose verdict is not complete, failed at a stage included (MC-Inverse's runs,
    TV-GDD's executed ball game, the carried box, the planner's executed plan; a baseline's
    violations are reported, not fatal), else 2 if no part is
    available on the robot, else 0. A part not available on the robot is reported, not fatal.
    """
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from dualarm.data import find_robot
    from dualarm.model.robot import load_robot
    from dualarm.reproduce.experiments import BY_NAME, ROBOT, robot_option
    from dualarm.reproduce.report import reproduction_claims, write_reproduction_report
    from dualarm.reproduce.runner import NOT_AVAILABLE, parts_named, prepare, run_parts

    robot = find_robot(str(robot_dir), Path.cwd()).resolve() if robot_dir is not None else ROBOT
    robot_name = load_robot(robot).name  # a robot that does not load is refused before the directory is touched
    default_out = f"reports/reproduction-{robot_name}" if robot_option(robot) else "reports/reproduction"
    out_dir = _out_path(out_text if out_text is not None else default_out, "--out")
    names = parts_named([n.strip() for n in only.split(",") if n.strip()] if only is not None else None)
    _claim = prepare(out_dir)  # out_dir stays locked until the command ends: a second reproduction into it is refused
    columns = (
        TextColumn("{task.fields[part]:<16}", markup=False),
        BarColumn(),
        TextColumn("{task.percentage:>3.0f} %"),
        TimeElapsedColumn(),
        TextColumn("{task.fields[text]}", markup=False),
    )
    with Progress(
        *columns, console=err, transient=not err.is_terminal
    ) as bar:  # in a file, the bars would print once at the end: the time table says it
        tasks = {
            name: bar.add_task(BY_NAME[name].title, total=1.0, part=name, text="waiting", start=False) for name in names
        }

        def on_progress(name: str, fraction: float, text: str) -> None:
            _raise_swallowed()
            bar.start_task(tasks[name])
            bar.update(tasks[name], completed=fraction, text=text)
            if fraction >= 1.0:
                bar.stop_task(tasks[name])

        results = run_parts(out_dir, names, jobs, on_progress, robot, scheduler)
        report_task = bar.add_task("report", total=1.0, part="report", text="reading the recordings back")
        claims = reproduction_claims(out_dir)
        report_path = write_reproduction_report(out_dir, claims)
        bar.update(report_task, completed=1.0, text="done")
    table = Table(
        title=f"time of each part ({'on ' + scheduler if scheduler else f'{jobs} at a time'})", title_justify="left"
    )
    for column in ("part", "status", "seconds"):
        table.add_column(column, justify="right" if column == "seconds" else "left")
    for r in results:
        table.add_row(r.name, f"{r.status}: {r.error}" if r.error else r.status, f"{r.seconds:.1f}")
    out.print(table)
    for c in claims:
        if c.contradicted:
            err.print(f"contradicted: {c.paper} {c.where}: {c.claim}: {c.verdict}", markup=False, soft_wrap=True)
    out.print(str(report_path), markup=False, soft_wrap=True)
    if any(r.status not in ("complete", NOT_AVAILABLE) for r in results):
        raise typer.Exit(1)
    if all(r.status == NOT_AVAILABLE for r in results):
        err.print(
            f"error: no part of the reproduction runs on {robot_name} (the report says why each is not available)",
            markup=False,
            soft_wrap=True,
        )
        raise typer.Exit(2)
    if any(c.contradicted for c in claims):
        raise typer.Exit(3)
