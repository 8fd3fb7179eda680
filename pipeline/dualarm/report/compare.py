"""``dualarm compare RUN_A RUN_B``: where two runs differ, topic by topic and field by field.

Both runs are read back into pandas (:mod:`dualarm.record.readback`) and each topic's rows are
aligned on repetition and motion time (to the nanosecond of the MCAP log time), and, where a topic
holds several rows at one instant (``/tf``: one per link), on their order within it. For every
field the largest absolute difference over the aligned rows is reported, with where it happens
and where the difference first exceeds the tolerance. Rows present in one run only, fields or
topics present in one run only and differing text count as beyond any tolerance.

The runs' files are judged too: the manifest's ``status`` (rows of topic ``manifest.json``: two
runs of different verdicts are never identical) and every key of ``metrics.json`` (rows of topic
``metrics.json``, a number's absolute difference; a key in one run only, or null in one run only,
is beyond any tolerance).

Wall-clock measurements (solve, planning, check and wall times, in topics and metrics alike)
differ on every run; they are reported but never judged.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from dualarm.errors import excerpt
from dualarm.record.readback import RunData, read_run

#: Fields and metrics that are wall-clock measurements: listed, never judged.
WALL_CLOCK = re.compile(r"(solve|planning|check|wall)_time")
#: The ``topic`` of the rows judging the runs' files rather than a topic of their recordings.
MANIFEST_ROWS, METRICS_ROWS = "manifest.json", "metrics.json"
_KEYS = ["rep", "t_ns", "k"]
#: Columns of :attr:`Comparison.table`.
COLUMNS = (
    "topic",
    "field",
    "max_difference",
    "t",
    "rep",
    "first_beyond_t",
    "first_beyond_rep",
    "rows_a",
    "rows_b",
    "aligned",
    "wall_clock",
    "note",
)


@dataclass(frozen=True)
class Comparison:
    """Two runs compared.

    Attributes:
        a, b: the run directories.
        tolerance: the largest absolute difference accepted (in each field's own unit).
        table: a row per topic and field (:data:`COLUMNS`): ``max_difference`` (inf where rows,
            fields or text differ; NaN where no rows aligned, which the ``(rows)`` row flags), where
            it is (``t`` [s], ``rep``), where the difference first exceeds ``tolerance``
            (``first_beyond_t``, ``first_beyond_rep``; NaN when it does not), the rows of each run
            and how many were aligned, and whether the field is a wall-clock measurement (never
            judged).
    """

    a: Path
    b: Path
    tolerance: float
    table: pd.DataFrame

    @property
    def beyond(self) -> pd.DataFrame:
        """The judged rows beyond the tolerance, the earliest divergence first."""
        judged = self.table[~self.table["wall_clock"]]
        beyond = judged[judged["max_difference"] > self.tolerance]
        return beyond.sort_values(
            ["first_beyond_t", "first_beyond_rep", "topic", "field"], na_position="last", kind="stable"
        )

    @property
    def within(self) -> bool:
        """Whether every judged field is within the tolerance."""
        return self.beyond.empty


def _keyed(df: pd.DataFrame) -> pd.DataFrame:
    """``df`` with the alignment keys: rep, time [ns] and order within (rep, time)."""
    keyed = df.drop(columns=["stage"]).assign(t_ns=np.round(df["t"].to_numpy() * 1e9).astype(np.int64))
    keyed["k"] = keyed.groupby(["rep", "t_ns"]).cumcount()
    return keyed


def _row(topic: str, field: str, rows_a: int, rows_b: int, aligned: int, **values) -> dict[str, object]:
    row = {
        "topic": topic,
        "field": field,
        "max_difference": np.inf,
        "t": np.nan,
        "rep": np.nan,
        "first_beyond_t": np.nan,
        "first_beyond_rep": np.nan,
        "rows_a": rows_a,
        "rows_b": rows_b,
        "aligned": aligned,
        "wall_clock": bool(WALL_CLOCK.search(field)),
        "note": "",
    }
    row.update(values)
    return row


def _field(
    topic: str, field: str, both: pd.DataFrame, tolerance: float, counts: tuple[int, int, int]
) -> dict[str, object]:
    """One field of the aligned rows ``both`` (columns ``<field>_a`` and ``<field>_b``)."""
    a, b = both[f"{field}_a"], both[f"{field}_b"]
    if pd.api.types.is_numeric_dtype(a) and pd.api.types.is_numeric_dtype(b):
        x, y = a.to_numpy(dtype=float), b.to_numpy(dtype=float)
        with np.errstate(invalid="ignore"):
            diff = np.where(np.isnan(x) & np.isnan(y), 0.0, np.abs(x - y))
        diff = np.where(np.isnan(diff), np.inf, diff)  # NaN in one run only
        note = ""
    else:
        unequal = (a.astype(str) != b.astype(str)).to_numpy()
        diff = np.where(unequal, np.inf, 0.0)
        note = (
            f"text differs in {unequal.sum()} rows, first {a[unequal].iloc[0]!r} vs {b[unequal].iloc[0]!r}"
            if unequal.any()
            else ""
        )
    if len(diff) == 0:
        return _row(topic, field, *counts, max_difference=np.nan, note="no rows aligned")
    worst = int(np.argmax(diff))
    beyond = np.flatnonzero(diff > tolerance)
    first = beyond[0] if len(beyond) else None
    return _row(
        topic,
        field,
        *counts,
        max_difference=float(diff[worst]),
        t=float(both["t_a"].iloc[worst]),
        rep=int(both["rep"].iloc[worst]),
        first_beyond_t=np.nan if first is None else float(both["t_a"].iloc[first]),
        first_beyond_rep=np.nan if first is None else int(both["rep"].iloc[first]),
        note=note,
    )


def compare_topic(topic: str, a: pd.DataFrame, b: pd.DataFrame, tolerance: float) -> list[dict[str, object]]:
    """Rows of :attr:`Comparison.table` for one topic present in both runs."""
    ka, kb = _keyed(a), _keyed(b)
    merged = ka.merge(kb, on=_KEYS, how="outer", suffixes=("_a", "_b"), indicator=True, sort=True)
    both = merged[merged["_merge"] == "both"]
    counts = (len(a), len(b), len(both))
    rows = []
    unmatched = merged[merged["_merge"] != "both"]
    if len(unmatched):
        first = unmatched.iloc[0]
        first_t = first["t_a"] if first["_merge"] == "left_only" else first["t_b"]
        rows.append(
            _row(
                topic,
                "(rows)",
                *counts,
                first_beyond_t=float(first_t),
                first_beyond_rep=int(first["rep"]),
                note=(
                    f"{(unmatched['_merge'] == 'left_only').sum()} rows only in "
                    f"A, {(unmatched['_merge'] == 'right_only').sum()} only in B"
                ),
            )
        )
    fields_a, fields_b = set(ka.columns) - set(_KEYS), set(kb.columns) - set(_KEYS)
    for field in sorted(fields_a | fields_b):
        if field in ("t", "t_ns"):
            continue
        if field not in fields_a or field not in fields_b:
            rows.append(_row(topic, field, *counts, note=f"only in {'A' if field in fields_a else 'B'}"))
            continue
        rows.append(_field(topic, field, both, tolerance, counts))
    return rows


def compare_status(a: RunData, b: RunData) -> list[dict[str, object]]:
    """The row of :attr:`Comparison.table` judging the runs' statuses: 0 when equal, inf otherwise.

    The statuses: ``complete``, ``violated``, ``failed``...
    """
    if a.status == b.status:
        return [_row(MANIFEST_ROWS, "status", 1, 1, 1, max_difference=0.0)]
    return [_row(MANIFEST_ROWS, "status", 1, 1, 1, note=f"{excerpt(repr(a.status))} vs {excerpt(repr(b.status))}")]


def compare_metrics(a: Mapping[str, float | None], b: Mapping[str, float | None]) -> list[dict[str, object]]:
    """Rows of :attr:`Comparison.table` for every key of two runs' ``metrics.json``.

    The absolute difference; inf for a key of one run only or a value null in one run only (0 when
    null in both).
    """
    rows = []
    for key in sorted(set(a) | set(b)):
        counts = (int(key in a), int(key in b), int(key in a and key in b))
        if key not in a or key not in b:
            rows.append(_row(METRICS_ROWS, key, *counts, note=f"only in {'A' if key in a else 'B'}"))
            continue
        x, y = a[key], b[key]
        if x is None or y is None:
            same = x is None and y is None
            rows.append(
                _row(
                    METRICS_ROWS,
                    key,
                    *counts,
                    max_difference=0.0 if same else np.inf,
                    note="" if same else f"null in {'A' if x is None else 'B'} only",
                )
            )
        else:
            rows.append(_row(METRICS_ROWS, key, *counts, max_difference=_difference(float(x), float(y))))
    return rows


def _difference(x: float, y: float) -> float:
    """|x - y|: 0 when equal (infinities included) or both NaN, inf when NaN in one only."""
    if x == y or (np.isnan(x) and np.isnan(y)):
        return 0.0
    gap = abs(x - y)
    return np.inf if np.isnan(gap) else gap


def compare_runs(run_a: str | Path | RunData, run_b: str | Path | RunData, tolerance: float = 0.0) -> Comparison:
    """Compare two runs' statuses, metrics and every topic and field (see the module's docstring).

    Raises:
        RecordingError: a run directory is missing or its recording unreadable.
    """
    a = run_a if isinstance(run_a, RunData) else read_run(run_a)
    b = run_b if isinstance(run_b, RunData) else read_run(run_b)
    rows = compare_status(a, b) + compare_metrics(a.metrics, b.metrics)
    for topic in dict.fromkeys([*a.topics, *b.topics]):
        if topic not in a.topics or topic not in b.topics:
            present = a.topics if topic in a.topics else b.topics
            rows.append(
                _row(
                    topic,
                    "(topic)",
                    len(present[topic]) if topic in a.topics else 0,
                    len(present[topic]) if topic in b.topics else 0,
                    0,
                    note=f"only in {'A' if topic in a.topics else 'B'}",
                )
            )
            continue
        rows.extend(compare_topic(topic, a[topic], b[topic], tolerance))
    return Comparison(a=a.directory, b=b.directory, tolerance=tolerance, table=pd.DataFrame(rows, columns=COLUMNS))
