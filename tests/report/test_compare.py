"""``dualarm compare``: every number it reports is checked against one computed independently
(from the solvers' own arrays, or with numpy on the two runs' DataFrames)."""

import json
import re
import shutil
from collections import Counter
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from mcap.reader import make_reader
from typer.testing import CliRunner

from dualarm.cli import app
from dualarm.errors import RecordingError, excerpt
from dualarm.ik.velocity.pinv import settings_for as pinv_settings_for
from dualarm.ik.velocity.pinv import solve_pinv
from dualarm.ik.velocity.tvgdd import settings_for, solve_tvgdd
from dualarm.paths import build_reference
from dualarm.record.readback import RunData, read_run
from dualarm.report.compare import COLUMNS, compare_runs
from dualarm.run import record_run
from dualarm.tasks import load_task
from tests.helpers import HUMANOID, TASKS

pytestmark = pytest.mark.integration

runner = CliRunner()
TRIANGLE = TASKS / "triangle.toml"
BALL_GAME = TASKS / "ball_game.toml"
#: The only wall-clock measurements of IK runs: per-sample solve times and their statistics.
WALL_CLOCK_WORD = "solve_time"


# --- runs, shared by the module ------------------------------------------------------------------


@pytest.fixture(scope="module")
def runs_dir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("compare_runs")


@pytest.fixture(scope="module")
def triangle_reruns(runs_dir) -> tuple[Path, Path]:
    """The same command twice: MC-Inverse on the triangle, path and IK, 2 repetitions."""
    return tuple(
        record_run(load_task(TRIANGLE, 2), "mc-inverse", stages=("path", "ik"), out_dir=runs_dir / "rerun").directory
        for _ in range(2)
    )


@pytest.fixture(scope="module")
def full_reruns(runs_dir) -> tuple[Path, Path]:
    """The same command twice through every stage (MC-Inverse, 1 repetition: a cheap full run whose trajectory passes
    validation)."""
    return tuple(
        record_run(load_task(TRIANGLE, 1), "mc-inverse", out_dir=runs_dir / "full").directory for _ in range(2)
    )


@pytest.fixture(scope="module")
def ball_game_methods(runs_dir) -> tuple[Path, Path]:
    """TV-GDD and pinv on the ball game, path and IK."""
    return tuple(
        record_run(BALL_GAME, ik, stages=("path", "ik"), out_dir=runs_dir / "methods").directory
        for ik in ("tvgdd", "pinv")
    )


@pytest.fixture(scope="module")
def gain_task(tmp_path_factory) -> Path:
    """The ball game with feedback gain K = 45 /s instead of 50 /s."""
    text = (BALL_GAME).read_text().replace('robot = "../robots/humanoid"', f'robot = "{HUMANOID}"')
    assert "feedback_gain = 50.0" in text
    path = tmp_path_factory.mktemp("gain") / "ball_game.toml"
    path.write_text(text.replace("feedback_gain = 50.0", "feedback_gain = 45.0"))
    return path


@pytest.fixture(scope="module")
def gain_pair(ball_game_methods, gain_task, runs_dir) -> tuple[Path, Path]:
    """pinv on the ball game at K = 50 and at K = 45: the same topics, fields, rows and text; only numbers differ."""
    return ball_game_methods[1], record_run(
        gain_task, "pinv", stages=("path", "ik"), out_dir=runs_dir / "gain"
    ).directory


@pytest.fixture(scope="module")
def repetitions_pair(runs_dir) -> tuple[Path, Path]:
    """pinv on the triangle with 2 repetitions (A) and with 1 (B)."""
    return tuple(
        record_run(load_task(TRIANGLE, n), "pinv", stages=("path", "ik"), out_dir=runs_dir / "reps").directory
        for n in (2, 1)
    )


# --- independent computations --------------------------------------------------------------------

_READ: dict[Path, RunData] = {}


def run_data(run: Path) -> RunData:
    """A run read back once per module (its topics are decoded once, then shared)."""
    if run not in _READ:
        _READ[run] = read_run(run)
    return _READ[run]


