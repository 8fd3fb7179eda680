"""``dualarm report RUN_DIR...``: a markdown summary of each run and the figures its topics allow.

For several runs also tables across them (CSV and markdown) and figures that set them side by side.

Everything comes from the pandas read-back of the recordings (:mod:`dualarm.record.readback`), so
runs copied from another machine report the same.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from dualarm.record.readback import RunData, read_run
from dualarm.record.run_dir import claim_output_dir
from dualarm.record.verify import path_name
from dualarm.report import figures


def _outside(sample: pd.DataFrame, kind: str, lower_of, upper_of) -> pd.DataFrame:
    """Per joint, how far and when ``kind`` leaves [lower_of(joint), upper_of(joint)].

    ``kind``: position or velocity. Columns joint, max_outside, t_first_out, t_max_out (only joints
    that leave).
    """
    rows = []
    t = sample["t"].to_numpy()
    for column in sample.columns:
        if not column.startswith(kind + "."):
            continue
        joint = column.split(".", 1)[1]
        v = sample[column].to_numpy()
        outside = np.maximum(lower_of(joint) - v, v - upper_of(joint))
        if outside.max() > 1e-9:
            rows.append(
                {
                    "joint": joint,
                    "max_outside": outside.max(),
                    "t_first_out": t[np.argmax(outside > 1e-9)],
                    "t_max_out": t[np.argmax(outside)],
                }
            )
    return pd.DataFrame(rows, columns=["joint", "max_outside", "t_first_out", "t_max_out"])


def excursions(sample: pd.DataFrame, bounds: pd.DataFrame, kind: str) -> pd.DataFrame:
    """Where ``kind`` (position or velocity) leaves the time-varying bounds of ``/ik/bounds``.

    The bounds theta_new+- or zeta_new+-; see :func:`_outside` for the columns.
    """
    lower, upper = ("theta_lower", "theta_upper") if kind == "position" else ("zeta_lower", "zeta_upper")
    return _outside(
        sample, kind, lambda j: bounds[f"{lower}.{j}"].to_numpy(), lambda j: bounds[f"{upper}.{j}"].to_numpy()
    )


def limit_excursions(sample: pd.DataFrame, limits: pd.DataFrame, kind: str) -> pd.DataFrame:
    """Where ``kind`` (position or velocity) leaves the physical limits of ``/ik/limits``."""
    row = limits.iloc[0]
    if kind == "position":
        return _outside(sample, kind, lambda j: row[f"lower.{j}"], lambda j: row[f"upper.{j}"])
    return _outside(sample, kind, lambda j: -row[f"velocity.{j}"], lambda j: row[f"velocity.{j}"])


KINDS = (("position", "rad", "positions"), ("velocity", "rad/s", "velocities"))


def _section(ex: pd.DataFrame, heading: str, unit: str, csv: Path) -> list[str]:
    """Markdown lines of an excursion table (or "none."); writes the table to ``csv`` when not empty."""
    if ex.empty:
        return [f"{heading}: none.", ""]
    ex.to_csv(csv, index=False)
    lines = [
        f"{heading}:",
        "",
        f"| joint | largest excursion [{unit}] | first out [s] | largest at [s] |",
        "|---|---:|---:|---:|",
    ]
    return (
        lines
        + [f"| {r.joint} | {r.max_outside:.4g} | {r.t_first_out:.2f} | {r.t_max_out:.2f} |" for r in ex.itertuples()]
        + [""]
    )


def write_report(run_dir: str | Path | RunData, out_dir: str | Path | None = None) -> Path:
    """Write ``summary.md`` and PNG figures for one run; returns the report directory.

    Figures by content: with ``/ik/bounds``, joints against theta_new+- and velocities against
    zeta_new+- (TV-GDD Figs 5-6, or 3-4 for pinv) and the bound profiles of eq (19) (Fig. 2); with
    ``/ik/sample``, the hand position errors (Fig. 8).

    Raises:
        RecordingError: the run cannot be read, or (without ``out_dir``) its task or run id
            cannot name a directory (:func:`~dualarm.record.verify.path_name`).
    """
    data = run_dir if isinstance(run_dir, RunData) else read_run(run_dir)
    out = (
        Path(out_dir)
        if out_dir is not None
        else Path("reports")
        / path_name(data.task, "task", data.directory)
        / path_name(data.run_id, "run_id", data.directory)
    )
    _claim = claim_output_dir(
        out, "report"
    )  # refuses a directory holding files dualarm did not write; locked until this returns
    out.mkdir(parents=True, exist_ok=True)
    m = data.manifest
    lines = [
        f"# Run {data.run_id}",
        "",
        f"- task: `{m.get('task')}` ({m.get('task_file')})",
        f"- status: {data.status}",
        f"- stages: {', '.join(data.stages)}",
    ]
    if m.get("error"):
        lines.append(f"- error: {m['error']}")
    if "/ik/sample" in data.topics:
        sample = data["/ik/sample"]
        method = str(sample["method"].iloc[0])
        lines += ["", f"## IK: {method}", ""]
        hand_errors_png = figures.hand_errors(
            sample, f"{method}: hand position errors (cf. TV-GDD Fig. 8)", out / "hand_errors.png"
        )
        lines.append(f"![hand errors]({hand_errors_png.name})")
        if "/ik/bounds" in data.topics:
            bounds = data["/ik/bounds"]
            figs = ("3", "4") if method == "pinv" else ("5", "6")
            joints_png = figures.joints_against_bounds(
                sample,
                bounds,
                "position",
                f"{method}: joint positions against theta_new± (cf. TV-GDD Fig. {figs[0]})",
                out / "joints_vs_bounds.png",
            )
            velocity_png = figures.joints_against_bounds(
                sample,
                bounds,
                "velocity",
                f"{method}: joint velocities against zeta_new± (cf. TV-GDD Fig. {figs[1]})",
                out / "velocities_vs_bounds.png",
            )
            profiles_png = figures.bound_profiles(float(sample["t"].max()), out / "bound_profiles.png")
            lines += [
                f"![joints]({joints_png.name})",
                f"![velocities]({velocity_png.name})",
                f"![bound profiles]({profiles_png.name})",
                "",
            ]
            for kind, unit, plural in KINDS:
                lines += _section(
                    excursions(sample, bounds, kind),
                    f"Joint {plural} outside their time-varying bounds",
                    unit,
                    out / f"{kind}_excursions.csv",
                )
        if "/ik/limits" in data.topics:
            for kind, unit, plural in KINDS:
                lines += _section(
                    limit_excursions(sample, data["/ik/limits"], kind),
                    f"Joint {plural} outside their physical limits",
                    unit,
                    out / f"{kind}_limit_excursions.csv",
                )
    lines += ["## Metrics", "", "| key | value |", "|---|---:|"]
    lines += [f"| {k} | {v:.6g} |" if v is not None else f"| {k} | null |" for k, v in sorted(data.metrics.items())]
    (out / "summary.md").write_text("\n".join(lines) + "\n")
    return out


def run_label(run: RunData) -> str:
    """A run's task and method: its IK method or planner ("triangle mc-inverse"), or "path"."""
    method = run.setting("ik", "method") or run.setting("plan", "method") or "path"
    return f"{run.manifest.get('task')} {method}"


