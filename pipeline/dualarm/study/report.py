"""A study's report, from its ``trials.parquet`` alone.

How often each method's motion is inconsistent, and under which conditions.

- Per method (:func:`method_rates`): of its trials, the share inconsistent and the share failed,
  each with its 95 % Wilson score interval (``statsmodels``' ``proportion_confint``); a row with
  ``status = error`` (a bug, not the method's answer) is left out and counted.
- Against each condition (:func:`feature_rates`): the trials binned by a feature -- the shape's
  size, kind and tilt, the centre's place in the shoulder frame (the workspace region), held or
  changing orientation, repetitions, period, and, where the metrics have them, the path's closest
  approach to the joint limits and its least manipulability -- and the share inconsistent per
  bin, with intervals (numbers into :data:`BINS` quantile bins, categories as they are).
- Together (:func:`logistic_fit`): per method, a logistic regression of ``inconsistent`` on the
  standardised numeric features (``statsmodels`` ``Logit``): odds ratio per standard deviation of
  each, with its 95 % interval and p-value; a method whose trials all agree (or whose fit
  separates them perfectly) has none, and the report says so.

:func:`write_study_report` writes ``report.md``, ``methods.csv``, ``features.csv``, ``logit.csv``,
``methods.png``, ``features.png`` and ``deviations.png`` (how far apart the repetitions are, per
method) into the study's directory.
"""

from __future__ import annotations

import hashlib
import json
import math
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from dualarm.errors import OutputError, RecordingError, excerpt
from dualarm.record.run_dir import STUDY_REPORT_DIGESTS as DIGESTS
from dualarm.record.run_dir import STUDY_REPORT_FILES as REPORT_FILES
from dualarm.record.run_dir import claim_output_dir, write_whole
from dualarm.study.run import RESULTS, SPEC_FILE

#: Quantile bins of a numeric feature.
BINS = 4
#: The features the report bins by, when the table has them: column -> what it is.
FEATURES = {
    "size_m": "shape size (circumradius) [m]",
    "kind": "shape",
    "tilt_rad": "shape plane's tilt [rad]",
    "orientation": "hand orientation along the shape",
    "centre_x_m": "centre, forward of the shoulder [m]",
    "centre_y_m": "centre, sideways (left +) [m]",
    "centre_z_m": "centre, below (-) the shoulder [m]",
    "hand": "hand",
    "repetitions": "repetitions",
    "period_s": "one repetition's duration [s]",
    "ik.joint_limit_margin_min_rad": "closest approach to a joint limit along the path [rad] (trials with a path)",
    "ik.manipulability_min": "least manipulability along the path (trials with a path)",
}
#: The confidence of every interval.
CONFIDENCE = 0.95
#: Trials of a method's rarer outcome needed per feature for its logistic fit (fewer: no fit, and the report says so).
EVENTS_PER_FEATURE = 5
#: The deviation the report gives quantiles of and draws (``ik.rep_joint_deviation_max_rad``).
DEVIATION = "ik.rep_joint_deviation_max_rad"


def wilson(count: int, n: int) -> tuple[float, float]:
    """The 95 % Wilson score interval of ``count`` successes in ``n`` trials (NaNs for n = 0)."""
    from statsmodels.stats.proportion import proportion_confint

    if n == 0:
        return math.nan, math.nan
    low, high = proportion_confint(count, n, alpha=1 - CONFIDENCE, method="wilson")
    return float(low), float(high)