def paired_differences(run_a: Path, run_b: Path) -> dict[tuple[str, str], tuple[np.ndarray, np.ndarray]]:
    """(topic, field) -> (t, |A - B| per row) for two runs whose topics hold the same rows (rep, t)
    in the same order, rows paired by position; text that differs is inf, NaN in both is 0."""
    a, b = run_data(run_a), run_data(run_b)
    assert list(a.topics) == list(b.topics)
    out = {}
    for topic in a.topics:
        da, db = a[topic], b[topic]
        assert len(da) == len(db), topic
        np.testing.assert_array_equal(da["t"].to_numpy(), db["t"].to_numpy())
        np.testing.assert_array_equal(da["rep"].to_numpy(), db["rep"].to_numpy())
        assert list(da.columns) == list(db.columns), topic
        for column in da.columns:
            if column in ("t", "rep", "stage"):
                continue
            x, y = da[column], db[column]
            if pd.api.types.is_numeric_dtype(x) and pd.api.types.is_numeric_dtype(y):
                x, y = x.to_numpy(float), y.to_numpy(float)
                gap = np.abs(x - y)
                gap[np.isnan(x) & np.isnan(y)] = 0.0
                gap[np.isnan(gap)] = np.inf
            else:
                gap = np.where(x.astype(str).to_numpy() != y.astype(str).to_numpy(), np.inf, 0.0)
            out[(topic, column)] = (da["t"].to_numpy(), gap)
    return out


def largest(differences) -> dict[tuple[str, str], float]:
    return {key: float(gap.max()) if len(gap) else 0.0 for key, (_, gap) in differences.items()}


def judged(differences) -> dict:
    return {key: value for key, value in differences.items() if WALL_CLOCK_WORD not in key[1]}


def _metrics_json(run: Path) -> dict:
    path = run / "metrics.json"
    return json.loads(path.read_text()) if path.exists() else {}


def file_differences(run_a: Path, run_b: Path) -> dict[tuple[str, str], float]:
    """(``manifest.json``, ``status``) and (``metrics.json``, key) -> |A - B|, read from the runs' files
    with json: inf for differing statuses, a key of one run only, or a value null in one run only."""
    status_a, status_b = (json.loads((run / "manifest.json").read_text())["status"] for run in (run_a, run_b))
    out = {("manifest.json", "status"): 0.0 if status_a == status_b else np.inf}
    a, b = _metrics_json(run_a), _metrics_json(run_b)
    for key in set(a) | set(b):
        if key not in a or key not in b or (a[key] is None) != (b[key] is None):
            out[("metrics.json", key)] = np.inf
        else:
            out[("metrics.json", key)] = 0.0 if a[key] is None else abs(float(a[key]) - float(b[key]))
    return out


def table_of(comparison) -> dict[tuple[str, str], pd.Series]:
    return {(row["topic"], row["field"]): row for _, row in comparison.table.iterrows()}


def one_error_line(result) -> str:
    assert result.exit_code == 2, result.output
    assert isinstance(result.exception, SystemExit), result.exception
    assert "Traceback" not in result.output
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    return lines[0]


DIFFER_FIRST = re.compile(r"^differ first: (\S+) (\S+) at t = ([0-9.]+) s, rep (\d+)", re.MULTILINE)
COUNT_BEYOND = re.compile(r"^(\d+) fields beyond ", re.MULTILINE)


# --- 1. a run against its re-run ----------------------------------------------------------------


@pytest.mark.parametrize("pair", ["triangle_reruns", "full_reruns"])
def test_a_rerun_is_identical_in_every_judged_field(pair, request):
    a, b = request.getfixturevalue(pair)
    differences = paired_differences(a, b)
    expected = largest(differences) | file_differences(a, b)
    wall_clock = {key for key in expected if WALL_CLOCK_WORD in key[1]}
    assert wall_clock, "IK runs record solve times"
    assert ("metrics.json", "ik.solve_time_total_s") in wall_clock and ("manifest.json", "status") in expected
    # the product itself is deterministic: only wall-clock fields differ between the runs' DataFrames
    assert {key for key, value in expected.items() if value > 0} <= wall_clock

    comparison = compare_runs(run_data(a), run_data(b))
    table = comparison.table
    assert list(table.columns) == list(COLUMNS)
    rows = table_of(comparison)
    assert set(rows) == set(
        expected
    )  # a row per topic and field, the status and each metric; no (rows) or (topic) rows
    assert {key for key, row in rows.items() if row["wall_clock"]} == wall_clock
    for key, row in rows.items():
        assert row["rows_a"] == row["rows_b"] == row["aligned"], key
        if key in wall_clock:  # reported, with its real difference, but not judged
            assert row["max_difference"] == expected[key], key
        else:
            assert row["max_difference"] == 0.0, key
    assert comparison.within and comparison.beyond.empty

    result = runner.invoke(app, ["compare", str(a), str(b)])
    assert result.exit_code == 0, result.output
    assert "identical within 0 in every judged field" in result.stdout
    listed = re.search(r"^not judged \(wall clock\): (.*)$", result.stdout, re.MULTILINE)
    assert listed, result.stdout
    assert set(listed.group(1).split(", ")) == {f"{topic} {field}" for topic, field in wall_clock}