#: The first columns of runs.csv; the run's metrics follow.
RUN_COLUMNS = ("label", "run", "task", "method", "status", "stages", "repetitions", "directory")


def runs_table(runs: Sequence[RunData]) -> pd.DataFrame:
    """A row per run: :data:`RUN_COLUMNS`, then every metric of any of the runs (NaN where a run has none).

    Labels are made unique with the run id where two runs share one.
    """
    base = [run_label(r) for r in runs]
    labels = _unique([b if base.count(b) == 1 else f"{b} {r.run_id}" for b, r in zip(base, runs, strict=True)])
    rows = []
    for run, label in zip(runs, labels, strict=True):
        rows.append(
            {
                "label": label,
                "run": run.run_id,
                "task": run.manifest.get("task"),
                "method": str(label).split(" ")[1],
                "status": run.status,
                "stages": ",".join(run.stages),
                "repetitions": run.setting("path", "repetitions"),
                "directory": str(run.directory),
                **run.metrics,
            }
        )
    table = pd.DataFrame(rows)
    metrics = sorted(c for c in table.columns if c not in RUN_COLUMNS)
    return table.reindex(columns=[*RUN_COLUMNS, *metrics])


def _unique(names: Sequence[str]) -> list[str]:
    """``names`` with " (2)", " (3)", ... added to repeats.

    Repeats: the same run given twice, or a run and its copy from another machine.
    """
    seen: dict[str, int] = {}
    out = []
    for name in names:
        seen[name] = seen.get(name, 0) + 1
        out.append(name if seen[name] == 1 else f"{name} ({seen[name]})")
    return out


