"""``dualarm compare RUN_A RUN_B``: where two runs differ, topic by topic and field by field.

Both runs are read back into pandas (:mod:`dualarm.record.readback`) and each topic's rows are
aligned on repetition and motion time (to the nanosecond of the MCAP log time), and, where a topic
holds several rows at one instant (``/tf``: one per link), on their order within it. For every
field the largest absolute difference over the aligned rows is reported, with where it happens
and where the difference first exceeds the tolerance. Rows present in one run only, fields or
topics present in one run only and differing text count as beyond any tolerance.

Wall-clock measurements (solve, planning and collision-check times) differ on every run; they are
reported but never judged.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from dualarm.record.readback import RunData, read_run

#: Fields that are wall-clock measurements: listed, never judged.
WALL_CLOCK = re.compile(r"(solve|planning|check)_time")
_KEYS = ["rep", "t_ns", "k"]
#: Columns of :attr:`Comparison.table`.
COLUMNS = ("topic", "field", "max_difference", "t", "rep", "first_beyond_t", "first_beyond_rep", "rows_a", "rows_b", "aligned", "wall_clock", "note")


@dataclass(frozen=True)
class Comparison:
    """Two runs compared.

    Attributes:
        a, b: the run directories.
        tolerance: the largest absolute difference accepted (in each field's own unit).
        table: a row per topic and field (:data:`COLUMNS`): ``max_difference`` (inf where rows,
            fields or text differ; NaN where no rows aligned, which the ``(rows)`` row flags), where it is (``t`` [s], ``rep``), where the difference first
            exceeds ``tolerance`` (``first_beyond_t``, ``first_beyond_rep``; NaN when it does
            not), the rows of each run and how many were aligned, and whether the field is a
            wall-clock measurement (never judged).
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
        return beyond.sort_values(["first_beyond_t", "first_beyond_rep", "topic", "field"], na_position="last", kind="stable")

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


def _field(topic: str, field: str, both: pd.DataFrame, tolerance: float, counts: tuple[int, int, int]) -> dict[str, object]:
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
        note = f"text differs in {unequal.sum()} rows, first {a[unequal].iloc[0]!r} vs {b[unequal].iloc[0]!r}" if unequal.any() else ""
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
                note=f"{(unmatched['_merge'] == 'left_only').sum()} rows only in A, {(unmatched['_merge'] == 'right_only').sum()} only in B",
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


def compare_runs(run_a: str | Path | RunData, run_b: str | Path | RunData, tolerance: float = 0.0) -> Comparison:
    """Compare every topic and field of two runs (see the module's docstring).

    Raises:
        RecordingError: a run directory is missing or its recording unreadable.
    """
    a = run_a if isinstance(run_a, RunData) else read_run(run_a)
    b = run_b if isinstance(run_b, RunData) else read_run(run_b)
    rows: list[dict[str, object]] = []
    for topic in dict.fromkeys([*a.topics, *b.topics]):
        if topic not in a.topics or topic not in b.topics:
            present = a.topics if topic in a.topics else b.topics
            rows.append(
                _row(topic, "(topic)", len(present[topic]) if topic in a.topics else 0, len(present[topic]) if topic in b.topics else 0, 0, note=f"only in {'A' if topic in a.topics else 'B'}")
            )
            continue
        rows.extend(compare_topic(topic, a[topic], b[topic], tolerance))
    return Comparison(a=a.directory, b=b.directory, tolerance=tolerance, table=pd.DataFrame(rows, columns=COLUMNS))