# --- 2. two methods ------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def ball_game_solutions():
    """The reference and TV-GDD's and pinv's joint paths, solved directly (not read from a run)."""
    task = load_task(BALL_GAME)
    reference = build_reference(task)
    settings = settings_for(task)
    pinv_settings = pinv_settings_for(task)
    assert pinv_settings.feedback_gain == settings.feedback_gain
    return (
        reference,
        solve_tvgdd(task.robot, reference, task.initial_q, settings),
        solve_pinv(task.robot, reference, task.initial_q, pinv_settings),
    )


def test_different_methods_differ_by_what_the_solvers_computed(ball_game_methods, ball_game_solutions):
    a, b = ball_game_methods
    reference, tvgdd, pinv = ball_game_solutions
    assert tvgdd.joint_names == pinv.joint_names
    rows = table_of(compare_runs(run_data(a), run_data(b)))
    for kind, x, y in (("velocity", tvgdd.qd, pinv.qd), ("position", tvgdd.q, pinv.q)):
        gap = np.abs(x - y)
        for j, joint in enumerate(tvgdd.joint_names):
            row = rows[("/ik/sample", f"{kind}.{joint}")]
            assert row["aligned"] == len(reference)
            assert row["max_difference"] == pytest.approx(gap[:, j].max(), rel=0, abs=1e-12), joint
            assert row["t"] == pytest.approx(reference.t[np.argmax(gap[:, j])], abs=1e-9), joint
            beyond = np.flatnonzero(gap[:, j] > 0)
            if len(beyond):
                assert row["first_beyond_t"] == pytest.approx(reference.t[beyond[0]], abs=1e-9), joint
            else:  # a joint both methods leave alone
                assert np.isnan(row["first_beyond_t"]) and row["max_difference"] == 0.0, joint
    method = rows[("/ik/sample", "method")]
    assert method["max_difference"] == np.inf
    assert (
        f"text differs in {len(reference)} rows" in method["note"]
        and "'tvgdd'" in method["note"]
        and "'pinv'" in method["note"]
    )


def test_different_methods_exit_1_naming_the_earliest_difference(ball_game_methods):
    a, b = ball_game_methods
    differences = judged(paired_differences(a, b))
    first_t = {key: t[np.argmax(gap > 0)] for key, (t, gap) in differences.items() if (gap > 0).any()}
    earliest = min(first_t.values())

    result = runner.invoke(app, ["compare", str(a), str(b)])
    assert result.exit_code == 1, result.output
    assert result.exception is None or isinstance(result.exception, SystemExit), result.exception
    named = DIFFER_FIRST.search(result.stdout)
    assert named, result.stdout
    topic, field, t, rep = named.groups()
    assert float(t) == pytest.approx(earliest, abs=1e-4)
    assert first_t[(topic, field)] == pytest.approx(earliest, abs=1e-9), (topic, field)  # that field does differ there
    assert int(rep) == 0
    metrics_beyond = {key for key, value in judged(file_differences(a, b)).items() if value > 0}
    assert metrics_beyond and ("manifest.json", "status") not in metrics_beyond  # both complete; their metrics differ
    count = COUNT_BEYOND.search(result.stdout)
    assert count and int(count.group(1)) == len(first_t) + len(metrics_beyond), result.stdout
    assert "/ik/sample method" in result.stdout and "/ik/sample velocity." in result.stdout


# --- 3. --tol ------------------------------------------------------------------------------------