def _cell(value) -> str:
    if value is None or (isinstance(value, float) and np.isnan(value)):
        return "-"
    if isinstance(value, (int, np.integer)) or (isinstance(value, float) and value.is_integer() and abs(value) < 1e9):
        return f"{value:.0f}"
    return f"{value:.4g}" if isinstance(value, (float, np.floating)) else str(value)


def metrics_markdown(table: pd.DataFrame) -> list[str]:
    """The metrics of :func:`runs_table` as markdown: a row per metric, a column per run."""
    metrics = [c for c in table.columns if c not in RUN_COLUMNS]
    lines = ["| metric | " + " | ".join(table["label"]) + " |", "|---|" + "---:|" * len(table)]
    return lines + [f"| {m} | " + " | ".join(_cell(v) for v in table[m]) + " |" for m in metrics]


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_")


#: Limit ratios drawn side by side: (label, metric).
RATIOS = (
    ("retime velocity", "retime.velocity_ratio_max"),
    ("retime acceleration", "retime.acceleration_ratio_max"),
    ("smooth velocity", "smooth.velocity_ratio_max"),
    ("smooth acceleration", "smooth.acceleration_ratio_max"),
    ("smooth jerk", "smooth.jerk_ratio_max"),
)


def hand_errors(sample: pd.DataFrame) -> pd.DataFrame:
    """The ``hand_error_m.<hand>`` columns [m] of an ``/ik/sample`` or ``/execute/sample``."""
    return sample[[c for c in sample.columns if c.startswith("hand_error_m.")]]


