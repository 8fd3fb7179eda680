"""The ``dualarm`` command line (Typer).

User mistakes (a malformed task file, an unknown robot, a corrupt recording, an argument outside
its range, an output directory holding files dualarm did not write, ...) print one line on
stderr and exit with code 2; no traceback. Every argument is checked before any work. Messages
are printed as they are (no markup, no emoji codes) and quote at most about 80 characters of a
user's string (:func:`dualarm.errors.excerpt`); a line is cut at :data:`MAX_LINE` characters.

Exit codes (:data:`EXIT_CODES`): 0 complete, 3 violated (the run finished, but a check failed),
1 failed, 2 a user's mistake, 130 interrupted by Ctrl-C (SIGINT), 143 terminated (SIGTERM). An
interrupted run is kept as failed, as any run that stops half-way.
"""

from __future__ import annotations

import functools
import math
import os
import signal
import stat
import sys
import threading
from pathlib import Path
from typing import Annotated, Any, Callable, Optional

import numpy as np
import typer
from rich.console import Console
from rich.status import Status
from rich.table import Table
from rich.text import Text

from dualarm.errors import DualarmError, NotSRSError, StageError, Terminated, excerpt

#: Exit codes of every command.
EXIT_CODES = {"complete": 0, "violated": 3, "failed": 1, "user error": 2, "interrupted (SIGINT)": 130, "terminated (SIGTERM)": 143}

app = typer.Typer(
    name="dualarm",
    help="Humanoid dual-arm motion papers as runnable, recorded, repeatable experiments.\n\nExit codes: " + ", ".join(f"{code} {what}" for what, code in EXIT_CODES.items()) + ".",
    no_args_is_help=True,
    rich_markup_mode=None,  # help as written: rich markup would eat "[s]", "[rad]", ...
    add_completion=False,
    pretty_exceptions_enable=False,
)
robot_app = typer.Typer(help="Inspect and verify robot descriptions.", no_args_is_help=True)
app.add_typer(robot_app, name="robot")
bench_app = typer.Typer(help="Measure speed as ratios against peers run in the same process.", no_args_is_help=True)
app.add_typer(bench_app, name="bench")
ik_app = typer.Typer(help="Inverse kinematics of single poses.", no_args_is_help=True)
app.add_typer(ik_app, name="ik")
task_app = typer.Typer(help="Author and validate task files.", no_args_is_help=True)
app.add_typer(task_app, name="task")

# Text is printed as it is: no markup, no emoji codes (":robot:" stays), in messages and table cells.
out = Console(highlight=False, markup=False, emoji=False, width=None if sys.stdout.isatty() else 120)  # tables unwrapped in pipes and files
err = Console(stderr=True, highlight=False, markup=False, emoji=False)
#: The longest line an error prints [characters] (a message quotes a user's string in ~80).
MAX_LINE = 400


def user_errors(func: Callable) -> Callable:
    """Turn a DualarmError into one line on stderr and exit code 2; a StageError from a recorded run (a run that failed on valid input, kept as failed) into ``verdict: failed``, the error and where the run is kept, and exit code 1.

    Ctrl-C (SIGINT) and SIGTERM during the command end it with one line and exit code 130 or 143
    (:data:`EXIT_CODES`); a run being recorded is kept as failed (:func:`_catch_signals`).
    """

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        received = _received
        received.clear()
        previous = _catch_signals(received)
        try:
            return func(*args, **kwargs)
        except StageError as exc:  # valid input, but a stage could not produce its output: the run failed
            if exc.run_directory is None:  # refused before any run was recorded: the input cannot be run
                err.print(excerpt(f"error: {exc}", MAX_LINE), markup=False, soft_wrap=True)
                raise typer.Exit(2) from None
            err.print("verdict: failed", markup=False, soft_wrap=True)
            for line in (f"error: {exc}", *getattr(exc, "__notes__", ())):
                err.print(line, markup=False, soft_wrap=True)
            raise typer.Exit(1) from None
        except DualarmError as exc:
            err.print(excerpt(f"error: {exc}", MAX_LINE), markup=False, soft_wrap=True)
            raise typer.Exit(2) from None
        except (KeyboardInterrupt, Terminated) as exc:
            if not received:  # raised without our handler (outside the main thread)
                received.append(signal.SIGINT if isinstance(exc, KeyboardInterrupt) else signal.SIGTERM)
        finally:
            for signum, handler in previous.items():
                signal.signal(signum, handler)
            sys.unraisablehook = sys.__unraisablehook__
            if received:  # also when a library swallowed the exception (CasADi turns it into a failed solve)
                what = "interrupted (SIGINT)" if received[0] == signal.SIGINT else "terminated (SIGTERM)"
                err.print(what, markup=False)
                raise typer.Exit(EXIT_CODES[what]) from None  # the signal decides the exit code, whatever the command was doing

    return wrapper


#: The signals the running command received.
_received: list[int] = []


def _raise_swallowed() -> None:
    """Raise again a signal the command received whose exception a library swallowed (CasADi turns it into a failed solve); called between stages."""
    if _received:
        raise KeyboardInterrupt if _received[0] == signal.SIGINT else Terminated()


def _unraisable(unraisable: Any) -> None:
    """``sys.unraisablehook``: silent for the exception of a signal, which Python cannot raise from a ``__del__`` (:func:`_raise_swallowed` raises it again); Python's own hook for anything else."""
    if not issubclass(unraisable.exc_type, (KeyboardInterrupt, Terminated)):
        sys.__unraisablehook__(unraisable)


def _update(status: Status, text: str) -> None:
    """Show ``text`` on the status line, once :func:`_raise_swallowed` let the command go on."""
    _raise_swallowed()
    status.update(text)


def _catch_signals(received: list[int]) -> dict[int, Any]:
    """Install the command's SIGINT and SIGTERM handlers; returns the handlers they replace.

    Each appends its signal to ``received`` and raises (KeyboardInterrupt or
    :class:`~dualarm.errors.Terminated`), so that a run being recorded is kept as failed. SIGINT
    is left alone when it is ignored (a command started in the background); outside the main
    thread nothing is installed.
    """
    if threading.current_thread() is not threading.main_thread():
        return {}

    def handler(signum: int, frame: object) -> None:
        received.append(signum)
        raise KeyboardInterrupt if signum == signal.SIGINT else Terminated()

    sys.unraisablehook = _unraisable  # a signal raised in a __del__ is raised again between stages, without a traceback

    previous: dict[int, Any] = {signal.SIGTERM: signal.signal(signal.SIGTERM, handler)}
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        previous[signal.SIGINT] = signal.signal(signal.SIGINT, handler)
    return previous


#: Largest planning timeout [s].
MAX_TIMEOUT_S = 86_400.0
#: Largest hand position coordinate of ``ik srs --pose`` [m] and largest angle [rad].
MAX_POSITION_M, MAX_ANGLE_RAD = 1e3, 1e3
#: Largest counts: planning trials, benchmark poses, robot check samples, benchmark repeats.
MAX_TRIALS, MAX_POSES, MAX_SAMPLES, MAX_REPEATS = 100_000, 1_000_000, 1_000_000, 1_000


def _out_path(text: str, option: str) -> Path:
    """``text``, given as ``option``, as an output path; an empty one (which ``Path`` would read as the working directory) is refused."""
    if not text.strip():
        raise DualarmError(f"{option} '{excerpt(text)}': an empty path; give a directory or file name")
    if "\0" in text:
        raise DualarmError(f"{option} '{excerpt(text)}': a path cannot hold a NUL byte")
    return Path(text)


def _seed(seed: int, option: str = "--seed") -> int:
    """``seed`` if it is an integer >= 0 (of any size: numpy's Generator takes them all)."""
    if seed < 0:
        raise DualarmError(f"{option} {excerpt(seed)}: a seed is an integer >= 0 (of any size)")
    return seed


def _within(value: float, option: str, low: float, high: float = math.inf, *, above_low: bool = False) -> float:
    """``value``, given as ``option``, if it is finite and in [low, high] ((low, high] with ``above_low``); a DualarmError with the range otherwise."""
    if math.isfinite(value) and (value > low if above_low else value >= low) and value <= high:
        return value
    bounds = f"{'>' if above_low else '>='} {low:g}" if high == math.inf else f"in {'(' if above_low else '['}{low:g}, {high:g}]"
    raise DualarmError(f"{option} {excerpt(value)}: give a finite number {bounds}")


def _stages(stages: str | None) -> list[str] | None:
    """The stages of ``--stages`` (None when not given); a value naming none is refused."""
    if stages is None:
        return None
    from dualarm.run import ALL_STAGES

    chosen = [s.strip() for s in stages.split(",") if s.strip()]
    if not chosen:
        raise DualarmError(f"--stages '{excerpt(stages)}': names no stage (stages: {', '.join(ALL_STAGES)})")
    return chosen