def _threshold(directory: Path) -> float | None:
    """The spec's ``[inconsistent] joint_deviation_rad`` from ``study.json``, if the directory has it."""
    try:
        return float(json.loads((directory / SPEC_FILE).read_text())["spec"]["inconsistent"]["joint_deviation_rad"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def read_trials(directory: str | Path) -> pd.DataFrame:
    """The rows of ``directory/trials.parquet``.

    Raises:
        RecordingError: no such file, or not a study's table (named).
    """
    file = Path(directory) / RESULTS
    if not file.is_file():
        raise RecordingError(
            f"{excerpt(file)}: no such file; give a study's directory (dualarm study SPEC.toml --out DIR)"
        )
    try:
        rows = pd.read_parquet(file)
    except Exception as exc:  # pyarrow's own errors for a truncated or foreign file
        raise RecordingError(
            f"{excerpt(file)}: not a readable parquet file ({type(exc).__name__}: {excerpt(str(exc), 120)})"
        ) from None
    missing = [c for c in ("trial", "method", "status", "failed", "inconsistent") if c not in rows.columns]
    if missing:
        raise RecordingError(f"{excerpt(file)}: not a study's table (no column {', '.join(missing)})")
    if not len(rows):
        raise RecordingError(f"{excerpt(file)}: no rows; a study writes its table once a trial has finished")
    for column in ("failed", "inconsistent"):
        if not pd.api.types.is_bool_dtype(rows[column]):
            raise RecordingError(
                f"{excerpt(file)}: not a study's table (column {column} holds {rows[column].dtype}, not booleans)"
            )
    return rows


def _judged(rows: pd.DataFrame) -> pd.DataFrame:
    """The rows that are a method's answer (not ``status = error``)."""
    return rows[rows["status"] != "error"]


def method_rates(rows: pd.DataFrame) -> pd.DataFrame:
    """Per method (in the table's order): trials, errors, inconsistent, failed, violated counts, and more.

    Errors are left out; each share with its Wilson interval, and the median and 90th percentile of
    the largest joint deviation between repetitions (of the trials that have one) [rad]. ``violated``: rows whose
    verdict is ``violated`` (a hand off its pose, a joint beyond a limit, an IK path through the robot or the scene).
    """
    out = []
    for method, group in rows.groupby("method", sort=False):
        judged = _judged(group)
        n, bad, failed = len(judged), int(judged["inconsistent"].sum()), int(judged["failed"].sum())
        low, high = wilson(bad, n)
        f_low, f_high = wilson(failed, n)
        out.append(
            {
                "method": method,
                "trials": n,
                "errors": len(group) - n,
                "inconsistent": bad,
                "p_inconsistent": bad / n if n else math.nan,
                "p_inconsistent_low": low,
                "p_inconsistent_high": high,
                "failed": failed,
                "p_failed": failed / n if n else math.nan,
                "p_failed_low": f_low,
                "p_failed_high": f_high,
                "violated": int((judged["status"] == "violated").sum()),
                **_quantiles(judged),
            }
        )
    return pd.DataFrame(out)


def _quantiles(rows: pd.DataFrame) -> dict[str, float]:
    """The median and 90th percentile of :data:`DEVIATION` over the rows that have it [rad].

    NaN without any.
    """
    values = rows[DEVIATION].dropna() if DEVIATION in rows.columns else pd.Series(dtype=float)
    return {
        "deviation_median_rad": float(values.median()) if len(values) else math.nan,
        "deviation_p90_rad": float(values.quantile(0.9)) if len(values) else math.nan,
    }


def _bins(values: pd.Series) -> pd.Series:
    """A feature's bins: its categories, or :data:`BINS` quantile bins of a number.

    Fewer where values repeat.
    """
    if not pd.api.types.is_numeric_dtype(values) or pd.api.types.is_bool_dtype(values) or values.nunique() <= BINS:
        return values.astype(str)
    return pd.qcut(values, BINS, duplicates="drop").astype(str)


def feature_rates(rows: pd.DataFrame) -> pd.DataFrame:
    """Per feature of :data:`FEATURES` the table has, bin and method: trials, inconsistent, the share.

    The share with its Wilson interval.

    A trial's features are binned over all methods' trials alike; a feature of a method's own
    joint path (``ik.*``) is binned per method, in its quartiles ``Q1``-``Q4`` (and only where the
    method made a path: a method that raised has none).
    """
    judged = _judged(rows)
    methods = {m: i for i, m in enumerate(dict.fromkeys(judged["method"]))}
    out = []
    for feature in (f for f in FEATURES if f in judged.columns and judged[f].notna().any()):
        present = judged[judged[feature].notna()]
        groups = present.groupby("method", sort=False) if feature.startswith("ik.") else [(None, present)]
        for _, part in groups:
            binned = part.assign(bin=_bins(part[feature]))
            ordered = list(binned.sort_values(feature)["bin"].drop_duplicates())
            label = (
                {b: f"Q{i + 1}" for i, b in enumerate(ordered)}
                if feature.startswith("ik.") and len(ordered) == BINS
                else {b: b for b in ordered}
            )
            for (method, where), group in binned.groupby(["method", "bin"], sort=False):
                n, bad = len(group), int(group["inconsistent"].sum())
                low, high = wilson(bad, n)
                out.append(
                    {
                        "feature": feature,
                        "bin": label[where],
                        "bin_order": ordered.index(where),
                        "method": method,
                        "trials": n,
                        "inconsistent": bad,
                        "p_inconsistent": bad / n,
                        "low": low,
                        "high": high,
                    }
                )
    table = pd.DataFrame(
        out,
        columns=["feature", "bin", "bin_order", "method", "trials", "inconsistent", "p_inconsistent", "low", "high"],
    )
    rank = {"feature": list(FEATURES).index, "method": methods.__getitem__}
    return table.sort_values(
        ["feature", "method", "bin_order"],
        key=lambda c: c.map(rank[c.name]) if c.name in rank else c,
        kind="stable",
        ignore_index=True,
    )


def logistic_fit(rows: pd.DataFrame) -> tuple[pd.DataFrame, dict[str, str]]:
    """Per method, ``inconsistent`` ~ the standardised numeric features (statsmodels ``Logit``).

    Odds ratio per standard deviation, its interval and p-value; and per method without a fit, why.
    """
    import statsmodels.api as sm
    from statsmodels.tools.sm_exceptions import ConvergenceWarning, PerfectSeparationError, PerfectSeparationWarning

    judged = _judged(rows)
    out, skipped = [], {}
    for method, group in judged.groupby("method", sort=False):
        numeric = [
            f
            for f in FEATURES
            if f in group.columns
            and pd.api.types.is_numeric_dtype(group[f])
            and group[f].notna().all()
            and group[f].std() > 0
        ]
        y = group["inconsistent"].astype(float)
        if y.nunique() < 2:
            skipped[str(method)] = f"all {len(y)} trials {'inconsistent' if y.iloc[0] else 'consistent'}"
            continue
        events = int(min(y.sum(), len(y) - y.sum()))
        if events < EVENTS_PER_FEATURE * len(numeric):
            rarer = "consistent" if y.mean() > 0.5 else "inconsistent"
            skipped[str(method)] = (
                f"{events} {rarer} trials are too few for {len(numeric)} features ({EVENTS_PER_FEATURE} per feature)"
            )
            continue
        x = (group[numeric] - group[numeric].mean()) / group[numeric].std()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("error", PerfectSeparationWarning)
                warnings.simplefilter("error", ConvergenceWarning)
                fit = sm.Logit(y, sm.add_constant(x)).fit(disp=0, maxiter=200)
        except (PerfectSeparationError, PerfectSeparationWarning, ConvergenceWarning, np.linalg.LinAlgError) as exc:
            skipped[str(method)] = (
                f"no fit ({type(exc).__name__}: the features separate its trials (nearly) perfectly or are collinear)"
            )
            continue
        interval = fit.conf_int(alpha=1 - CONFIDENCE)
        for feature in numeric:
            out.append(
                {
                    "method": method,
                    "feature": feature,
                    "odds_ratio_per_sd": float(np.exp(fit.params[feature])),
                    "low": float(np.exp(interval.loc[feature, 0])),
                    "high": float(np.exp(interval.loc[feature, 1])),
                    "p_value": float(fit.pvalues[feature]),
                }
            )
    return pd.DataFrame(out, columns=["method", "feature", "odds_ratio_per_sd", "low", "high", "p_value"]), skipped


def _methods_figure(rates: pd.DataFrame, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 0.5 * len(rates) + 1.5))
    y = np.arange(len(rates))
    for offset, (what, colour) in zip(
        (-0.18, 0.18), (("p_inconsistent", "tab:red"), ("p_failed", "tab:grey")), strict=True
    ):
        p = rates[what].to_numpy()
        err = np.clip(
            np.vstack([p - rates[f"{what}_low"], rates[f"{what}_high"] - p]), 0.0, None
        )  # the interval's end at 0 or 1 is p up to rounding
        ax.errorbar(p, y + offset, xerr=err, fmt="o", color=colour, capsize=3, label=what.replace("p_", "P(") + ")")
    ax.set_yticks(y, [f"{m} (n = {n})" for m, n in zip(rates["method"], rates["trials"], strict=True)])
    ax.invert_yaxis()
    ax.set_xlim(-0.02, 1.02)
    ax.set_xlabel("share of trials, with 95 % Wilson intervals")
    ax.legend(loc="lower right", fontsize="small")
    ax.grid(axis="x", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _deviations_figure(rows: pd.DataFrame, threshold: float | None, path: Path) -> None:
    """Per method, the share of trials whose largest joint deviation between repetitions is at most x.

    An empirical CDF, x logarithmic; the spec's threshold dashed.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 4))
    for method, group in _judged(rows).groupby("method", sort=False):
        values = np.sort(np.maximum(group[DEVIATION].dropna().to_numpy(), 1e-16))
        if len(values):
            ax.step(
                values,
                np.arange(1, len(values) + 1) / len(group),
                where="post",
                label=f"{method} ({len(values)} of {len(group)})",
            )
    if threshold is not None:
        ax.axvline(threshold, color="k", ls="--", lw=1, label=f"inconsistent above {threshold:g} rad")
    ax.set_xscale("log")
    ax.set_xlabel("largest joint deviation between repetitions [rad] (1e-16 for 0)")
    ax.set_ylabel("share of the method's trials")
    ax.set_ylim(0, 1.01)
    ax.grid(alpha=0.3)
    ax.legend(fontsize="x-small", loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _features_figure(features: pd.DataFrame, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(dict.fromkeys(features["feature"]))
    cols = 3
    fig, axes = plt.subplots(
        math.ceil(len(names) / cols), cols, figsize=(4.2 * cols, 3.2 * math.ceil(len(names) / cols)), squeeze=False
    )
    methods = list(dict.fromkeys(features["method"]))
    for ax, name in zip(axes.flat, names, strict=False):
        table = features[features["feature"] == name]
        for k, method in enumerate(methods):
            t = table[table["method"] == method]
            x = t["bin_order"].to_numpy() + (k - (len(methods) - 1) / 2) * 0.08
            p = t["p_inconsistent"].to_numpy()
            ax.errorbar(
                x,
                p,
                yerr=np.clip(np.vstack([p - t["low"], t["high"] - p]), 0.0, None),
                fmt="o-",
                capsize=2,
                ms=3,
                lw=1,
                label=method,
            )
        labels = table.drop_duplicates("bin_order").sort_values("bin_order")
        ax.set_xticks(labels["bin_order"], labels["bin"], rotation=20, fontsize="x-small", ha="right")
        ax.set_title(FEATURES[name], fontsize="small")
        ax.set_ylim(-0.02, 1.02)
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(names) :]:
        ax.axis("off")
    axes.flat[0].set_ylabel("P(inconsistent)")
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=min(len(methods), 7), fontsize="small")
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _markdown(table: pd.DataFrame, digits: int = 3) -> str:
    """A table as Markdown (numbers to ``digits`` significant digits)."""
    head = "| " + " | ".join(table.columns) + " |\n|" + "---|" * len(table.columns) + "\n"
    cells = (
        " | ".join(f"{v:.{digits}g}" if isinstance(v, float) else str(v) for v in row)
        for row in table.itertuples(index=False)
    )
    return head + "".join(f"| {line} |\n" for line in cells)


def write_study_report(directory: str | Path) -> Path:
    """Write the study's report into ``directory`` (module docstring) from its ``trials.parquet``.

    Returns ``report.md``'s path.

    Raises:
        RecordingError: no ``trials.parquet``, or not a study's table.
        OutputError: the directory is not a study's, or in use.
    """
    directory = Path(directory)
    rows = read_trials(directory)
    with claim_output_dir(directory, "study"):
        _only_ours(directory)
        rates, features = method_rates(rows), feature_rates(rows)
        fit, skipped = logistic_fit(rows)
        write_whole(directory / "methods.csv", rates.to_csv(index=False))
        write_whole(directory / "features.csv", features.to_csv(index=False))
        write_whole(directory / "logit.csv", fit.to_csv(index=False))
        if len(rates):
            _methods_figure(rates, directory / "methods.png")
        if len(features):
            _features_figure(features, directory / "features.png")
        drawn = DEVIATION in rows.columns and rows[DEVIATION].notna().any()
        if drawn:
            _deviations_figure(rows, _threshold(directory), directory / "deviations.png")
        study = rows["study"].iloc[0] if len(rows) else "?"
        shown = rates.assign(
            P=[
                f"{p:.3f} [{lo:.3f}, {hi:.3f}]"
                for p, lo, hi in zip(
                    rates["p_inconsistent"], rates["p_inconsistent_low"], rates["p_inconsistent_high"], strict=True
                )
            ]
        )
        shown = shown.assign(
            P_failed=[
                f"{p:.3f} [{lo:.3f}, {hi:.3f}]"
                for p, lo, hi in zip(rates["p_failed"], rates["p_failed_low"], rates["p_failed_high"], strict=True)
            ]
        )
        text = [
            f"# Study {study}: when does repeated motion become inconsistent?\n",
            f"{rows['trial'].nunique()} trials, {len(rows)} rows (trial x method); from `{RESULTS}` alone. "
            "P is the share of a method's trials, with its 95 % Wilson "
            "interval; rows with `status = error` are left out and counted. `violated`: rows whose run broke a "
            "check (a hand off its pose, a joint beyond a limit, an IK path through the robot or the scene; the "
            "row's `violations` names them).\n",
            "## Per method\n",
            _markdown(
                shown[
                    [
                        "method",
                        "trials",
                        "errors",
                        "inconsistent",
                        "P",
                        "failed",
                        "P_failed",
                        "violated",
                        "deviation_median_rad",
                        "deviation_p90_rad",
                    ]
                ].rename(
                    columns={
                        "P": "P(inconsistent) [95 %]",
                        "P_failed": "P(failed) [95 %]",
                        "deviation_median_rad": "deviation median [rad]",
                        "deviation_p90_rad": "p90 [rad]",
                    }
                )
            ),
            "\n![per method](methods.png)\n",
            "\nHow far apart the repetitions are, per method (the largest joint deviation, "
            "`ik.rep_joint_deviation_max_rad`):\n\n![deviations](deviations.png)\n"
            if drawn
            else "",
            f"## Against the conditions\n\nEach feature in {BINS} quantile "
            "bins (categories as they are); `features.csv` holds every bin.\n",
            "![against the conditions](features.png)\n" if len(features) else "",
            "## Logistic regression\n\nPer method, `inconsistent` on the standardised numeric "
            "features: odds ratio per standard deviation [95 %] and p-value (`logit.csv`).\n",
            _markdown(fit) if len(fit) else "No method has a fit.\n",
            "".join(f"- {m}: {why}\n" for m, why in skipped.items()),
        ]
        report = write_whole(directory / "report.md", "\n".join(text))
        written = (name for name in REPORT_FILES if (directory / name).is_file())
        write_whole(directory / DIGESTS, "".join(f"{_sha256(directory / name)}  {name}\n" for name in written))
        return report


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _only_ours(directory: Path) -> None:
    """Refuse a report file in ``directory`` other than the last report's, unchanged (``DIGESTS``).

    Raises:
        OutputError: one such file (named): a user's, or one edited since.
    """
    recorded: dict[str, str] = {}
    if (directory / DIGESTS).is_file():
        for line in (directory / DIGESTS).read_text(errors="replace").splitlines():
            digest, _, name = line.partition("  ")
            recorded[name] = digest
    for name in REPORT_FILES:
        path = directory / name
        if (path.exists() or path.is_symlink()) and (not path.is_file() or recorded.get(name) != _sha256(path)):
            raise OutputError(
                f"{excerpt(path)}: not the file the last 'study report' wrote there (yours, or edited since); "
                "move it away to write the report (nothing was written)",
                str(path),
            )