def _hand_error(sample: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    """(t [s], the larger of the hands' position errors [m]) of a sample topic."""
    return sample["t"].to_numpy(), hand_errors(sample).to_numpy().max(axis=1)


def cross_run_figures(runs: Sequence[RunData], labels: Sequence[str], out: Path) -> list[tuple[str, Path]]:
    """Figures that put the runs side by side, each only when some runs hold its data.

    IK hand errors, execution tracking errors, retime and smooth limit ratios, and per task with
    repetitions, the joints and arm angles per repetition.

    Returns (caption, file) pairs.
    """
    written = []
    ik = {
        label: _hand_error(r["/ik/sample"]) for r, label in zip(runs, labels, strict=True) if "/ik/sample" in r.topics
    }
    if ik:
        written.append(
            (
                "IK: the larger hand position error, per run",
                figures.runs_over_time(
                    ik,
                    "position error [m]",
                    "IK hand position error |r - f(q)| (larger hand)",
                    out / "ik_hand_errors.png",
                ),
            )
        )
    executed = {
        label: _hand_error(r["/execute/sample"])
        for r, label in zip(runs, labels, strict=True)
        if "/execute/sample" in r.topics
    }
    if executed:
        written.append(
            (
                "Execution: distance of the measured hand from the commanded one (larger hand), per run",
                figures.runs_over_time(
                    executed,
                    "tracking error [m]",
                    "PyBullet execution tracking error (larger hand)",
                    out / "tracking_errors.png",
                ),
            )
        )
    ratios = (
        pd.DataFrame({name: [r.metrics.get(key, np.nan) for r in runs] for name, key in RATIOS}, index=list(labels))
        .dropna(how="all")
        .dropna(axis=1, how="all")
    )
    if not ratios.empty:
        written.append(
            (
                "Retime and smooth: largest velocity, acceleration and jerk as a fraction of the limits",
                figures.limit_ratios(
                    ratios, "largest value / limit per run (dashed: the limit)", out / "limit_ratios.png"
                ),
            )
        )
    by_task: dict[str, dict[str, pd.DataFrame]] = {}
    for run, label in zip(runs, labels, strict=True):
        if "/ik/sample" in run.topics and run["/ik/sample"]["rep"].nunique() > 1:
            by_task.setdefault(str(run.manifest.get("task")), {})[label] = run["/ik/sample"]
    for task, samples in by_task.items():
        first = next(iter(samples.values()))
        hands = [c.split(".", 1)[1] for c in first.columns if c.startswith("arm_angle_rad.")]
        if hands and all(f"arm_angle_rad.{h}" in s for s in samples.values() for h in hands):
            written.append(
                (
                    f"{task}: arm angle per repetition",
                    figures.arm_angle_per_repetition(
                        samples, hands, f"{task}: arm angle per repetition", out / f"arm_angle_{_slug(task)}.png"
                    ),
                )
            )
        joints = [c.split(".", 1)[1] for c in first.columns if c.startswith("position.")]
        for hand in hands:
            mine = [j for j in joints if j.startswith(f"{hand}_")]
            if mine and all(f"position.{j}" in s for s in samples.values() for j in mine):
                written.append(
                    (
                        f"{task}: {hand} arm joints per repetition",
                        figures.joints_per_repetition(
                            samples,
                            mine,
                            f"{task}: {hand} arm joints per repetition",
                            out / f"joints_{_slug(task)}_{hand}.png",
                        ),
                    )
                )
    return written


def write_runs_report(run_dirs: Sequence[str | Path], out_dir: str | Path | None = None) -> Path:
    """Report several runs; returns the report directory.

    Each run's summary in ``<task>-<run-id>/``, ``runs.csv`` and ``runs.md`` (a row per run, every
    metric), the cross-run figures and ``report.md`` linking it all. The report directory defaults
    to ``reports/<task>/<first run id>+<n - 1>``, the task being ``runs`` when they differ.

    Raises:
        RecordingError: a run directory is missing or its recording unreadable.
    """
    runs = [read_run(d) for d in run_dirs]
    table = runs_table(runs)
    tasks = sorted(set(table["task"].astype(str)))
    if out_dir is None:  # named after the recordings' fields only once they are checked to be plain names
        first = runs[0]
        out_dir = (
            Path("reports")
            / (path_name(first.task, "task", first.directory) if len(tasks) == 1 else "runs")
            / f"{path_name(first.run_id, 'run_id', first.directory)}+{len(runs) - 1}"
        )
    out = Path(out_dir)
    _claim = claim_output_dir(
        out, "report"
    )  # refuses a directory holding files dualarm did not write; locked until this returns
    out.mkdir(parents=True, exist_ok=True)
    names = _unique([f"{run.manifest.get('task')}-{run.run_id}" for run in runs])
    summaries = [write_report(run, out / _slug(name)) for run, name in zip(runs, names, strict=True)]
    table.to_csv(out / "runs.csv", index=False)
    lines = [
        f"# {len(runs)} runs",
        "",
        "| run | task | method | status | stages | reps | summary |",
        "|---|---|---|---|---|---:|---|",
    ]
    lines += [
        f"| {r.run} | {r.task} | {r.method} | {r.status} | {r.stages} "
        f"| {_cell(r.repetitions)} | [{s.name}]({s.name}/summary.md) |"
        for r, s in zip(table.itertuples(), summaries, strict=True)
    ]
    metrics = ["", "## Metrics", "", *metrics_markdown(table)]
    (out / "runs.md").write_text("\n".join(lines + metrics) + "\n")
    written = cross_run_figures(runs, list(table["label"]), out)
    lines += (
        metrics + ["", "## Figures", ""] + [f"{caption}:\n\n![{path.stem}]({path.name})\n" for caption, path in written]
    )
    (out / "report.md").write_text("\n".join(lines) + "\n")
    return out