def test_tolerance_just_above_the_largest_difference_passes_and_just_below_fails(gain_pair):
    a, b = gain_pair
    differences = judged(paired_differences(a, b))
    maxima = largest(differences) | judged(file_differences(a, b))
    assert all(np.isfinite(v) for v in maxima.values()), "only numbers differ between the two gains"
    worst = max(maxima.values())
    assert worst > 0

    above = runner.invoke(app, ["compare", str(a), str(b), "--tol", repr(worst * 1.01)])
    assert above.exit_code == 0, above.output
    assert "identical within" in above.stdout

    tol = worst * 0.99
    below = runner.invoke(app, ["compare", str(a), str(b), "--tol", repr(tol)])
    assert below.exit_code == 1, below.output
    expected = {key for key, value in maxima.items() if value > tol}
    named = DIFFER_FIRST.search(below.stdout)
    assert named and (named.group(1), named.group(2)) in expected, below.stdout
    count = COUNT_BEYOND.search(below.stdout)
    assert count and int(count.group(1)) == len(expected), below.stdout


@pytest.mark.parametrize("fraction", [0.0, 0.5, 0.99, 1.01])
def test_beyond_lists_the_fields_over_the_tolerance_with_where_they_first_exceed_it(gain_pair, fraction):
    a, b = gain_pair
    differences = judged(paired_differences(a, b))
    files = judged(file_differences(a, b))
    tol = max([*largest(differences).values(), *files.values()]) * fraction
    comparison = compare_runs(run_data(a), run_data(b), tol)
    beyond = comparison.beyond
    expected = {key for key, (_, gap) in differences.items() if (gap > tol).any()} | {
        key for key, value in files.items() if value > tol
    }
    assert set(zip(beyond["topic"], beyond["field"], strict=True)) == expected
    assert comparison.within == (not expected)
    for _, row in beyond.iterrows():
        if (row["topic"], row["field"]) in files:  # a metric: no time
            assert np.isnan(row["first_beyond_t"])
            continue
        t, gap = differences[(row["topic"], row["field"])]
        assert row["first_beyond_t"] == pytest.approx(t[np.argmax(gap > tol)], abs=1e-9)
    # earliest divergence first, the metrics (no time) last
    times = beyond["first_beyond_t"].to_numpy()
    timed = times[~np.isnan(times)]
    assert list(timed) == sorted(timed) and not np.isnan(times[: len(timed)]).any()


# --- 4. rows present in one run only -------------------------------------------------------------


def _row_counts(df: pd.DataFrame) -> Counter:
    return Counter(zip(df["rep"].to_numpy().tolist(), np.round(df["t"].to_numpy(), 9).tolist(), strict=True))


def test_rows_in_one_run_only_are_counted_and_beyond_any_tolerance(repetitions_pair):
    a, b = repetitions_pair  # 2 repetitions, 1 repetition
    da, db = run_data(a), run_data(b)
    assert set(da.topics) == set(db.topics)
    expected_rows, expected_beyond = {}, set()
    for topic in da.topics:
        ca, cb = _row_counts(da[topic]), _row_counts(db[topic])
        only_a, only_b = sum((ca - cb).values()), sum((cb - ca).values())
        aligned = sum((ca & cb).values())
        expected_rows[topic] = (only_a, only_b, aligned)
        if only_a or only_b:
            expected_beyond.add((topic, "(rows)"))
        columns_a, columns_b = set(da[topic].columns), set(db[topic].columns)
        expected_beyond |= {(topic, column) for column in columns_a ^ columns_b if WALL_CLOCK_WORD not in column}
    assert any(only_a for only_a, _, _ in expected_rows.values()), "2 repetitions have rows 1 has not"
    expected_beyond |= {key for key, value in judged(file_differences(a, b)).items() if value == np.inf}

    for swapped in (False, True):
        first, second = (b, a) if swapped else (a, b)
        table = compare_runs(run_data(first), run_data(second)).table
        for topic, (only_a, only_b, aligned) in expected_rows.items():
            if swapped:
                only_a, only_b = only_b, only_a
            rows = table[table["topic"] == topic]
            assert (rows["aligned"] == aligned).all(), topic
            marker = rows[rows["field"] == "(rows)"]
            if not (only_a or only_b):
                assert marker.empty, topic
                continue
            assert len(marker) == 1, topic
            row = marker.iloc[0]
            assert row["max_difference"] == np.inf
            ca, cb = _row_counts(da[topic]), _row_counts(db[topic])
            first_rep, first_t = min(((ca - cb) + (cb - ca)).keys())
            assert (row["first_beyond_rep"], row["first_beyond_t"]) == (first_rep, pytest.approx(first_t, abs=1e-9)), (
                topic
            )
            assert re.search(rf"\b{only_a} rows only in A, {only_b} only in B\b", row["note"]), (topic, row["note"])
            assert (row["rows_a"], row["rows_b"]) == (
                (len(db[topic]), len(da[topic])) if swapped else (len(da[topic]), len(db[topic]))
            )

    # rows in one run only are beyond any tolerance: with a huge one, only they (and fields of one run only) remain
    comparison = compare_runs(run_data(a), run_data(b), 1e300)
    assert set(zip(comparison.beyond["topic"], comparison.beyond["field"], strict=True)) == expected_beyond
    result = runner.invoke(app, ["compare", str(a), str(b), "--tol", "1e300"])
    assert result.exit_code == 1, result.output
    count = COUNT_BEYOND.search(result.stdout)
    assert count and int(count.group(1)) == len(expected_beyond), result.stdout


