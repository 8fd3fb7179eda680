"""``dualarm report RUN_DIR``: a short markdown summary of a run and the figures its topics allow."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from pipeline.record.readback import RunData, read_run
from pipeline.report import figures


def _outside(sample: pd.DataFrame, kind: str, lower_of, upper_of) -> pd.DataFrame:
    """Per joint, how far and when ``kind`` (position or velocity) leaves [lower_of(joint),
    upper_of(joint)]: columns joint, max_outside, t_first_out, t_max_out (only joints that leave)."""
    rows = []
    t = sample["t"].to_numpy()
    for column in sample.columns:
        if not column.startswith(kind + "."):
            continue
        joint = column.split(".", 1)[1]
        v = sample[column].to_numpy()
        outside = np.maximum(lower_of(joint) - v, v - upper_of(joint))
        if outside.max() > 1e-9:
            rows.append({"joint": joint, "max_outside": outside.max(), "t_first_out": t[np.argmax(outside > 1e-9)], "t_max_out": t[np.argmax(outside)]})
    return pd.DataFrame(rows, columns=["joint", "max_outside", "t_first_out", "t_max_out"])


def excursions(sample: pd.DataFrame, bounds: pd.DataFrame, kind: str) -> pd.DataFrame:
    """Where ``kind`` (position or velocity) leaves the time-varying bounds of ``/ik/bounds``
    (theta_new+- or zeta_new+-); see :func:`_outside` for the columns."""
    lower, upper = ("theta_lower", "theta_upper") if kind == "position" else ("zeta_lower", "zeta_upper")
    return _outside(sample, kind, lambda j: bounds[f"{lower}.{j}"].to_numpy(), lambda j: bounds[f"{upper}.{j}"].to_numpy())


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
    lines = [f"{heading}:", "", f"| joint | largest excursion [{unit}] | first out [s] | largest at [s] |", "|---|---:|---:|---:|"]
    return lines + [f"| {r.joint} | {r.max_outside:.4g} | {r.t_first_out:.2f} | {r.t_max_out:.2f} |" for r in ex.itertuples()] + [""]


def write_report(run_dir: str | Path, out_dir: str | Path | None = None) -> Path:
    """Write ``summary.md`` and PNG figures for one run; returns the report directory.

    Figures by content: with ``/ik/bounds``, joints against theta_new+- and velocities against
    zeta_new+- (TV-GDD Figs 5-6, or 3-4 for pinv) and the bound profiles of eq (19) (Fig. 2); with
    ``/ik/sample``, the hand position errors (Fig. 8).
    """
    data: RunData = read_run(run_dir)
    out = Path(out_dir) if out_dir is not None else Path("reports") / str(data.manifest.get("task")) / data.run_id
    out.mkdir(parents=True, exist_ok=True)
    m = data.manifest
    lines = [f"# Run {data.run_id}", "", f"- task: `{m.get('task')}` ({m.get('task_file')})", f"- status: {data.status}", f"- stages: {', '.join(m.get('stages', []))}"]
    if m.get("error"):
        lines.append(f"- error: {m['error']}")
    if "/ik/sample" in data.topics:
        sample = data["/ik/sample"]
        method = str(sample["method"].iloc[0])
        lines += ["", f"## IK: {method}", ""]
        lines.append(f"![hand errors]({figures.hand_errors(sample, f'{method}: hand position errors (cf. TV-GDD Fig. 8)', out / 'hand_errors.png').name})")
        if "/ik/bounds" in data.topics:
            bounds = data["/ik/bounds"]
            figs = ("3", "4") if method == "pinv" else ("5", "6")
            joints_png = figures.joints_against_bounds(sample, bounds, "position", f"{method}: joint positions against theta_new± (cf. TV-GDD Fig. {figs[0]})", out / "joints_vs_bounds.png")
            velocity_png = figures.joints_against_bounds(sample, bounds, "velocity", f"{method}: joint velocities against zeta_new± (cf. TV-GDD Fig. {figs[1]})", out / "velocities_vs_bounds.png")
            profiles_png = figures.bound_profiles(float(sample["t"].max()), out / "bound_profiles.png")
            lines += [f"![joints]({joints_png.name})", f"![velocities]({velocity_png.name})", f"![bound profiles]({profiles_png.name})", ""]
            for kind, unit, plural in KINDS:
                lines += _section(excursions(sample, bounds, kind), f"Joint {plural} outside their time-varying bounds", unit, out / f"{kind}_excursions.csv")
        if "/ik/limits" in data.topics:
            for kind, unit, plural in KINDS:
                lines += _section(limit_excursions(sample, data["/ik/limits"], kind), f"Joint {plural} outside their physical limits", unit, out / f"{kind}_limit_excursions.csv")
    lines += ["## Metrics", "", "| key | value |", "|---|---:|"]
    lines += [f"| {k} | {v:.6g} |" if v is not None else f"| {k} | null |" for k, v in sorted(data.metrics.items())]
    (out / "summary.md").write_text("\n".join(lines) + "\n")
    return out
