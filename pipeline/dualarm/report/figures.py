"""Figures (PNG) from read-back DataFrames; each function returns the file it wrote."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.colors import TABLEAU_COLORS  # noqa: E402

from dualarm.contracts.reference import time_in_repetition  # noqa: E402
from dualarm.ik.velocity.gesture import position_bounds  # noqa: E402


def _joints(df: pd.DataFrame, prefix: str) -> list[str]:
    return [c[len(prefix) + 1 :] for c in df.columns if c.startswith(prefix + ".")]


def _grid(n: int):
    cols = 2 if n > 7 else 1
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(6 * cols, 1.5 * rows + 1), sharex=True, squeeze=False)
    return fig, axes.T.ravel()  # fill the left column first (left arm), then the right


def joints_against_bounds(sample: pd.DataFrame, bounds: pd.DataFrame, kind: str, title: str, path: Path) -> Path:
    """Each joint's position or velocity over time, against its bounds; excursions are shaded red.

    The position with ``kind="position"``, against theta_new+-; the velocity with
    ``kind="velocity"``, against zeta_new+-.
    """
    lower, upper = ("theta_lower", "theta_upper") if kind == "position" else ("zeta_lower", "zeta_upper")
    unit = "rad" if kind == "position" else "rad/s"
    joints = _joints(sample, kind)
    fig, axes = _grid(len(joints))
    t = sample["t"].to_numpy()
    for ax, joint in zip(axes, joints, strict=False):
        v = sample[f"{kind}.{joint}"].to_numpy()
        lo, hi = bounds[f"{lower}.{joint}"].to_numpy(), bounds[f"{upper}.{joint}"].to_numpy()
        ax.fill_between(t, lo, hi, color="tab:green", alpha=0.15, lw=0)
        ax.plot(t, lo, color="tab:green", lw=0.8)
        ax.plot(t, hi, color="tab:green", lw=0.8)
        ax.plot(t, v, color="tab:blue", lw=1.2)
        out = (v < lo) | (v > hi)
        if out.any():
            ax.fill_between(t, v, np.clip(v, lo, hi), where=out, color="tab:red", alpha=0.6, lw=0)
        ax.set_ylabel(joint.replace("_", " "), fontsize=7)
        ax.tick_params(labelsize=7)
        # unbounded (a continuous joint: inf, or NaN as recorded) bounds leave the axis to the values
        shown_lo = np.where(np.isfinite(lo), np.maximum(lo, v.min() - 1), v.min())
        shown_hi = np.where(np.isfinite(hi), np.minimum(hi, v.max() + 1), v.max())
        span = np.concatenate([v, shown_lo, shown_hi])
        pad = 0.1 * (span.max() - span.min() + 1e-6)
        ax.set_ylim(span.min() - pad, span.max() + pad)
    for ax in axes[len(joints) :]:
        ax.set_visible(False)
    for ax in axes:
        if ax.get_visible():
            ax.set_xlabel("t [s]", fontsize=7)
    fig.suptitle(f"{title} [{unit}]; green: bounds, red: outside", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def hand_errors(sample: pd.DataFrame, title: str, path: Path) -> Path:
    """|r - f(q)| of each hand over time (log scale) [m]."""
    fig, ax = plt.subplots(figsize=(7, 3.2))
    for hand in _joints(sample, "hand_error_m"):
        ax.semilogy(sample["t"], np.maximum(sample[f"hand_error_m.{hand}"], 1e-12), label=hand, lw=1)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("position error [m]")
    ax.set_title(title, fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def bound_profiles(duration_s: float, path: Path) -> Path:
    """TV-GDD eq (19) with theta+- = 0 and theta_goal+- = 5 (the paper's Fig. 2).

    Left, several c_tuning with N = 2; right, several N with c_tuning = 0.9.

    T_SP = T_d / N.
    """
    t = np.linspace(0, duration_s, 600)
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 3.2), sharey=True)
    for c in (0.1, 0.3, 0.6, 0.9, 1.0):
        left.plot(t, position_bounds(t, 0.0, 0.0, 5.0, 5.0, duration_s / 2, c)[0], label=f"c = {c}")
    for n in (1, 2, 4, 8, 16):
        right.plot(t, position_bounds(t, 0.0, 0.0, 5.0, 5.0, duration_s / n, 0.9)[0], label=f"N = {n}")
    left.set_title("N = 2, several c_tuning", fontsize=10)
    right.set_title("c_tuning = 0.9, several N", fontsize=10)
    for ax in (left, right):
        ax.set_xlabel("t [s]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    left.set_ylabel("theta_new± [rad]")
    fig.suptitle(f"TV-GDD bound profiles, eq (19), T_d = {duration_s:g} s", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


#: Smallest y range of a per-repetition plot [rad].
MIN_SPAN_RAD = 0.1
#: Repetition labels, as in the MC-Inverse paper's figures.
ROMAN = ("I", "II", "III", "IV", "V", "VI", "VII", "VIII", "IX", "X")
#: The colours of Matplotlib's "tab10" colormap, by name ("tab:blue", ...).
TAB10 = tuple(TABLEAU_COLORS)


def _per_repetition(ax, sample: pd.DataFrame, column: str, colours: tuple[str, ...]) -> None:
    """``column`` of ``sample`` against the time within the repetition, one line per repetition.

    Failed samples are left out; a column the sample lacks (an arm angle of an arm that is not
    S-R-S) is said so in the panel.
    """
    if column not in sample.columns:
        ax.text(
            0.5,
            0.5,
            f"no {column}\n(not S-R-S)" if column.startswith("arm_angle_rad.") else f"no {column}",
            ha="center",
            va="center",
            fontsize=7,
            transform=ax.transAxes,
        )
        return
    phase = time_in_repetition(sample["t"].to_numpy(), sample["rep"].to_numpy())
    values = np.where(sample["status"].to_numpy() == 0, sample[column].to_numpy(), np.nan)
    for i, rep in enumerate(np.unique(sample["rep"])):
        mine = sample["rep"].to_numpy() == rep
        ax.plot(
            phase[mine],
            values[mine],
            color=colours[i % len(colours)],
            lw=1.0,
            label=ROMAN[i] if i < len(ROMAN) else str(rep + 1),
        )
    low, high = np.nanmin(values, initial=np.inf), np.nanmax(values, initial=-np.inf)
    if np.isfinite(low) and high - low < MIN_SPAN_RAD:  # a constant curve is drawn flat, not as rounding noise
        middle = (low + high) / 2
        ax.set_ylim(middle - MIN_SPAN_RAD / 2, middle + MIN_SPAN_RAD / 2)


def _finish_per_repetition(fig, axes, title: str, path: Path) -> Path:
    drawn = next(
        (ax for ax in (axes[0, -1], *axes.ravel()) if ax.get_legend_handles_labels()[0]), None
    )  # the top right panel, or else one with curves
    if drawn is not None:
        drawn.legend(fontsize=6, title="rep", title_fontsize=6, loc="best")
    fig.suptitle(f"{title} [rad]; one line per repetition", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def joints_per_repetition(samples: dict[str, pd.DataFrame], joints: list[str], title: str, path: Path) -> Path:
    """The MC-Inverse paper's Figs 9 and 12: each joint per method against the time within the repetition.

    Each joint of ``joints`` (columns) per method (rows), one line per repetition (I, II, ...), so a
    method that repeats itself draws one line [rad].
    """
    colours = TAB10
    fig, axes = plt.subplots(
        len(samples), len(joints), figsize=(2.1 * len(joints), 1.8 * len(samples) + 0.8), squeeze=False, sharex=True
    )
    for row, (method, sample) in zip(axes, samples.items(), strict=True):
        for ax, joint in zip(row, joints, strict=True):
            _per_repetition(ax, sample, f"position.{joint}", colours)
            ax.tick_params(labelsize=6)
        row[0].set_ylabel(method, fontsize=8)
    for ax, joint in zip(axes[0], joints, strict=True):
        ax.set_title(joint.replace("_", " "), fontsize=7)
    for ax in axes[-1]:
        ax.set_xlabel("t in repetition [s]", fontsize=7)
    return _finish_per_repetition(fig, axes, title, path)


def arm_angle_per_repetition(samples: dict[str, pd.DataFrame], hands: list[str], title: str, path: Path) -> Path:
    """The MC-Inverse paper's Figs 10, 13 and 16: each hand's arm angle psi per method, by repetition.

    Each hand's arm angle (columns) per method (rows) against the time within the repetition, one
    line per repetition [rad]; a hand without one (its arm not S-R-S) is a panel saying so.
    """
    colours = TAB10
    fig, axes = plt.subplots(
        len(samples),
        len(hands),
        figsize=(max(7.5, 5 * len(hands)), 1.8 * len(samples) + 0.8),
        squeeze=False,
        sharex=True,
    )
    for row, (method, sample) in zip(axes, samples.items(), strict=True):
        for ax, hand in zip(row, hands, strict=True):
            _per_repetition(ax, sample, f"arm_angle_rad.{hand}", colours)
            ax.set_ylabel(f"{method}\n{hand} psi", fontsize=8)
            ax.tick_params(labelsize=7)
    for ax in axes[-1]:
        ax.set_xlabel("t in repetition [s]", fontsize=8)
    return _finish_per_repetition(fig, axes, title, path)


def runs_over_time(series: dict[str, tuple[np.ndarray, np.ndarray]], ylabel: str, title: str, path: Path) -> Path:
    """One line per run: label -> (t [s], values), on a log scale (values below 1e-12 drawn at 1e-12)."""
    fig, ax = plt.subplots(figsize=(8, 3.4))
    for label, (t, values) in series.items():
        ax.semilogy(t, np.maximum(values, 1e-12), label=label, lw=1)
    ax.set_xlabel("t [s]")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def limit_ratios(ratios: pd.DataFrame, title: str, path: Path) -> Path:
    """Grouped bars: each run (rows of ``ratios``) against each ratio (columns, e.g. "smooth jerk").

    The limit is drawn at 1.
    """
    fig, ax = plt.subplots(figsize=(max(6.0, 1.1 * len(ratios.columns) * max(1, len(ratios)) ** 0.5), 3.6))
    width = 0.8 / max(1, len(ratios))
    x = np.arange(len(ratios.columns))
    for i, (label, row) in enumerate(ratios.iterrows()):
        ax.bar(x + (i - (len(ratios) - 1) / 2) * width, row.to_numpy(dtype=float), width, label=label)
    ax.axhline(1.0, color="tab:red", lw=1, ls="--")
    ax.set_xticks(x, [c.replace(" ", "\n") for c in ratios.columns], fontsize=8)
    ax.set_ylabel("largest value / limit")
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=7)
    ax.grid(True, axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def histogram(values: np.ndarray, xlabel: str, title: str, path: Path, marks: dict[str, float] | None = None) -> Path:
    """A histogram of ``values``, with labelled vertical lines at ``marks`` (label -> x)."""
    fig, ax = plt.subplots(figsize=(7, 3.2))
    ax.hist(values, bins=30, color="tab:blue", alpha=0.8)
    for i, (label, x) in enumerate((marks or {}).items()):
        ax.axvline(x, color=TAB10[(i + 1) % 10], ls="--", lw=1.2, label=label)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("count")
    ax.set_title(title, fontsize=10)
    if marks:
        ax.legend(fontsize=8)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