def _record(level: str) -> str:
    """The recording level of ``--record``; another value is refused, naming the levels."""
    from dualarm.record.sink import RECORD_LEVELS

    if level not in RECORD_LEVELS:
        raise DualarmError(f"--record '{excerpt(level)}': unknown recording level (levels: {', '.join(RECORD_LEVELS)})")
    return level


#: Help of ``--record``, with the sizes measured on ``dualarm run triangle --ik mc-inverse --reps 5``.
RECORD_HELP = (
    "How much to record: full (run.mcap and run.rrd hold every stage; 74 MB), ik (they hold the path and ik/plan stages only; 4.9 MB) "
    "or metrics (no run.mcap, no run.rrd: manifest.json and metrics.json only; 9 kB). Every stage runs and is judged whatever the level "
    "(sizes of dualarm run triangle --ik mc-inverse --reps 5)."
)


@app.command()
@user_errors
def run(
    task: Annotated[Path, typer.Argument(help="Task file (TOML), e.g. tasks/triangle.toml, or a shipped task's name (triangle).")],
    stages: Annotated[
        Optional[str],
        typer.Option(
            help="Comma-separated stages to run: path, ik or plan, retime, smooth, approach (from the task's initial configuration to the motion's start), execute (default: all of them when --ik or --planner is given, else path)."
        ),
    ] = None,
    ik: Annotated[Optional[str], typer.Option("--ik", help="IK method of the ik stage: tvgdd, pinv, mc-inverse, sew, trac-ik, pybullet, dls-svd or ikfast-style.")] = None,
    scheme: Annotated[str, typer.Option(help="TV-GDD scheme: mvn (minimum velocity norm), rmp (repetitive motion) or mke (minimum kinetic energy).")] = "mvn",
    qp_backend: Annotated[str, typer.Option(help="TV-GDD QP solver: casadi (DAQP through CasADi conic) or lvi (the paper's projection solver).")] = "casadi",
    lvi_tolerance: Annotated[float, typer.Option(help="Stop of the lvi backend on ||eps(u)||_2 (the paper's 1e-5; its velocity error can be ~35x this, see docs).")] = 1e-5,
    out_text: Annotated[str, typer.Option("--out", help="Directory that receives <task>/<run-id>/ (a recordings directory: runs are added, nothing in it is deleted or overwritten).")] = "recordings",
    seed: Annotated[int, typer.Option(help="Random seed (an integer >= 0), recorded in the manifest.")] = 0,
    reps: Annotated[Optional[int], typer.Option(min=1, help="Repetitions (default: the task file's).")] = None,
    timing: Annotated[
        Optional[str],
        typer.Option(
            help="Retime: jerk-limited (on the path, within the velocity, acceleration and jerk limits), optimal (TOPP-RA, then Ruckig tracking) or task (the task's own timing, checked against the limits); default: the task file's retime.timing."
        ),
    ] = None,
    gui: Annotated[bool, typer.Option("--gui", help="Show the execution in a PyBullet window (needs a display).")] = False,
    execute_anyway: Annotated[
        bool, typer.Option("--execute-anyway", help="Play a trajectory that fails its validation (limits, collisions) for diagnosis; the run is then at best 'violated'.")
    ] = False,
    planner: Annotated[Optional[str], typer.Option(help="Planner of the plan stage: mcikrrt or ompl-rrtconnect (default for a task with [[wta]] and no --ik: mcikrrt).")] = None,
    timeout: Annotated[Optional[float], typer.Option(help="Planning timeout [s] (default 5).")] = None,
    record: Annotated[str, typer.Option("--record", metavar="LEVEL", help=RECORD_HELP)] = "full",
    robot_dir: Annotated[Optional[Path], typer.Option("--robot", help="Robot directory (or shipped robot's name) to run the task on instead of the one it names.")] = None,
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
    if method == "tvgdd":
        settings = _method(method).settings_for(loaded, scheme=scheme, backend=qp_backend, lvi_tolerance=lvi_tolerance)
    elif method is not None and _method(method).kind == "planner":
        settings = _method(method).settings_for(loaded).with_timeout(timeout)
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
    _print_arm_angles(result)
    for line in result.verdict.lines():
        err.print(line, markup=False, soft_wrap=True)
    out.print(str(result.directory), markup=False, soft_wrap=True)
    if result.verdict.exit_code:
        raise typer.Exit(result.verdict.exit_code)


def _print_arm_angles(result) -> None:
    """MC-Inverse's arm-angle profile of a run, one line per hand on stderr (as its manifest records it)."""
    from dualarm.ik.mc_path import arm_angle_profiles, settings_for

    path = result.joint_path
    if path is not None and path.method == "mc-inverse":
        for profile in arm_angle_profiles(path, result.task.robot, settings_for(result.task)):
            err.print(profile.line(), markup=False, soft_wrap=True)


def _method(name: str, kind=None, option: str = "method"):
    """The registered method ``name`` (of ``kind``; a DualarmError naming ``option`` and listing the methods otherwise)."""
    from dualarm.methods import method

    return method(name, kind, option)


def _execution(gui: bool, execute_anyway: bool = False):
    from dualarm.execute.simulate import ExecutionSettings

    return ExecutionSettings(gui=gui, execute_anyway=execute_anyway)


@app.command()
@user_errors
def plan(
    task: Annotated[Path, typer.Argument(help="Task file (TOML) with [[wta]] tables, e.g. tasks/bowl_grasp.toml.")],
    planner: Annotated[str, typer.Option(help="mcikrrt (Li & Liang) or ompl-rrtconnect (OMPL's RRTConnect, same checker and goals).")] = "mcikrrt",
    trials: Annotated[int, typer.Option(min=1, help=f"Planning trials (at most {MAX_TRIALS}); trial i uses seed SEED + i.")] = 100,
    seed: Annotated[int, typer.Option(help="Seed of the first trial (an integer >= 0).")] = 0,
    timeout: Annotated[Optional[float], typer.Option(help="Planning timeout per trial [s] (default 5).")] = None,
    out_text: Annotated[Optional[str], typer.Option("--out", help="Directory for plan_trials.csv and plan_summary.json (default plans/<task>-<planner>).")] = None,
    recordings_text: Annotated[str, typer.Option("--recordings", help="Directory that receives the recorded run of the first successful plan.")] = "recordings",
    robot_dir: Annotated[Optional[Path], typer.Option("--robot", help="Robot directory (or shipped robot's name) to plan the task on instead of the one it names.")] = None,
) -> None:
    """Plan a task repeatedly: per-trial CSV, summary JSON, and the first successful plan retimed, smoothed, executed and recorded as a run; exits 1 when no trial succeeded, else with the verdict of that run (0 complete, 3 violated, 1 failed)."""
    from dualarm.plan.problem import PlanningSettings
    from dualarm.plan.trials import run_trials

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
            progress=lambda done, total: _update(status, f"planning {task}: trial {done}/{total}" + (" (recording the first plan)" if done == total else "")),
            robot=robot_dir,
        )
    s = result.summary
    out.print(
        f"{planner} on {task}: {s['success_rate'] * 100:.0f} % of {s['trials']} trials; planning time median {s['planning_time_median_s'] * 1e3:.1f} ms, p95 {s['planning_time_p95_s'] * 1e3:.1f} ms (paper: {s['paper_planning_time_mean_s'] * 1e3:.2f} ms mean); {s['collision_check_time_mean_s'] * 1e6:.1f} µs per collision check",
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


@app.command()
@user_errors
def reproduce(
    out_text: Annotated[
        Optional[str],
        typer.Option(
            "--out",
            help="Directory that receives every run, table and figure, and report.md (emptied first if it holds only an earlier reproduction); default reports/reproduction, or reports/reproduction-NAME with --robot.",
        ),
    ] = None,
    only: Annotated[Optional[str], typer.Option(help="Comma-separated parts to run (default: all): ball-game-tvgdd, ball-game-pinv, table-i, triangle, circle, carry-box, bowl-grasp.")] = None,
    jobs: Annotated[
        int,
        typer.Option("--jobs", "--workers", min=1, help="Parts run at once: the worker processes of a Dask LocalCluster (default: 2, or 1 on a 1-core machine, which runs the parts in this process)."),
    ] = min(2, os.cpu_count() or 1),
    scheduler: Annotated[
        Optional[str],
        typer.Option(help="An existing Dask cluster's scheduler (tcp://HOST:PORT) to run the parts on instead of a LocalCluster; --out must be on a file system its workers share."),
    ] = None,
    robot_dir: Annotated[
        Optional[Path],
        typer.Option(
            "--robot", help="Robot directory (or shipped robot's name) to run the experiments on instead of the humanoid; a part it cannot run is reported as not available, with the reason."
        ),
    ] = None,
) -> None:
    """Run every experiment of the three papers, record it, and write DIR/report.md: each paper claim against ours (read back from the recordings), the figures, the runs and the time of each part.

    Exits 1 if a part failed (the report says which and why), else 3 if a claim rests on a run whose verdict is not complete (MC-Inverse's runs, TV-GDD's executed ball game, the carried box, the planner's executed plan; a baseline's violations are reported, not fatal), else 2 if no part is available on the robot, else 0. A part not available on the robot is reported, not fatal.
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
    columns = (TextColumn("{task.fields[part]:<16}", markup=False), BarColumn(), TextColumn("{task.percentage:>3.0f} %"), TimeElapsedColumn(), TextColumn("{task.fields[text]}", markup=False))
    with Progress(*columns, console=err, transient=not err.is_terminal) as bar:  # in a file, the bars would print once at the end: the time table says it
        tasks = {name: bar.add_task(BY_NAME[name].title, total=1.0, part=name, text="waiting", start=False) for name in names}

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
    table = Table(title=f"time of each part ({'on ' + scheduler if scheduler else f'{jobs} at a time'})", title_justify="left")
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
        err.print(f"error: no part of the reproduction runs on {robot_name} (the report says why each is not available)", markup=False, soft_wrap=True)
        raise typer.Exit(2)
    if any(c.contradicted for c in claims):
        raise typer.Exit(3)


@app.command()
@user_errors
def inspect(run_dir: Annotated[Path, typer.Argument(help="A run directory (recordings/<task>/<run-id>).")]) -> None:
    """Print a run's verdict (status, error, each violation), topics (message counts and time range) and metrics."""
    from dualarm.record.readback import read_run

    data = read_run(run_dir)
    m = data.manifest
    out.print(f"run      {data.run_id}  ({data.status})", markup=False)
    out.print(f"task     {m.get('task')}  ({m.get('task_file')})", markup=False)
    out.print(f"stages   {', '.join(data.stages)}", markup=False)
    if data.record != "full":
        out.print(f"record   {data.record} ({data.lacks()})", markup=False, soft_wrap=True)
    if m.get("error"):
        out.print(f"error    {m['error']}", markup=False, soft_wrap=True)
    for violation in data.violations:
        out.print(f"violated {violation}", markup=False, soft_wrap=True)
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
    run_dir: Annotated[Path, typer.Argument(help="A run directory (recordings/<task>/<run-id>), recorded with --record full or ik.")],
    web: Annotated[bool, typer.Option("--web", help="Serve the run with Rerun's web viewer on 127.0.0.1 and print the URL to open (no browser is started); serves until Ctrl-C.")] = False,
    stage: Annotated[Optional[str], typer.Option(metavar="STAGE", help="Open Rerun on this stage's robot and plots (one the run recorded: path, ik or plan, retime, smooth, execute).")] = None,
) -> None:
    """Open a recorded run in Rerun's viewer (a window, or with --web the web viewer) and print how to open its run.mcap in Foxglove, with the run's layout.

    The viewer is the rerun command installed with rerun-sdk (beside this Python, or on PATH).
    """
    import tempfile

    from dualarm.record.view import blueprint_file, check_display, check_stage, open_native, rerun_executable, serve_web, viewable

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
    run_dirs: Annotated[list[Path], typer.Argument(help="One or more run directories (recordings/<task>/<run-id>), from this machine or copied from another.")],
    out_text: Annotated[Optional[str], typer.Option("--out", help="Report directory (default reports/<task>/<run-id> for one run, reports/<task or runs>/<first run-id>+<n-1> for several).")] = None,
) -> None:
    """Write a markdown summary and the figures each run's recording allows; for several runs also runs.csv and runs.md (a row per run, every metric), figures setting them side by side and report.md linking it all.

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
    tol: Annotated[float, typer.Option(help="Largest absolute difference accepted, in each field's own unit (a finite number >= 0; 0: identical).")] = 0.0,
    csv_text: Annotated[Optional[str], typer.Option("--csv", help="Also write the whole table (a row per topic and field) to this CSV file (a new file, or one an earlier compare wrote).")] = None,
) -> None:
    """Per topic and field, the largest difference between two runs, aligned on repetition and time; exits 0 when every field is within --tol and 1 otherwise, naming where they differ first.

    Wall-clock measurements (solve, planning, collision-check times) are listed, never judged.
    """
    from dualarm.record.run_dir import write_whole
    from dualarm.report.compare import compare_runs

    _within(tol, "--tol", 0.0)
    csv = _compare_csv(csv_text) if csv_text is not None else None
    with err.status(f"comparing {run_a} and {run_b} ..."):
        result = compare_runs(run_a, run_b, tol)
    table = Table(title=f"A = {run_a}\nB = {run_b}", title_justify="left")
    for column in ("topic", "rows A", "rows B", "aligned", "largest |A - B|", "in field", "at t [s]", "rep", f"within {tol:g}"):
        table.add_column(column, justify="left" if column in ("topic", "in field") else "right", no_wrap=column == "topic")
    judged = result.table[~result.table["wall_clock"]]
    for topic, rows in judged.groupby("topic", sort=False):
        worst = rows.iloc[rows["max_difference"].fillna(-np.inf).argmax()]
        located = ("", "", "") if worst["max_difference"] == 0 else (str(worst["field"]), "" if _missing(worst["t"]) else f"{worst['t']:.3f}", "" if _missing(worst["rep"]) else str(int(worst["rep"])))
        table.add_row(str(topic), str(worst["rows_a"]), str(worst["rows_b"]), str(worst["aligned"]), f"{worst['max_difference']:.3g}", *located, "yes" if worst["max_difference"] <= tol else "NO")
    out.print(table)
    clock = result.table[result.table["wall_clock"]]
    if len(clock):
        out.print(f"not judged (wall clock): {', '.join(f'{r.topic} {r.field}' for r in clock.itertuples())}", markup=False, soft_wrap=True)
    if csv is not None:
        write_whole(csv, result.table.to_csv(index=False))
    if result.within:
        out.print(f"identical within {tol:g} in every judged field", markup=False)
        return
    beyond = result.beyond
    first = beyond.iloc[0]
    where = f"at t = {first['first_beyond_t']:.4f} s, rep {int(first['first_beyond_rep'])}" if not _missing(first["first_beyond_t"]) else "(whole topic or field)"
    out.print(
        f"differ first: {first['topic']} {first['field']} {where}" + (f" ({first['note']})" if first["note"] else f" (largest |A - B| = {first['max_difference']:.3g})"), markup=False, soft_wrap=True
    )
    out.print(
        f"{len(beyond)} fields beyond {tol:g}, earliest first: " + ", ".join(f"{r.topic} {r.field}" for r in beyond.head(12).itertuples()) + (" ..." if len(beyond) > 12 else ""),
        markup=False,
        soft_wrap=True,
    )
    raise typer.Exit(1)


#: How a table ``dualarm compare`` wrote begins.
COMPARE_HEADER = "topic,field,max_difference,"


def _compare_csv(text: str) -> Path:
    """The ``--csv`` path of compare: a new file, or a regular file whose first line is :data:`COMPARE_HEADER` (an earlier compare's table); anything else is refused, untouched."""
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
            raise DualarmError(f"--csv {excerpt(path)}: cannot read it ({exc.strerror}); give another file name") from None
    if not first.startswith(COMPARE_HEADER):
        raise DualarmError(f"--csv {excerpt(path)}: exists and is not a table dualarm compare wrote (it does not begin '{COMPARE_HEADER}'); give another file name")
    return path


def _missing(value) -> bool:
    """Whether a table cell is missing (NaN or None)."""
    return value is None or (isinstance(value, float) and np.isnan(value))


@app.command()
@user_errors
def consistency(
    task: Annotated[Path, typer.Argument(help="Task file (TOML), e.g. tasks/triangle.toml.")],
    methods: Annotated[
        Optional[str], typer.Option(help="Comma-separated IK methods to compare (default: mc-inverse,trac-ik,ikfast-style,pybullet,dls-svd,tvgdd,pinv, those that run on the task's robot).")
    ] = None,
    reps: Annotated[Optional[int], typer.Option(min=1, help="Repetitions (default: the task file's).")] = None,
    out_text: Annotated[Optional[str], typer.Option("--out", help="Output directory (default consistency/<task>).")] = None,
    seed: Annotated[int, typer.Option(help="Random seed (an integer >= 0), recorded in each run's manifest.")] = 0,
    robot_dir: Annotated[Optional[Path], typer.Option("--robot", help="Robot directory (or shipped robot's name) to run the task on instead of the one it names.")] = None,
) -> None:
    """Run each IK method on a repeated task as a recorded run and compare repetition by repetition: consistency.csv, consistency.md and figures; prints the table (with each run's verdict) and the directory.

    Exits 0 when every run is complete, 3 when one is violated (its first violation is printed), 1 when one failed.
    """
    from dualarm.report.consistency import method_label, run_consistency

    out_dir = _out_path(out_text, "--out") if out_text is not None else None
    _seed(seed)
    chosen = [m.strip() for m in methods.split(",") if m.strip()] if methods is not None else None  # None: DEFAULT_METHODS that run on the task's robot
    directory = out_dir or Path("consistency") / task.stem
    with err.status("consistency ...") as status:
        result = run_consistency(task, chosen, directory, reps, seed, progress=lambda text: _update(status, text), robot=robot_dir)
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
        table.add_column(column, justify="left" if column in ("method", "verdict") else "right", no_wrap=column in ("method", "verdict"))
    for _, row in result.table.iterrows():
        if row["status"] == "failed":
            table.add_row(row["method"], f"failed: {row['error']}", *[""] * len(shown))
            continue
        table.add_row(method_label(row), row["status"], *(f"{row[c] * (1e3 if c.endswith('_s') else 1):.3g}" for c in shown))
    out.print(table)
    for _, row in result.table.iterrows():
        if row["status"] != "complete":
            err.print(f"{row['method']}: {row['status']}: {row['error'] or row['violation']}", markup=False, soft_wrap=True)
    out.print(str(directory), markup=False, soft_wrap=True)
    raise typer.Exit(_worst(result.table["status"]))


@app.command()
@user_errors
def study(
    spec_or_report: Annotated[str, typer.Argument(metavar="SPEC.toml | report", help="A study spec file (studies/inconsistency.toml) to run, or the word report.")],
    directory_text: Annotated[Optional[str], typer.Argument(metavar="[DIR]", help="With report: the study's directory.")] = None,
    scheduler: Annotated[Optional[str], typer.Option(help="An existing Dask cluster's scheduler (tcp://HOST:PORT) to run the trials on; default a LocalCluster on this machine.")] = None,
    workers: Annotated[Optional[int], typer.Option(min=1, help="The LocalCluster's worker processes (one thread each; default one per core).")] = None,
    out_text: Annotated[Optional[str], typer.Option("--out", help="The study's directory (default studies/results/<name>).")] = None,
    resume: Annotated[bool, typer.Option("--resume", help="Run only the trials not yet in --out (a study stopped or crashed half-way).")] = False,
    record: Annotated[str, typer.Option(help="metrics (no recordings, the default), ik or full: each trial's runs in DIR/runs (full runs every stage).")] = "metrics",
) -> None:
    """Run a study: every generated trial of SPEC.toml with every method, on Dask (dualarm study SPEC.toml); or write a study's report (dualarm study report DIR).

    A run writes DIR/trials.parquet (one row per trial and method: the trial's features, every ik.* metric, the verdict, wall time, worker), one task file per trial in DIR/tasks, and prints per method P(inconsistent) and P(failed) with 95 % Wilson intervals. A report writes DIR/report.md, its tables (csv) and figures from DIR/trials.parquet alone.

    Exits 0 when every trial has its rows (a method that failed a trial is the study's data, counted in the table), 1 when a row is an error (an exception other than dualarm's, or a trial whose worker died 3 times), 2 on a bad spec or --out (another study's directory, or this study's without --resume).
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
        raise DualarmError(f"unexpected argument '{excerpt(directory_text)}': dualarm study SPEC.toml [--out DIR], or dualarm study report DIR")
    spec, base = load_study(spec_or_report)
    level = _record(record)
    directory = _out_path(out_text, "--out") if out_text is not None else Path("studies") / "results" / spec.name
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    columns = (TextColumn(f"study {spec.name}", markup=False), BarColumn(), MofNCompleteColumn(), TextColumn("{task.fields[text]}", markup=False), TimeElapsedColumn(), TimeRemainingColumn())
    with Progress(*columns, console=err, transient=not err.is_terminal) as bar:
        task = bar.add_task("trials", total=None, text="starting the cluster")

        def on_trial(done: int, failed: int, total: int, errors: int) -> None:
            seconds = bar.tasks[task].elapsed or 1e-9
            bar.update(task, completed=done, total=total, text=f"{failed} with a failed method, {errors} errors, {done / seconds:.2f} trials/s")

        result = run_study(spec, base, directory, scheduler=scheduler, workers=workers, resume=resume, record=level, progress=on_trial)
    rates = method_rates(result.results)
    table = Table(
        title=f"study {spec.name}: {result.results['trial'].nunique()} trials ({result.ran} now in {result.seconds:.1f} s on {result.workers} workers, after {result.startup_s:.1f} s starting them)",
        title_justify="left",
    )
    for column in ("method", "trials", "P(inconsistent) [95 %]", "P(failed) [95 %]", "errors"):
        table.add_column(column, justify="left" if column == "method" else "right")
    for r in rates.itertuples():
        table.add_row(
            str(r.method),
            str(r.trials),
            f"{r.p_inconsistent:.3f} [{r.p_inconsistent_low:.3f}, {r.p_inconsistent_high:.3f}]",
            Text(f"{r.p_failed:.3f} [{r.p_failed_low:.3f}, {r.p_failed_high:.3f}]", style="yellow" if r.failed else ""),
            Text(str(r.errors), style="red" if r.errors else ""),
        )
    out.print(table)
    out.print(f"{directory / 'trials.parquet'} (dualarm study report {directory})", markup=False, soft_wrap=True)
    errors = result.results[result.results["status"] == "error"]
    if len(errors):
        first = errors.iloc[0]
        err.print(f"error: {len(errors)} rows are errors, the first trial {first['trial']} {first['method']}: {first['error']}", markup=False, soft_wrap=True)
        raise typer.Exit(1)


def _worst(statuses) -> int:
    """The exit code of several runs' verdicts: 1 if one failed, else 3 if one was violated, else 0."""
    from dualarm.verdict import EXIT_CODES

    return max((EXIT_CODES[s] for s in statuses), key=lambda code: (code == 1, code), default=0)


@bench_app.command("tvgdd")
@user_errors
def bench_tvgdd_command(
    task: Annotated[Path, typer.Option(help="Task to run TV-GDD on.")] = Path("tasks/ball_game.toml"),
    repeats: Annotated[int, typer.Option(min=1, help=f"Repeats of the one-call rollout (best is kept; at most {MAX_REPEATS}).")] = 5,
    plugins: Annotated[str, typer.Option(help="Comma-separated CasADi conic plugins to compare with DAQP, e.g. qpoases,osqp,proxqp,qrqp.")] = "",
) -> None:
    """TV-GDD per-step median and p99 of the casadi and LVI backends, their ratio, and the whole-task IK time against the paper's T_ave = 1 ms and T_sum = 1.12 s (optionally other conic plugins for the casadi backend)."""
    from dualarm.bench.tvgdd import PAPER_T_AVE_S, PAPER_T_SUM_S, bench_tvgdd

    _within(repeats, "--repeats", 1, MAX_REPEATS)
    with err.status("benchmarking ...") as status:
        rows = bench_tvgdd(task, repeats, tuple(p.strip() for p in plugins.split(",") if p.strip()), progress=lambda text: status.update(text))
    table = Table(title=f"TV-GDD on {task} ({rows[0].steps} steps)", title_justify="left")
    for column in ("solver", "median µs", "p99 µs", "task s", "T_ave/ours", "T_sum/ours", "max |Δq̇| rad/s"):
        table.add_column(column, justify="left" if column == "solver" else "right")
    for r in rows:
        table.add_row(
            r.name, f"{r.median_s * 1e6:.1f}", f"{r.p99_s * 1e6:.1f}", f"{r.total_s:.4f}", f"{PAPER_T_AVE_S / r.median_s:.1f}x", f"{PAPER_T_SUM_S / r.total_s:.1f}x", f"{r.velocity_gap_rad_s:.2g}"
        )
    out.print(table)
    for r in rows:
        if r.failure:
            out.print(f"{r.name} failed: {r.failure}", markup=False, soft_wrap=True)
    out.print(f"per-step median, lvi / casadi: {rows[1].median_s / rows[0].median_s:.1f}x", markup=False)
    out.print("max |Δq̇|: largest joint-velocity difference from the first row along the task (lvi stops at ||eps|| <= 1e-5, as published)", markup=False)


def _robot(robot_dir: Optional[Path], urdf: Optional[Path], base: Optional[str], tip: Optional[str]):
    """The robot of ``ROBOT_DIR`` or of ``--urdf PATH --base LINK --tip LINK`` (one chain named ``chain``)."""
    from dualarm.model.robot import load_robot, robot_from_urdf

    if robot_dir is not None and urdf is None:
        return load_robot(robot_dir)
    if robot_dir is not None or urdf is None:  # both given, or neither
        raise DualarmError("give either ROBOT_DIR or --urdf PATH --base LINK --tip LINK")
    if not base or not tip:
        raise DualarmError("--urdf needs --base LINK and --tip LINK")
    return robot_from_urdf(urdf, base, tip)


#: What every ``dualarm ik`` command takes to name an arm and a hand pose.
PoseOption = Annotated[tuple[float, float, float, float, float, float], typer.Option(help="Hand pose: X Y Z [m] ROLL PITCH YAW [rad] (extrinsic x-y-z, as in task files), in the frame of --frame.")]
ArmRobotArgument = Annotated[Optional[Path], typer.Argument(help="Robot directory holding robot.toml (with --arm).")]
ArmOption = Annotated[Optional[str], typer.Option(help="Which arm of ROBOT_DIR: left or right.")]
UrdfOption = Annotated[Optional[Path], typer.Option(help="A bare URDF instead (needs --base and --tip).")]
BaseLinkOption = Annotated[Optional[str], typer.Option(help="Base link of the arm chain (with --urdf).")]
TipLinkOption = Annotated[Optional[str], typer.Option(help="Tip link of the arm chain (with --urdf).")]
FrameOption = Annotated[str, typer.Option(help="Frame of --pose: robot (the URDF's root link, waist at 0; as task files) or chain (the arm chain's base).")]


def _arm_chain(robot_dir: Optional[Path], arm: Optional[str], urdf: Optional[Path], base: Optional[str], tip: Optional[str]):
    """(robot, arm chain) of ``ROBOT_DIR --arm SIDE`` or of ``--urdf PATH --base LINK --tip LINK``."""
    robot = _robot(robot_dir, urdf, base, tip)
    if urdf is not None:
        return robot, robot.chain("chain")
    if arm not in ("left", "right"):
        raise DualarmError("give --arm left or --arm right with ROBOT_DIR")
    return robot, robot.hand_chain(arm)


def _pose(pose: tuple[float, ...], frame: str) -> None:
    """Refuse a --pose value outside the ranges task files allow, and a --frame other than robot or chain."""
    for name, value, bound in zip(("X", "Y", "Z", "ROLL", "PITCH", "YAW"), pose, (MAX_POSITION_M,) * 3 + (MAX_ANGLE_RAD,) * 3):
        _within(value, f"--pose {name}", -bound, bound)
    if frame not in ("robot", "chain"):
        raise DualarmError(f"--frame '{excerpt(frame)}': give robot or chain")


@ik_app.command("srs")
@user_errors
def ik_srs(
    pose: PoseOption,
    arm_angle: Annotated[Optional[float], typer.Option(help="Arm angle psi of MC-Inverse eq (1) [rad] (not with --sweep).")] = None,
    robot_dir: ArmRobotArgument = None,
    arm: ArmOption = None,
    urdf: UrdfOption = None,
    base: BaseLinkOption = None,
    tip: TipLinkOption = None,
    vertical: Annotated[tuple[float, float, float], typer.Option(help="Vertical vector V of the arm angle's reference plane, in the chain base frame.")] = (0.0, 0.0, 1.0),
    frame: FrameOption = "robot",
    sweep: Annotated[bool, typer.Option("--sweep", help="Instead of one arm angle: the feasible psi intervals (within the joint limits) of each of the 8 branches.")] = False,
    step: Annotated[float, typer.Option(help="Grid step of --sweep [deg], in [0.01, 30].")] = 1.0,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON: {chain, frame, pose, arm_angle, candidates}; with --sweep {chain, frame, pose, step_rad, branches}.")] = False,
) -> None:
    """The 8 MC-Inverse candidates of one hand pose at one arm angle, with validity and the error of each candidate's forward kinematics (the analogue of the paper's Table I); with --sweep, the arm angles at which each branch reaches the pose within the joint limits."""
    import json

    from dualarm.ik.mc_inverse import PoseFrame, candidate_table

    _pose(pose, frame)
    if sweep:
        if arm_angle is not None:
            raise DualarmError("give either --arm-angle PSI or --sweep")
        _within(step, "--step", 0.01, 30.0)
    elif arm_angle is None:
        raise DualarmError("give --arm-angle PSI (or --sweep for every arm angle)")
    else:
        _within(arm_angle, "--arm-angle", -MAX_ANGLE_RAD, MAX_ANGLE_RAD)
    for value in vertical:
        _within(value, "--vertical", -MAX_POSITION_M, MAX_POSITION_M)
    robot, chain = _arm_chain(robot_dir, arm, urdf, base, tip)
    if not np.linalg.norm(vertical) > 0:
        raise DualarmError("--vertical must not be zero")
    where = PoseFrame.robot_base(robot, chain) if frame == "robot" else PoseFrame.chain_base(chain)
    if sweep:
        _ik_srs_sweep(chain, pose, vertical, where, math.radians(step), as_json)
        return
    assert arm_angle is not None
    data = candidate_table(chain, pose, arm_angle, vertical, where)
    candidates = data["candidates"]
    if as_json:
        typer.echo(json.dumps(data, indent=2))
        return
    _print_candidates(f"MC-Inverse, {chain.base} -> {chain.tip}, pose in the {frame} frame ({where.link}), psi = {arm_angle:g} rad", candidates, "arm_angle_rad")
    out.print(f"joints: {', '.join(chain.joint_names)}; {sum(c['valid'] for c in candidates)} of 8 valid", markup=False)


@ik_app.command("sew")
@user_errors
def ik_sew(
    pose: PoseOption,
    sew_angle: Annotated[float, typer.Option(help="SEW angle psi [rad]: the elbow's turn about the shoulder-wrist line from the reference half-plane.")],
    robot_dir: ArmRobotArgument = None,
    arm: ArmOption = None,
    urdf: UrdfOption = None,
    base: BaseLinkOption = None,
    tip: TipLinkOption = None,
    reference: Annotated[tuple[float, float, float], typer.Option(help="Reference direction e_r of psi = 0, in the chain base frame.")] = (0.0, 0.0, 1.0),
    singular: Annotated[
        tuple[float, float, float], typer.Option(help="Stereographic SEW angle: the direction e_t of its singular half-line from the shoulder, in the chain base frame (keep it out of reach).")
    ] = (0.0, 0.0, -1.0),
    conventional: Annotated[bool, typer.Option("--conventional", help="The conventional SEW angle (singular along the whole line through the shoulder along e_r) instead.")] = False,
    frame: FrameOption = "robot",
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON: {chain, frame, pose, sew_angle, reference, singular, candidates}.")] = False,
) -> None:
    """Every solution of one hand pose at one SEW angle for a 7R arm of a SEW family (joints 2-3 and 5-7 meet: an offset humanoid shoulder, any S-R-S arm; or joints 1-3 and 5-6: the Panda), with validity and the error of each solution's forward kinematics (Elias and Wen; the analogue of ik srs).

    Exits 2 with one line for an arm of another family, or when no solution exists at that SEW angle (the pose out of reach, or the elbow unable to lie in that half-plane).
    """
    import json

    from dualarm.errors import UnreachablePoseError
    from dualarm.ik.mc_inverse import PoseFrame
    from dualarm.ik.sew import SewAngle, candidate_table

    _pose(pose, frame)
    _within(sew_angle, "--sew-angle", -MAX_ANGLE_RAD, MAX_ANGLE_RAD)
    directions = {"--reference": np.asarray(reference, dtype=float), "--singular": np.asarray(singular, dtype=float)}
    for option, direction in directions.items():
        if not (np.all(np.isfinite(direction)) and np.linalg.norm(direction) > 0):
            raise DualarmError(f"{option} must be a finite non-zero direction")
    e_r, e_t = (v / np.linalg.norm(v) for v in directions.values())
    if not conventional and np.linalg.norm(np.cross(e_r, e_t)) < 1e-9 and e_r @ e_t > 0:
        raise DualarmError("--singular must not point along --reference (the stereographic angle needs e_t != e_r)")
    robot, chain = _arm_chain(robot_dir, arm, urdf, base, tip)
    where = PoseFrame.robot_base(robot, chain) if frame == "robot" else PoseFrame.chain_base(chain)
    sew = SewAngle(reference=(float(e_r[0]), float(e_r[1]), float(e_r[2])), singular=None if conventional else (float(e_t[0]), float(e_t[1]), float(e_t[2])))
    candidates = candidate_table(robot, chain, where.to_chain(pose), sew_angle, sew)
    if not candidates:
        raise UnreachablePoseError(f"no solution at psi = {sew_angle:g} rad: the pose is out of reach, or this SEW angle puts the elbow where the arm cannot reach it")
    if as_json:
        data = {
            "chain": {"base": chain.base, "tip": chain.tip, "joints": list(chain.joint_names)},
            "frame": where.record(),
            "pose": list(pose),
            "sew_angle": sew_angle,
            "reference": list(sew.reference),
            "singular": list(sew.singular) if sew.singular is not None else None,
            "candidates": candidates,
        }
        typer.echo(json.dumps(data, indent=2))
        return
    kind = "conventional" if conventional else "stereographic"
    _print_candidates(f"SEW IK, {chain.base} -> {chain.tip}, pose in the {frame} frame ({where.link}), {kind} psi = {sew_angle:g} rad", candidates, "sew_angle_rad")
    out.print(f"joints: {', '.join(chain.joint_names)}; {len(candidates)} solutions, {sum(c['valid'] for c in candidates)} within the joint limits", markup=False)


def _sew_line(chain) -> str:
    """``robot check``'s line on a 7-DOF chain's SEW family (what ``--ik sew`` and ``ik sew`` need), or why it has none."""
    from dualarm.ik.sew import FIRST_JOINT_FAMILY, sew_chain

    try:
        arm = sew_chain(chain)
    except NotSRSError as exc:
        return f"no SEW family: {exc}"
    first = arm.family == FIRST_JOINT_FAMILY
    offset = float(np.linalg.norm(arm.crossing - arm.shoulder if first else arm.wrist - arm.crossing))
    where = "shoulder (joints 2-3 from axis 1)" if first else "wrist (axis 7 from joints 5-6)"
    return f"SEW family {arm.family} (--ik sew, ik sew): S = {(np.round(arm.shoulder, 4) + 0.0).tolist()} m, {where} offset {offset:.4f} m"


def _print_candidates(title: str, candidates: list[dict], angle: str) -> None:
    """``ik srs``'s and ``ik sew``'s table: each candidate's joints, validity (the reason's head), FK errors and its angle (the key ``angle``)."""
    table = Table(title=title, title_justify="left")
    for column in ("#", *[f"θ{i}" for i in range(1, 8)], "validity", "pos. err [m]", "rot. err [rad]", "ψ of q [rad]"):
        table.add_column(column, justify="left" if column == "validity" else "right", no_wrap=True)
    for i, c in enumerate(candidates):
        table.add_row(str(i + 1), *(f"{v:.4f}" for v in c["q"]), c["reason"].split(" at ")[0], f"{c['position_error_m']:.1e}", f"{c['orientation_error_rad']:.1e}", f"{c[angle]:.4f}")
    out.print(table)


def _ik_srs_sweep(chain, pose: tuple[float, ...], vertical: tuple[float, float, float], frame, step_rad: float, as_json: bool) -> None:
    """``ik srs --sweep``: each branch's feasible arm-angle intervals at ``pose`` (in ``frame``), as a table or JSON."""
    import json

    from dualarm.ik.mc_inverse import McInverse, branch_label, sweep_arm_angle, sweep_table

    length = float(np.linalg.norm(vertical))
    result = sweep_arm_angle(McInverse.of(chain, (vertical[0] / length, vertical[1] / length, vertical[2] / length)), frame.to_chain(pose), step_rad)
    rows = sweep_table(result)
    if as_json:
        data = {"chain": {"base": chain.base, "tip": chain.tip, "joints": list(chain.joint_names)}, "frame": frame.record(), "pose": list(pose), "step_rad": step_rad, "branches": rows}
        typer.echo(json.dumps(data, indent=2))
        return
    table = Table(title=f"MC-Inverse arm-angle sweep, {chain.base} -> {chain.tip}, pose in the {frame.kind} frame ({frame.link}), step {math.degrees(step_rad):g} deg", title_justify="left")
    for column in ("branch", "feasible psi [rad]", "samples"):
        table.add_column(column, justify="right" if column == "samples" else "left", no_wrap=column == "branch")
    for b, row in enumerate(rows):
        spans = ", ".join(f"[{lo:.4f}, {hi:.4f}]" if hi <= math.pi else f"[{lo:.4f}, {hi - 2 * math.pi:.4f}] across ±pi" for lo, hi in row["intervals_rad"]) or f"none ({row['blocked_by']})"
        table.add_row(branch_label(b), spans, str(row["valid_samples"]))
    out.print(table)
    feasible = sum(bool(r["intervals_rad"]) for r in rows)
    out.print(f"{feasible} of 8 branches reach the pose within the joint limits; interval ends are grid samples (the true ends lie within one step outside)", markup=False)


@task_app.command("check")
@user_errors
def task_check(
    task: Annotated[str, typer.Argument(help="Task file (TOML), or a shipped task's name.")],
    robot_dir: Annotated[Optional[Path], typer.Option("--robot", help="Robot directory to check the task on instead of the one it names.")] = None,
) -> None:
    """Validate a task without running it: schema, robot, and every waypoint's reach within the joint limits (per waypoint the hand pose and, for an S-R-S arm, the MC-Inverse branches and psi intervals that reach it); exits 3 when a waypoint is unreachable, 2 for a malformed task."""
    from dualarm.tasks.check import check_task, report_lines, unreachable_lines

    result = check_task(task, robot_dir)
    if not result.waypoints:
        out.print(f"{result.source}: valid; no waypoints to check (the hands start at the initial configuration and move by displacements or arcs)", markup=False, soft_wrap=True)
    for line in report_lines(result):
        out.print(line, markup=False, soft_wrap=True)
    for line in unreachable_lines(result):
        err.print(line, markup=False, soft_wrap=True)
    if result.unreachable:
        raise typer.Exit(EXIT_CODES["violated"])


@bench_app.command("ik")
@user_errors
def bench_ik_command(
    robot_dir: Annotated[Path, typer.Argument(help="Robot directory.")] = Path("robots/humanoid"),
    arm: Annotated[str, typer.Option(help="Arm whose chain is solved: left or right.")] = "left",
    poses: Annotated[int, typer.Option(min=1, help=f"Random reachable poses (at most {MAX_POSES}).")] = 10_000,
    seed: Annotated[int, typer.Option(help="Seed of the random configurations (an integer >= 0).")] = 0,
) -> None:
    """The arm's analytic IK time per pose called singly and batched (MC-Inverse's 8 candidates on an S-R-S arm, SEW's solutions on an arm of the SEW family such as the Panda) and its analytic peer IK-Geo's, and DLS-SVD, TRAC-IK and PyBullet IK time and success rate, on the same random reachable poses, with ratios."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TaskID, TextColumn, TimeElapsedColumn

    from dualarm.bench.ik import IK_GEO, MC_BATCHED, MC_SINGLE, SEW_BATCHED, TARGET_BATCHED_S, TARGET_DLS_SUCCESS, TARGET_SINGLE_S, bench_ik, ratios
    from dualarm.model.robot import load_robot

    _seed(seed)
    _within(poses, "--poses", 1, MAX_POSES)
    model = load_robot(robot_dir)
    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(), console=err, transient=True) as bar:
        tasks: dict[str, TaskID] = {}

        def progress(name: str, done: int, total: int) -> None:
            if name not in tasks:
                tasks[name] = bar.add_task(name, total=total)
            bar.update(tasks[name], completed=done)

        rows = bench_ik(model, arm, poses, seed, progress)
    ratio = ratios(rows)
    by_name = {r.name: r for r in rows}
    reference = MC_BATCHED if MC_BATCHED in by_name else SEW_BATCHED
    table = Table(title=f"IK of the {arm} arm of {model.name} on {poses} random reachable poses (seed {seed})", title_justify="left")
    for column in ("solver", "mean µs/pose", "median µs/pose", "success", f"time / {reference}"):
        table.add_column(column, justify="left" if column == "solver" else "right")
    for r in rows:
        table.add_row(r.name, f"{r.mean_s * 1e6:.2f}", f"{r.median_s * 1e6:.2f}", f"{r.success_rate:.2%}", f"{ratio[r.name]:.3g}x")
    out.print(table)
    for r in rows:
        out.print(f"- {r.name}: {r.note}", markup=False, soft_wrap=True)
    if MC_BATCHED in by_name:
        single, batched = by_name[MC_SINGLE], by_name[MC_BATCHED]
        out.print(
            f"targets: MC-Inverse single <= {TARGET_SINGLE_S * 1e6:.0f} µs median ({single.median_s * 1e6:.2f}; {single.median_s / by_name[IK_GEO].median_s:.2f}x IK-Geo's median), "
            f"batched <= {TARGET_BATCHED_S * 1e6:.0f} µs/pose ({batched.mean_s * 1e6:.2f}), DLS-SVD success >= {TARGET_DLS_SUCCESS:.1%} ({by_name['DLS-SVD'].success_rate:.2%})"
        )


@bench_app.command("pipeline")
@user_errors
def bench_pipeline_command() -> None:
    """Each stage's share of a whole recorded run, on the triangle and the circle (MC-Inverse) and the ball game (TV-GDD), and MC-Inverse's auto arm-angle search alone."""
    from dualarm.bench.pipeline import PARTS, SEARCH_REPEATS, bench_pipeline

    with err.status("benchmarking ...") as status:
        timings = bench_pipeline(progress=lambda text: status.update(f"benchmarking {text} ..."))
    table = Table(title="share of a whole run (dualarm run TASK --ik METHOD, recording included)", title_justify="left")
    for column in ("task", "ik", *PARTS, "total s", "motion s", "run / motion"):
        table.add_column(column, justify="left" if column in ("task", "ik") else "right")
    for r in timings:
        table.add_row(r.task, r.ik, *(f"{r.seconds.get(p, 0.0) / r.total_s:.1%}" for p in PARTS), f"{r.total_s:.2f}", f"{r.motion_s:.2f}", f"{r.total_s / r.motion_s:.2f}x" if r.motion_s else "-")
    out.print(table)
    for r in timings:
        for hand, (seconds, samples, angles) in r.search.items():
            out.print(f"{r.task}, {hand} arm: the auto arm-angle search alone {seconds * 1e3:.0f} ms (median of {SEARCH_REPEATS}; {samples} samples x {angles} angles x 8 branches)", markup=False)


@bench_app.command("study")
@user_errors
def bench_study_command(
    spec_file: Annotated[Path, typer.Argument(help="A study spec (default the example, studies/inconsistency.toml).")] = Path("studies/inconsistency.toml"),
    workers: Annotated[int, typer.Option(min=1, help="Workers of the scaling, two-node and whole runs.")] = 2,
    scaling_trials: Annotated[int, typer.Option(min=1, help="Trials of the scaling and two-node runs (the spec's first).")] = 100,
    whole: Annotated[bool, typer.Option(help="Also run every trial of the spec (the example: 1,000 trials x 7 methods).")] = True,
    whole_out: Annotated[
        Optional[str], typer.Option("--out", help="Keep the whole study's directory here (as dualarm study --out writes it; dualarm study report reads it); default a temporary directory.")
    ] = None,
) -> None:
    """A study on Dask: trials per second per worker on 1 and on --workers workers (LocalCluster), per method; the same trials in plain processes without Dask (what the machine gives) and on workers started apart on 127.0.0.1 (two nodes) compared row by row; the whole study's time with the trials' sizes; the hypervisor's share of CPU time (steal) during each run.

    Exits 1 when the two-node run's rows differ from the LocalCluster's (but for times, workers and TRAC-IK's rows, whose timeout is wall-clock).
    """
    from dualarm.bench.study import StudyBench, bench_study, method_seconds, trial_sizes
    from dualarm.study import load_study

    spec, base = load_study(spec_file)
    with err.status("benchmarking ...") as status:
        kept = _out_path(whole_out, "--out") if whole_out is not None else None
        bench = bench_study(spec, base, workers=workers, scaling_trials=scaling_trials, whole=whole, whole_out=kept, progress=lambda text: _update(status, f"benchmarking: {text} ..."))
    table = Table(title=f"study {spec.name} on this machine ({os.cpu_count()} cores)", title_justify="left")
    for column in ("run", "workers", "trials", "startup s", "trials s", "trials/s per worker", "x 1 worker", "steal"):
        table.add_column(column, justify="left" if column == "run" else "right")
    runs = [("LocalCluster", "one", bench.one), ("LocalCluster", "many", bench.many), ("workers started apart", "nodes", bench.nodes)] + (
        [("whole study", "whole", bench.whole)] if bench.whole else []
    )
    for name, key, r in runs:
        rate = StudyBench.rate(r)
        table.add_row(name, str(r.workers), str(r.ran), f"{r.startup_s:.1f}", f"{r.seconds:.1f}", f"{rate:.3f}", f"{rate / StudyBench.rate(bench.one):.3f}", f"{bench.steal[key]:.1%}")
    for key, p in (("plain_one", bench.plain_one), ("plain_many", bench.plain_many)):
        table.add_row(
            "plain processes, no Dask", str(len(p.trials)), str(sum(p.trials)), "-", f"{max(p.seconds):.1f}", f"{p.rate:.3f}", f"{p.rate / bench.plain_one.rate:.3f}", f"{bench.steal[key]:.1%}"
        )
    out.print(table)
    methods = Table(title=f"mean time per trial on 1 and on {bench.many.workers} workers (LocalCluster)", title_justify="left")
    for column in ("method", "1 worker s", f"{bench.many.workers} workers s", "ratio"):
        methods.add_column(column, justify="left" if column == "method" else "right")
    for method, row in method_seconds(bench.one, bench.many).iterrows():
        methods.add_row(str(method), f"{row.one_s:.3f}", f"{row.many_s:.3f}", f"{row.ratio:.2f}")
    out.print(methods)
    for what, value in trial_sizes((bench.whole or bench.many).results).items():
        out.print(f"{what}: {value}", markup=False, soft_wrap=True)
    if bench.whole is not None:
        out.print(f"whole study: {bench.whole.ran} trials x {len(spec.methods)} methods in {(bench.whole.startup_s + bench.whole.seconds) / 60:.1f} min, cluster start included", markup=False)
    if bench.nodes_differ:
        err.print(f"the two-node run's rows differ from the LocalCluster's in: {', '.join(bench.nodes_differ)}", markup=False, soft_wrap=True)
        raise typer.Exit(1)
    out.print(f"two nodes: {bench.compared_rows} rows identical bit for bit to the LocalCluster's (times, workers and TRAC-IK's rows left out)", markup=False)


@bench_app.command("trajectory")
@user_errors
def bench_trajectory_command() -> None:
    """The jerk-limited timing against TOPP-RA (0.9/0.3 and 1.0/1.0) with Ruckig tracking, on the triangle, the circle, the ball game and the bowl grasp: duration and its ratio to TOPP-RA at full limits, limit ratios by finite differences (red above 1 + 1e-6), path deviation per joint and at the hands, compute time. Exits 1 if a method failed, 3 if a motion exceeds a limit."""
    from dualarm.bench.trajectory import bench_trajectory
    from dualarm.limits import LIMIT_TOLERANCE

    with err.status("benchmarking ...") as status:
        rows = bench_trajectory(progress=lambda text: status.update(f"benchmarking {text} ..."))
    table = Table(
        title="trajectory generation on each task's joint path: velocity, acceleration and jerk limit ratios by finite differences of the motion's positions (red above 1 + 1e-6); deviation from the path per joint and at the hands; compute time per second of motion",
        title_justify="left",
    )
    for column in ("task", "method", "duration s", "× TOPP-RA 1.0/1.0", "v", "a", "j", "Δq rad", "Δhand µm", "ms / s"):
        table.add_column(column, justify="left" if column in ("task", "method") else "right", no_wrap=True)
    for r in rows:
        if r.failure:
            table.add_row(r.task, r.method, "failed", *["-"] * 7)
            continue
        table.add_row(
            r.task,
            r.method,
            f"{r.duration_s:.3f}",
            f"{r.duration_s / r.optimal_s:.3f}" if r.optimal_s else "-",
            *(Text(f"{x:.6f}", style="bold red" if x > 1 + LIMIT_TOLERANCE else "") for x in r.ratios),
            f"{r.deviation_rad:.2e}",
            f"{r.hand_deviation_m * 1e6:.3g}" if r.hand_deviation_m < 1e-3 else f"{r.hand_deviation_m * 1e6:.0f}",
            f"{r.compute_s / r.duration_s * 1e3:.1f}" if r.duration_s else "-",
        )
    Console(highlight=False, emoji=False, width=max(out.width, 150), file=out.file).print(table)  # ten columns of numbers, none cut
    exceeded = [
        f"- {r.task}, {r.method}: its {kind} reaches {x:.7f} times the limit"
        for r in rows
        if not r.failure
        for kind, x in zip(("velocity", "acceleration", "jerk"), r.ratios)
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
    """MCIKRRT against OMPL RRTConnect on the same problem, checker and goals: planning times and their ratio, collision checks and the time of one check; then the time of one check by PyBullet's narrow phase (the reference) and by the planners' closed-form checker, on the same configurations."""
    from dualarm.bench.plan import bench_plan
    from dualarm.plan.trials import PAPER_PLANNING_TIME_S

    _seed(seed)
    _within(trials, "--trials", 1, MAX_TRIALS)
    with err.status("benchmarking ...") as status:
        bench = bench_plan(task, trials, seed, progress=lambda text: status.update(f"benchmarking {text} ..."))
    table = Table(title=f"planning {task} ({trials} trials each, interleaved)", title_justify="left")
    for column in ("planner", "success", "median ms", "p95 ms", "mean ms", "checks (median)", "µs / check", "path rad (median)", "paper mean / ours"):
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
    checks = Table(title=f"one collision check, the same {bench.configurations} configurations of planner-like edges (fastest of the rounds)", title_justify="left")
    for column in ("checker", "configurations given", "per call", "µs / check", "pybullet / this"):
        checks.add_column(column, justify="left" if column in ("checker", "configurations given") else "right", no_wrap=True)
    reference = bench.checkers[0].check_time_s
    for c in bench.checkers:
        checks.add_row(c.checker, c.batch, str(c.batch_size), f"{c.check_time_s * 1e6:.2f}", f"{reference / c.check_time_s:.1f}x")
    out.print(checks)
    out.print(f"verdicts that differ between the two checkers: {bench.disagreements} of {bench.configurations}", markup=False)


@robot_app.command("check")
@user_errors
def robot_check(
    robot_dir: Annotated[Optional[Path], typer.Argument(help="Robot directory holding robot.toml (e.g. robots/humanoid).")] = None,
    urdf: Annotated[Optional[Path], typer.Option(help="Check one chain of a bare URDF instead (needs --base and --tip).")] = None,
    base: Annotated[Optional[str], typer.Option(help="Base link of the chain (with --urdf).")] = None,
    tip: Annotated[Optional[str], typer.Option(help="Tip link of the chain (with --urdf).")] = None,
    samples: Annotated[int, typer.Option(min=1, help=f"Random configurations per chain (at most {MAX_SAMPLES}).")] = 1000,
    seed: Annotated[int, typer.Option(help="Seed of the random configurations (an integer >= 0).")] = 0,
) -> None:
    """Print chains, DOF and limits, and check the CasADi kinematics against adam-robotics, PyBullet and finite differences; exit 0 only if every figure is within tolerance."""
    from dualarm.model.check import FK_TOLERANCE, JACOBIAN_TOLERANCE, PYBULLET_TOLERANCE, check_chain, require_limits
    from dualarm.model.srs import srs_geometry

    _seed(seed)
    _within(samples, "--samples", 1, MAX_SAMPLES)
    robot = _robot(robot_dir, urdf, base, tip)
    require_limits(robot)
    out.print(f"robot {robot.name}: {robot.urdf.path}  ({len(robot.joint_names)} movable joints)", markup=False)
    results = []
    for chain in robot.chains.values():
        out.print(f"\nchain {chain.name}: {chain.base} -> {chain.tip}, {chain.dof} DOF" + (f", hand '{chain.hand}'" if chain.hand else ""), markup=False)
        limits = Table(show_edge=False, pad_edge=False)
        for column in ("joint", "lower [rad]", "upper [rad]", "vel [rad/s]", "acc [rad/s²]", "jerk [rad/s³]"):
            limits.add_column(column, justify="left" if column == "joint" else "right")
        for name in chain.joint_names:
            lim = robot.limits[name]
            limits.add_row(name, *(f"{v:.4g}" for v in (lim.lower, lim.upper, lim.velocity, lim.acceleration, lim.jerk)))
        out.print(limits)
        if chain.dof == 7:
            try:
                g = srs_geometry(chain)
                out.print(
                    f"S-R-S: shoulder S = {(np.round(g.shoulder, 4) + 0.0).tolist()} m, L2 = {g.upper_arm:.4f} m, "
                    f"L3 = {g.forearm:.4f} m, wrist-to-tip = {(np.round(g.tool_from_wrist, 4) + 0.0).tolist()} m",
                    markup=False,
                )
            except NotSRSError as exc:
                out.print(f"not S-R-S: {exc}", markup=False)
            out.print(_sew_line(chain), markup=False)
        with err.status(f"checking {chain.name} on {samples} configurations ..."):
            results.append(check_chain(robot, chain, samples=samples, seed=seed))
    table = Table(title=f"kinematics check ({samples} random configurations per chain, seed {seed})", title_justify="left")
    for column in ("chain", "FK vs adam [m]", "[rad]", "FK vs PyBullet [m]", "[rad]", "Jacobian vs FD", "result"):
        table.add_column(column, justify="left" if column == "chain" else "right")
    for r in results:
        table.add_row(
            r.chain,
            f"{r.fk_position_error_m:.2e}",
            f"{r.fk_rotation_error_rad:.2e}",
            f"{r.pybullet_position_error_m:.2e}",
            f"{r.pybullet_rotation_error_rad:.2e}",
            f"{r.jacobian_error:.2e}",
            "pass" if r.passed else "FAIL",
        )
    out.print(table)
    out.print(
        f"tolerances: FK vs adam-robotics (double precision) {FK_TOLERANCE:g} m / rad; FK vs PyBullet "
        f"{PYBULLET_TOLERANCE:g} (PyBullet reports link poses in single precision); Jacobian {JACOBIAN_TOLERANCE:g}",
        markup=False,
    )
    if not all(r.passed for r in results):
        raise typer.Exit(1)


@robot_app.command("init")
@user_errors
def robot_init(
    urdf: Annotated[Path, typer.Argument(help="The robot's URDF (mesh paths: package:// through ROS_PACKAGE_PATH or the URDF's own folders, file://, absolute or relative).")],
    out_dir: Annotated[str, typer.Option("--out", help="The robot directory to write (new or empty): robot.toml, a copy of the URDF and its meshes.")],
    left_tip: Annotated[Optional[str], typer.Option(help="Tip link (hand frame) of the left arm; default: proposed from the tree.")] = None,
    right_tip: Annotated[Optional[str], typer.Option(help="Tip link of the right arm; default: proposed from the tree.")] = None,
    left_base: Annotated[Optional[str], typer.Option(help="Base link of the left arm's chain; default: the torso.")] = None,
    right_base: Annotated[Optional[str], typer.Option(help="Base link of the right arm's chain; default: the torso.")] = None,
    torso: Annotated[Optional[str], typer.Option(help="The link the arms hang from; default: their common root. The waist is the movable joints above it.")] = None,
    acceleration: Annotated[Optional[float], typer.Option(help="Acceleration limit of every chain joint [rad/s^2]; default: an assumed 5, marked so in robot.toml.")] = None,
    jerk: Annotated[Optional[float], typer.Option(help="Jerk limit of every chain joint [rad/s^3]; default: an assumed 50, marked so in robot.toml.")] = None,
) -> None:
    """Write a robot directory from a URDF: arm chains, waist, locked joints, S-R-S verdicts, limits, home poses zero and ready; print every choice (robots/README.md)."""
    from dualarm.model.init import init_robot

    for value, option in ((acceleration, "--acceleration"), (jerk, "--jerk")):
        if value is not None:
            _within(value, option, 0.0, above_low=True)
    with err.status("robot init: sampling configurations ..."):
        result = init_robot(urdf, _out_path(out_dir, "--out"), left_tip=left_tip, right_tip=right_tip, left_base=left_base, right_base=right_base, torso=torso, acceleration=acceleration, jerk=jerk)
    for line in result.notes:
        out.print(line, markup=False, soft_wrap=True)
    out.print(f"wrote {result.directory / 'robot.toml'}; next: dualarm robot check {result.directory}, dualarm robot poses {result.directory}", markup=False, soft_wrap=True)


@robot_app.command("poses")
@user_errors
def robot_poses(
    robot_dir: Annotated[Path, typer.Argument(help="Robot directory holding robot.toml (or a shipped robot's name).")],
    pose: Annotated[Optional[str], typer.Option(help="Only this home pose (default: every one).")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON: [{home, hand, position_m, rpy_rad, arm_angle_rad}].")] = False,
) -> None:
    """Each hand's pose at each home pose: position [m] and roll, pitch, yaw (extrinsic x-y-z, as task files) [rad] in the robot base frame, and the arm angle psi [rad] where the arm is S-R-S."""
    import dataclasses
    import json

    from dualarm.model.init import hand_poses
    from dualarm.model.robot import load_robot

    poses = hand_poses(load_robot(robot_dir), pose)
    if as_json:
        typer.echo(json.dumps([dataclasses.asdict(p) for p in poses], indent=2))
        return
    table = Table(title="hand poses in the robot base frame", title_justify="left")
    for column in ("home", "hand", "x [m]", "y [m]", "z [m]", "roll [rad]", "pitch [rad]", "yaw [rad]", "ψ [rad]"):
        table.add_column(column, justify="left" if column in ("home", "hand") else "right", no_wrap=True)
    for p in poses:
        table.add_row(p.home, p.hand, *(f"{v:.4f}" for v in (*p.position_m, *p.rpy_rad)), "-" if p.arm_angle_rad is None else f"{p.arm_angle_rad:.4f}")
    out.print(table)
    out.print("ψ: the arm angle of MC-Inverse eq (1) (V = +z of the arm's base frame); '-' where the arm is not S-R-S or ψ is undefined (shoulder-wrist line vertical)", markup=False)
