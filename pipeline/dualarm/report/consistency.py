"""``dualarm consistency``: IK methods compared on one repeated task, repetition by repetition.

The MC-Inverse paper's experiments (section V.B-V.D): the same task is repeated and each IK method
is judged by whether its joints and arm angles repeat. Every method is run as a normal recorded run
(``DIR/runs/<task>/<run-id>``); the comparison reads the runs back like any report and writes
``DIR/consistency.csv`` (a row per method), ``DIR/consistency.md`` and the figures. A method that
fails is a row with its error, not the end of the comparison; each row carries its run's verdict and
first violation (a baseline failing a repetition is the paper's point, not an error). Beside the
joint deviations stands the largest hand orientation error; a method that solved the hands'
positions only (TV-GDD and pinv in ``position`` task space, ``ik.orientation_solved`` 0) is marked
"position only", since its repeatability is not bought at the same price as a full-pose method's.

On a robot whose driven arms are not S-R-S there is no arm angle: its column is left out of the
table and the arm-angle figure is not drawn, and without a list of methods only those that run on
the robot are compared (:func:`dualarm.methods.suited_methods`); a method asked for that needs
S-R-S is refused before anything runs.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from dualarm.errors import DualarmError
from dualarm.record.readback import RunData, read_run
from dualarm.record.run_dir import claim_output_dir, write_whole
from dualarm.report import figures

#: Columns of consistency.csv after ``method``: DESIGN.md's ``ik.*`` metric names without the prefix.
COLUMNS = (
    "rep_joint_deviation_max_rad",
    "rep_arm_angle_deviation_max_rad",
    "orientation_error_max_rad",
    "closure_error_max_rad",
    "failed_reps",
    "failures",
    "max_joint_step_rad",
    "position_error_max_m",
    "solve_time_mean_s",
    "solve_time_median_s",
    "solve_time_total_s",
    "orientation_solved",
)
#: The mark of a method that solved the hands' positions only (``ik.orientation_solved`` 0).
POSITION_ONLY = "position only"
#: Methods compared by default: MC-Inverse and the paper's baselines, the other pose-level solvers,
#: then the velocity-level ones of TV-GDD.
DEFAULT_METHODS = ("mc-inverse", "trac-ik", "ikfast-style", "pybullet", "dls-svd", "tvgdd", "pinv")
#: The MC-Inverse paper's figures that the joint and arm-angle plots of a task correspond to.
PAPER_FIGURES = {"triangle": ("Fig. 9", "Fig. 10"), "circle": ("Fig. 12", "Fig. 13"), "carry_box": ("-", "Fig. 16")}


@dataclass(frozen=True)
class Consistency:
    """What :func:`run_consistency` wrote.

    Attributes:
        table: a row per method: ``method``, ``status`` (the run's verdict: complete, violated or
            failed), ``error`` (a failed run's), ``violation`` (a violated run's first, with the
            count of the others), ``run`` and :data:`COLUMNS`.
        csv: consistency.csv.
        markdown: consistency.md.
        figures: the PNG files.
    """

    table: pd.DataFrame
    csv: Path
    markdown: Path
    figures: tuple[Path, ...]


#: Consistency is a property of the joint path: the runs stop after IK.
CONSISTENCY_STAGES = ("path", "ik")


#: The columns that hold an arm angle, left out when no driven arm is S-R-S.
ARM_ANGLE_COLUMNS = ("rep_arm_angle_deviation_max_rad",)


def run_consistency(
    task_file: str | Path,
    methods: Sequence[str] | None,
    out_dir: str | Path,
    repetitions: int | None = None,
    seed: int = 0,
    progress: Callable[[str], None] | None = None,
    robot: str | Path | None = None,
) -> Consistency:
    """Run ``methods`` on ``task_file`` and compare them.

    ``methods`` None: :data:`DEFAULT_METHODS` that run on the task's robot. ``repetitions``
    overrides the file's; ``robot``, a robot directory or shipped robot's name, the robot it names.

    Raises:
        DualarmError: an unknown method, a method that needs S-R-S arms on a robot whose arm is not
            one (:class:`~dualarm.errors.NotSRSError`), or a malformed task, before anything runs.
    """
    from dualarm.methods import IK_METHODS, METHODS, refuse_unsuited, suited_methods
    from dualarm.run import record_run
    from dualarm.tasks import load_task

    unknown = [m for m in methods or () if m not in IK_METHODS]
    if unknown or (methods is not None and not methods):
        raise DualarmError(f"unknown IK method '{(unknown or [''])[0]}' (methods: {', '.join(IK_METHODS)})")
    task = load_task(task_file, repetitions, robot)
    hands = task.spec.hands
    if methods is None:
        suited = suited_methods(task.robot, hands)
        methods = [m for m in DEFAULT_METHODS if m in suited]
    for m in methods:
        refuse_unsuited(METHODS[m], task.robot, hands)
    columns = COLUMNS if any_arm_angle(task) else tuple(c for c in COLUMNS if c not in ARM_ANGLE_COLUMNS)
    out_dir = Path(out_dir)
    _claim = claim_output_dir(
        out_dir, "consistency"
    )  # refuses a directory holding files dualarm did not write; locked until this returns
    runs_dir = out_dir / "runs"
    rows: list[dict[str, object]] = []
    samples: dict[str, pd.DataFrame] = {}
    for method in methods:
        if progress is not None:
            progress(f"{task.name}: {method} ...")
        before = set((runs_dir / task.name).glob("*")) if (runs_dir / task.name).exists() else set()
        try:
            recorded = record_run(
                task,
                method,
                stages=CONSISTENCY_STAGES,
                out_dir=runs_dir,
                seed=seed,
                command=[
                    "dualarm",
                    "consistency",
                    str(task_file),
                    "--methods",
                    method,
                    *(["--robot", str(robot)] if robot is not None else []),
                ],
            )
            assert recorded.directory is not None  # record_run always returns its run directory
            run = read_run(recorded.directory)
        except DualarmError as exc:
            failed = sorted(set((runs_dir / task.name).glob("*")) - before)
            rows.append(
                {
                    "method": method,
                    "status": "failed",
                    "error": str(exc),
                    "violation": "",
                    "run": str(failed[-1]) if failed else "",
                }
            )
            continue
        rows.append(_row(method, run))
        samples[method] = run["/ik/sample"]
    table = pd.DataFrame(rows, columns=["method", "status", "error", "violation", "run", *columns])
    written = _figures(task, samples, out_dir)
    csv = write_whole(
        out_dir / "consistency.csv",
        table[["method", *columns, "status", "violation", "error", "run"]].to_csv(index=False),
    )
    markdown = write_whole(out_dir / "consistency.md", _markdown(task, table, written, repetitions, columns))
    return Consistency(table=table, csv=csv, markdown=markdown, figures=written)


def any_arm_angle(task) -> bool:
    """Whether a driven arm of ``task`` has an arm angle.

    MC-Inverse's on an S-R-S arm, the SEW angle on another arm of a SEW family (S-R-S arms are of
    one too).
    """
    from dualarm.methods import not_sew

    return len(not_sew(task.robot, task.spec.hands)) < len(task.spec.hands)


def _row(method: str, run: RunData) -> dict[str, object]:
    metrics = {k.removeprefix("ik."): v for k, v in run.metrics.items() if k.startswith("ik.")}
    violations = run.violations or [""]
    first = violations[0] + (f" (and {len(violations) - 1} more)" if len(violations) > 1 else "")
    return {
        "method": method,
        "status": run.status,
        "error": "",
        "violation": first,
        "run": str(run.directory),
        **{c: metrics.get(c, np.nan) for c in COLUMNS},
    }


def _figures(task, samples: dict[str, pd.DataFrame], out_dir: Path) -> tuple[Path, ...]:
    if not samples:
        return ()
    out_dir.mkdir(parents=True, exist_ok=True)
    joints_figure, angle_figure = PAPER_FIGURES.get(task.name, ("-", "-"))
    written = []
    for hand in task.spec.hands:
        joints = list(task.robot.hand_chain(hand).joint_names)
        title = f"{task.name}: {hand} arm joints per repetition" + (
            f" (cf. MC-Inverse {joints_figure})" if joints_figure != "-" else ""
        )
        written.append(figures.joints_per_repetition(samples, joints, title, out_dir / f"joints_{hand}.png"))
    hands = [
        h for h in task.spec.hands if any(f"arm_angle_rad.{h}" in sample.columns for sample in samples.values())
    ]  # arms with an arm angle only
    if hands:
        title = f"{task.name}: arm angle per repetition" + (
            f" (cf. MC-Inverse {angle_figure})" if angle_figure != "-" else ""
        )
        written.append(figures.arm_angle_per_repetition(samples, hands, title, out_dir / "arm_angle.png"))
    return tuple(written)


def _markdown(
    task, table: pd.DataFrame, written: tuple[Path, ...], repetitions: int | None, columns: tuple[str, ...] = COLUMNS
) -> str:
    reps = repetitions or task.spec.repetitions
    lines = [
        f"# Consistency: {task.name}, {reps} repetitions",
        "",
        f"Task file `{task.file}`. Rep 0 is the reference; deviations compare "
        "samples at the same place of every repetition where both succeeded.",
        "orientation_error_max_rad is the largest angle between an asked and a reached hand orientation; "
        f"a method marked ({POSITION_ONLY}) solved the hands' positions only, its orientation followed.",
        "",
    ]
    if columns != COLUMNS:
        lines += ["No driven arm is S-R-S, so there is no arm angle: its column and figure are left out.", ""]
    header = ["method", "verdict", *columns, "first violation"]
    lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for _, row in table.iterrows():
        if row["status"] == "failed":
            lines.append(f"| {row['method']} | failed: {row['error']} |" + " |" * len(columns))
            continue
        lines.append(
            "| "
            + " | ".join(
                [method_label(row), str(row["status"]), *(_cell(row[c]) for c in columns), str(row["violation"])]
            )
            + " |"
        )
    lines += ["", "Runs:", ""] + [f"- {row['method']}: `{row['run']}`" for _, row in table.iterrows() if row["run"]]
    if written:
        lines += ["", "Figures:", ""] + [f"![{p.stem}]({p.name})" for p in written]
    return "\n".join(lines) + "\n"


def method_label(row: pd.Series) -> str:
    """A table row's method, marked "(position only)" when it did not solve the asked orientation.

    Not solved: ``orientation_solved`` 0.
    """
    return f"{row['method']} ({POSITION_ONLY})" if row.get("orientation_solved") == 0 else str(row["method"])


def _cell(value: float) -> str:
    if pd.isna(value):
        return "-"
    return f"{value:.0f}" if float(value).is_integer() and abs(value) < 1e6 else f"{value:.3g}"
