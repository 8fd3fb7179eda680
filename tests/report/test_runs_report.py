"""``dualarm report RUN1 RUN2 ... --out DIR``: runs.csv is the runs' own metrics.json, the figures
follow what the recordings hold, report.md links it all, and copied runs report the same."""

import json
import math
import re
import shutil
import tomllib
from pathlib import Path

import matplotlib.image
import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from dualarm.cli import app
from dualarm.report.run_report import RUN_COLUMNS
from dualarm.run import record_run
from dualarm.tasks import load_task
from tests.helpers import TASKS

pytestmark = pytest.mark.integration

runner = CliRunner()
TRIANGLE = TASKS / "triangle.toml"
BALL_GAME = TASKS / "ball_game.toml"
#: Figures that need a run through retime, smooth and execute.
BACK_HALF_FIGURES = {"tracking_errors.png", "limit_ratios.png"}
LINK = re.compile(r"(!?)\[[^\]]*\]\(([^)\s]+)\)")


# --- runs and reports, shared by the module ------------------------------------------------------


@pytest.fixture(scope="module")
def runs_dir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("report_runs")


@pytest.fixture(scope="module")
def ik_runs(runs_dir) -> list[Path]:
    """IK-only runs: MC-Inverse and pinv on the triangle (2 repetitions), TV-GDD on the ball game (1)."""
    return [
        record_run(load_task(TRIANGLE, 2), "mc-inverse", stages=("path", "ik"), out_dir=runs_dir).directory,
        record_run(load_task(TRIANGLE, 2), "pinv", stages=("path", "ik"), out_dir=runs_dir).directory,
        record_run(BALL_GAME, "tvgdd", stages=("path", "ik"), out_dir=runs_dir).directory,
    ]


@pytest.fixture(scope="module")
def full_run(runs_dir) -> Path:
    """The one run through every stage: MC-Inverse on the triangle, 1 repetition."""
    return record_run(load_task(TRIANGLE, 1), "mc-inverse", out_dir=runs_dir).directory