# --- 5. missing or corrupt run directories -------------------------------------------------------


def _truncate_mcap(run: Path) -> Path:
    mcap = run / "run.mcap"
    data = mcap.read_bytes()
    mcap.write_bytes(data[: len(data) // 2])
    return mcap


def _corrupt_chunk(run: Path) -> Path:
    """Overwrite the middle of the first chunk; the summary at the end stays readable."""
    mcap = run / "run.mcap"
    with mcap.open("rb") as f:
        chunk = min(make_reader(f).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)
    data = bytearray(mcap.read_bytes())
    middle = chunk.chunk_start_offset + chunk.chunk_length // 2
    data[middle : middle + 64] = b"\xff" * 64
    mcap.write_bytes(bytes(data))
    return mcap


def _corrupt_manifest(run: Path) -> Path:
    (run / "manifest.json").write_text("{not json")
    return run / "manifest.json"


def _remove(run: Path) -> Path:
    shutil.rmtree(run)
    return run


def _empty(run: Path) -> Path:
    shutil.rmtree(run)
    run.mkdir()
    return run / "manifest.json"


@pytest.mark.parametrize(
    "damage",
    [_remove, _empty, _truncate_mcap, _corrupt_chunk, _corrupt_manifest],
    ids=["missing", "not-a-run", "truncated-mcap", "corrupt-chunk", "corrupt-manifest"],
)
@pytest.mark.parametrize("side", ["A", "B"])
def test_a_missing_or_corrupt_run_is_one_line_and_exit_2(triangle_reruns, tmp_path, damage, side):
    good = triangle_reruns[0]
    bad = tmp_path / "copied" / good.name
    shutil.copytree(good, bad)
    named = damage(bad)
    args = [str(bad), str(good)] if side == "A" else [str(good), str(bad)]
    line = one_error_line(runner.invoke(app, ["compare", *args]))
    assert f"{excerpt(named)}: " in line, line  # the path, quoted with at most 80 characters
    with pytest.raises(RecordingError):
        compare_runs(*args)


# --- 6. --csv ------------------------------------------------------------------------------------


def test_csv_holds_the_comparison_table(repetitions_pair, tmp_path):
    a, b = repetitions_pair
    csv = tmp_path / "table.csv"
    result = runner.invoke(app, ["compare", str(a), str(b), "--csv", str(csv)])
    assert result.exit_code == 1, result.output  # the runs differ; the CSV is written all the same
    written = pd.read_csv(csv)
    table = compare_runs(run_data(a), run_data(b)).table
    assert list(written.columns) == list(COLUMNS)
    assert len(written) == len(table)
    assert (
        np.isinf(table["max_difference"]).any() and table["first_beyond_t"].isna().any()
    )  # the CSV has infs and NaNs to carry
    for column in COLUMNS:
        mine, theirs = written[column], table[column]
        if column in ("topic", "field", "note"):
            assert mine.fillna("").astype(str).tolist() == theirs.fillna("").astype(str).tolist(), column
        elif column == "wall_clock":
            assert mine.astype(bool).tolist() == theirs.astype(bool).tolist()
        else:
            np.testing.assert_array_equal(mine.to_numpy(float), theirs.to_numpy(float), err_msg=column)


def test_csv_into_a_missing_directory_is_written_or_one_line_exit_2(triangle_reruns, tmp_path):
    a, b = triangle_reruns
    csv = tmp_path / "no" / "such" / "dir" / "table.csv"
    result = runner.invoke(app, ["compare", str(a), str(b), "--csv", str(csv)])
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    assert result.exit_code in (0, 2), result.output
    if result.exit_code == 0:
        assert csv.exists()
    else:
        assert str(csv.parent) in one_error_line(result)


# --- 7. status and metrics.json ------------------------------------------------------------------


def test_runs_of_different_status_are_never_identical(triangle_reruns):
    a = run_data(triangle_reruns[0])
    failed = replace(a, manifest={**a.manifest, "status": "failed"})
    for first, second in ((a, failed), (failed, a)):
        comparison = compare_runs(first, second, 1e300)
        row = table_of(comparison)[("manifest.json", "status")]
        assert row["max_difference"] == np.inf and not row["wall_clock"]
        assert "'complete'" in row["note"] and "'failed'" in row["note"]
        assert not comparison.within
        assert [(r.topic, r.field) for r in comparison.beyond.itertuples()] == [
            ("manifest.json", "status")
        ]  # the topics are the same run's
    assert table_of(compare_runs(a, a))[("manifest.json", "status")]["max_difference"] == 0.0


def test_metrics_are_judged_with_the_tolerance_and_wall_clock_metrics_listed(triangle_reruns):
    a = run_data(triangle_reruns[0])
    metrics = json.loads((triangle_reruns[0] / "metrics.json").read_text())
    judged_key, clock_key = "path.length_max_m", "ik.solve_time_total_s"
    changed = {**metrics, judged_key: metrics[judged_key] + 1e-3, clock_key: metrics[clock_key] + 1.0}
    gap = abs(np.float64(changed[judged_key]) - np.float64(metrics[judged_key]))
    b = replace(a, metrics=changed)

    rows = table_of(compare_runs(a, b))
    assert (
        rows[("metrics.json", judged_key)]["max_difference"] == gap
        and not rows[("metrics.json", judged_key)]["wall_clock"]
    )
    assert rows[("metrics.json", clock_key)]["wall_clock"]
    assert rows[("metrics.json", clock_key)]["max_difference"] == pytest.approx(1.0, abs=1e-9)
    unchanged = [key for key in metrics if key not in (judged_key, clock_key)]
    assert unchanged and all(rows[("metrics.json", key)]["max_difference"] == 0.0 for key in unchanged)

    assert compare_runs(a, b, gap * 1.01).within  # the wall-clock second is not judged
    below = compare_runs(a, b, gap * 0.99)
    assert [(r.topic, r.field) for r in below.beyond.itertuples()] == [("metrics.json", judged_key)]


def test_a_metric_in_one_run_only_or_null_in_one_only_is_beyond_any_tolerance(triangle_reruns):
    a = run_data(triangle_reruns[0])
    metrics = json.loads((triangle_reruns[0] / "metrics.json").read_text())
    removed, nulled = sorted(k for k in metrics if "solve_time" not in k)[:2]
    b = replace(a, metrics={**{k: v for k, v in metrics.items() if k != removed}, nulled: None})
    comparison = compare_runs(a, b, 1e300)
    rows = table_of(comparison)
    assert (
        rows[("metrics.json", removed)]["max_difference"] == np.inf
        and rows[("metrics.json", removed)]["note"] == "only in A"
    )
    assert (
        rows[("metrics.json", nulled)]["max_difference"] == np.inf
        and rows[("metrics.json", nulled)]["note"] == "null in B only"
    )
    assert {(r.topic, r.field) for r in comparison.beyond.itertuples()} == {
        ("metrics.json", removed),
        ("metrics.json", nulled),
    }


@pytest.mark.parametrize("edit", ["swapped metrics.json", "failed status"])
def test_a_swapped_metrics_json_or_an_edited_status_is_not_identical_but_refused(
    triangle_reruns, repetitions_pair, tmp_path, edit
):
    """The issue's cases: ``compare`` said "identical" for a run whose metrics.json came from another
    run, or whose manifest was set to failed. The run is not one run's files: one line, exit 2."""
    good = triangle_reruns[0]
    bad = tmp_path / "copied" / good.name
    shutil.copytree(triangle_reruns[1], bad)
    if edit == "swapped metrics.json":
        shutil.copy(repetitions_pair[1] / "metrics.json", bad / "metrics.json")
        named = "metrics.json"
    else:
        manifest = json.loads((bad / "manifest.json").read_text())
        (bad / "manifest.json").write_text(json.dumps({**manifest, "status": "failed"}))
        named = "run.mcap"
    line = one_error_line(runner.invoke(app, ["compare", str(good), str(bad)]))
    assert f"{named}: " in line
