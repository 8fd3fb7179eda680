"""``dualarm task check``: a task file validated against its robot."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from dualarm.cli.app import EXIT_CODES, err, out, task_app, user_errors


@task_app.command("check")
@user_errors
def task_check(
    task: Annotated[str, typer.Argument(help="Task file (TOML), or a shipped task's name.")],
    robot_dir: Annotated[
        Path | None, typer.Option("--robot", help="Robot directory to check the task on instead of the one it names.")
    ] = None,
) -> None:
    """Validate a task without running it: schema, robot, every waypoint's reach and the sampled path's.

    Reach within the joint limits (per waypoint the hand pose and, for an S-R-S arm, the MC-Inverse
    branches and psi intervals that reach it), then every sample of the path as a run samples it;
    exits 3 when a waypoint or a sample is unreachable, 2 for a malformed task.
    """
    from dualarm.task_check import check_task, report_lines, unreachable_lines

    result = check_task(task, robot_dir)
    if not result.waypoints:
        out.print(
            f"{result.source}: valid; no waypoints to check (the hands start "
            "at the initial configuration and move by displacements or arcs)",
            markup=False,
            soft_wrap=True,
        )
    for line in report_lines(result):
        out.print(line, markup=False, soft_wrap=True)
    if result.samples:
        out.print(
            f"path: all {result.samples} samples within reach (the run's path-stage check)",
            markup=False,
            soft_wrap=True,
        )
    for line in unreachable_lines(result):
        err.print(line, markup=False, soft_wrap=True)
    if not result.passed:
        raise typer.Exit(EXIT_CODES["violated"])