def _report(run_dirs: list[Path], out: Path) -> Path:
    result = runner.invoke(app, ["report", *map(str, run_dirs), "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert Path(result.stdout.strip().splitlines()[-1]) == out
    return out


@pytest.fixture(scope="module")
def ik_report(ik_runs, tmp_path_factory) -> tuple[Path, list[Path]]:
    return _report(ik_runs, tmp_path_factory.mktemp("ik_report")), ik_runs


@pytest.fixture(scope="module")
def mixed_report(ik_runs, full_run, tmp_path_factory) -> tuple[Path, list[Path]]:
    """The IK-only runs and the full run."""
    runs = [*ik_runs, full_run]
    return _report(runs, tmp_path_factory.mktemp("mixed_report")), runs


@pytest.fixture(params=["ik_report", "mixed_report"])
def report(request) -> tuple[Path, list[Path]]:
    return request.getfixturevalue(request.param)


def _json(path: Path) -> dict:
    return json.loads(path.read_text())


def _same(value, expected) -> bool:
    """A runs.csv cell against a metrics.json value (null and absent are NaN in the CSV)."""
    if expected is None:
        return isinstance(value, float) and math.isnan(value)
    return float(value) == float(expected)


# --- 1. runs.csv ---------------------------------------------------------------------------------


def test_runs_csv_has_a_row_per_run_with_its_metrics_json(report):
    out, runs = report
    table = pd.read_csv(out / "runs.csv")
    assert len(table) == len(runs)
    metrics = [_json(run / "metrics.json") for run in runs]
    manifests = [_json(run / "manifest.json") for run in runs]
    keys = sorted(set().union(*metrics))
    assert list(table.columns) == [*RUN_COLUMNS, *keys]
    assert table["label"].is_unique
    for (_, row), run, metric, manifest in zip(table.iterrows(), runs, metrics, manifests, strict=True):
        assert row["run"] == manifest["run_id"] == run.name
        assert row["task"] == manifest["task"]
        assert row["method"] == manifest["settings"]["ik"]["method"]
        assert (
            row["status"] == manifest["status"] in ("complete", "violated")
        )  # pinv in pose mode leaves the joint limits on the triangle
        assert row["stages"] == ",".join(manifest["stages"])
        assert row["repetitions"] == manifest["settings"]["path"]["repetitions"] == metric["path.repetitions"]
        assert Path(row["directory"]) == run
        for key in keys:
            assert _same(row[key], metric.get(key)), (run.name, key, row[key], metric.get(key))


# --- 2. figures chosen by content ----------------------------------------------------------------


def _hands(task_file: Path) -> list[str]:
    """The hands a task moves: the keys of its [start] table."""
    return sorted(tomllib.loads(task_file.read_text())["start"])


def _expected_figures(runs: list[Path]) -> set[str]:
    manifests = [_json(run / "manifest.json") for run in runs]
    expected = {"ik_hand_errors.png"} if any("ik" in m["stages"] for m in manifests) else set()
    if any("execute" in m["stages"] for m in manifests):
        expected |= BACK_HALF_FIGURES
    task_files = {"triangle": TRIANGLE, "ball_game": BALL_GAME}
    for task in {m["task"] for m in manifests if "ik" in m["stages"] and m["settings"]["path"]["repetitions"] > 1}:
        expected.add(f"arm_angle_{task}.png")
        expected |= {f"joints_{task}_{hand}.png" for hand in _hands(task_files[task])}
    return expected


def _check_png(path: Path) -> None:
    assert path.stat().st_size > 10_000, path
    image = matplotlib.image.imread(path)
    assert image.ndim == 3 and image.shape[0] >= 200 and image.shape[1] >= 200, (path, image.shape)
    assert float(np.std(image[..., :3])) > 0.01, f"{path} is blank"


def test_ik_only_runs_give_ik_figures_and_no_back_half_figures(ik_report):
    out, runs = ik_report
    pngs = {p.name for p in out.glob("*.png")}
    assert pngs == _expected_figures(runs)
    assert "ik_hand_errors.png" in pngs and not pngs & BACK_HALF_FIGURES
    # the triangle runs have 2 repetitions, the ball game 1: per-repetition figures for the triangle only
    assert {"arm_angle_triangle.png", "joints_triangle_left.png"} <= pngs
    assert not [name for name in pngs if "ball_game" in name]
    for name in pngs:
        _check_png(out / name)


def test_a_full_run_adds_tracking_errors_and_limit_ratios(ik_report, mixed_report):
    ik_pngs = {p.name for p in ik_report[0].glob("*.png")}
    out, runs = mixed_report
    pngs = {p.name for p in out.glob("*.png")}
    assert pngs == _expected_figures(runs)
    assert pngs == ik_pngs | BACK_HALF_FIGURES
    for name in pngs:
        _check_png(out / name)


# --- 3. report.md --------------------------------------------------------------------------------


def test_report_md_links_every_summary_and_figure(report):
    out, runs = report
    links = LINK.findall((out / "report.md").read_text())
    targets = [target for _, target in links]
    for target in targets:
        assert (out / target).is_file(), f"report.md links {target}, which does not exist"
    summaries = [target for bang, target in links if not bang and target.endswith("summary.md")]
    assert len(summaries) == len(set(summaries)) == len(runs)
    headed = {(out / target).read_text().splitlines()[0] for target in summaries}
    assert headed == {f"# Run {_json(run / 'manifest.json')['run_id']}" for run in runs}
    images = {target for bang, target in links if bang}
    assert images == {p.name for p in out.glob("*.png")}
    for target in summaries:  # and each summary's own figures are where it says
        summary = out / target
        for _, figure in LINK.findall(summary.read_text()):
            assert (summary.parent / figure).is_file(), f"{target} links {figure}, which does not exist"


# --- 4. runs copied to another machine -----------------------------------------------------------


def test_copied_runs_report_the_same(ik_report, tmp_path):
    out, runs = ik_report
    copies = []
    for run in runs:
        copy = tmp_path / "other-machine" / run.parent.name / run.name
        shutil.copytree(run, copy)
        copies.append(copy)
    copied = _report(copies, tmp_path / "report")
    original, again = pd.read_csv(out / "runs.csv"), pd.read_csv(copied / "runs.csv")
    assert [Path(d) for d in again["directory"]] == copies
    pd.testing.assert_frame_equal(again.drop(columns="directory"), original.drop(columns="directory"))
    assert (copied / "report.md").read_text() == (out / "report.md").read_text()
    assert {p.name for p in copied.glob("*.png")} == {p.name for p in out.glob("*.png")}
    for summary in out.glob("*/summary.md"):
        assert (copied / summary.parent.name / "summary.md").read_text() == summary.read_text()


def test_a_run_and_its_copy_side_by_side_stay_apart(ik_runs, tmp_path):
    run = ik_runs[0]
    copy = tmp_path / "other-machine" / run.parent.name / run.name
    shutil.copytree(run, copy)
    out = _report([run, copy], tmp_path / "report")
    table = pd.read_csv(out / "runs.csv")
    assert table["label"].is_unique, list(table["label"])
    summaries = [
        target
        for bang, target in LINK.findall((out / "report.md").read_text())
        if not bang and target.endswith("summary.md")
    ]
    assert len(set(summaries)) == 2, summaries


# --- 5. one run, and a bad directory among several -----------------------------------------------


def test_a_single_run_still_writes_summary_md(ik_runs, tmp_path):
    run = ik_runs[0]
    manifest = _json(run / "manifest.json")
    out = _report([run], tmp_path / "single")
    summary = (out / "summary.md").read_text()
    assert summary.splitlines()[0] == f"# Run {manifest['run_id']}"
    assert "## Metrics" in summary and f"## IK: {manifest['settings']['ik']['method']}" in summary
    for key in _json(run / "metrics.json"):
        assert f"| {key} |" in summary, key
    assert not (out / "runs.csv").exists() and not (out / "report.md").exists()
    for target in (target for _, target in LINK.findall(summary)):
        assert (out / target).is_file(), target


def _missing(run: Path, tmp_path: Path) -> Path:
    return tmp_path / "no-such-run"


def _truncated(run: Path, tmp_path: Path) -> Path:
    copy = tmp_path / "truncated" / run.name
    shutil.copytree(run, copy)
    data = (copy / "run.mcap").read_bytes()
    (copy / "run.mcap").write_bytes(data[: len(data) // 2])
    return copy


@pytest.mark.parametrize("bad", [_missing, _truncated], ids=["missing", "truncated-mcap"])
def test_a_bad_directory_among_several_is_one_line_and_exit_2(ik_runs, tmp_path, bad):
    broken = bad(ik_runs[0], tmp_path)
    result = runner.invoke(
        app, ["report", str(ik_runs[1]), str(broken), str(ik_runs[2]), "--out", str(tmp_path / "report")]
    )
    assert result.exit_code == 2, result.output
    assert isinstance(result.exception, SystemExit), result.exception
    assert "Traceback" not in result.output
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and broken.name in lines[0], (
        result.stderr
    )  # paths are quoted to ~80 characters
