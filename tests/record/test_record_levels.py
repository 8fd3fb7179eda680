"""Recording levels (``record_run(..., record=...)``, ``dualarm run --record``): what each writes, and reading each
back.

The runs are real: the triangle through every stage, one repetition, same seed, at each level. The MCAP is read with the
``mcap`` library, the files are listed from the file system; the metrics of the three runs are compared with each other,
not with figures of ours.
"""

import json
import re
import shutil
from pathlib import Path

import pytest
from mcap.reader import make_reader
from typer.testing import CliRunner

from dualarm.cli import app
from dualarm.errors import InvalidArgumentError, RecordingError, UnreachablePoseError
from dualarm.record.readback import read_run, read_runs
from dualarm.record.sink import RECORD_LEVELS
from dualarm.report.compare import WALL_CLOCK
from dualarm.run import record_run
from dualarm.tasks import load_task
from tests.helpers import HUMANOID, TASKS

runner = CliRunner()
#: The files every recorded run holds, and those only a run with recordings holds (a Foxglove layout may come beside
#: them).
ALWAYS, RECORDINGS, LAYOUT = {"manifest.json", "metrics.json"}, {"run.mcap", "run.rrd"}, "foxglove-layout.json"
#: Topic families of the stages an ``ik`` run leaves out.
LATER = ("/retime", "/smooth", "/approach", "/execute")


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    """Level -> the run directory of the triangle (MC-Inverse, every stage, one repetition, seed 0) recorded at that
    level."""
    out = tmp_path_factory.mktemp("levels")
    return {
        level: record_run(
            load_task(TASKS / "triangle.toml", 1), "mc-inverse", out_dir=out / level, seed=0, record=level
        ).directory
        for level in RECORD_LEVELS
    }


def _topics(mcap: Path) -> set[str]:
    with mcap.open("rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None and summary.statistics is not None
    counts = summary.statistics.channel_message_counts
    return {channel.topic for i, channel in summary.channels.items() if counts.get(i, 0) > 0}


def _files(run: Path) -> set[str]:
    return {p.name for p in run.iterdir()}


@pytest.mark.integration
def test_each_level_writes_exactly_its_files_and_records_its_level(runs):
    full, ik, metrics = (_files(runs[level]) for level in ("full", "ik", "metrics"))
    assert metrics == ALWAYS
    assert full == ik == ALWAYS | RECORDINGS | ({LAYOUT} & full)
    for level, run in runs.items():
        manifest = json.loads((run / "manifest.json").read_text())
        assert manifest["record"] == level and manifest["status"] == "complete"
        assert manifest["stages"] == [
            "path",
            "ik",
            "retime",
            "smooth",
            "approach",
            "execute",
        ]  # every stage ran, whatever was recorded


@pytest.mark.integration
def test_an_ik_run_records_the_path_and_ik_stages_only(runs):
    full, ik = _topics(runs["full"] / "run.mcap"), _topics(runs["ik"] / "run.mcap")
    assert {"/task/joint_state", "/ik/sample", "/ik/limits", "/tf", "/metrics"} <= ik
    assert not [t for t in ik if t.startswith(LATER)]
    assert [t for t in full if t.startswith(LATER)]  # the full run of the same task has them


@pytest.mark.integration
def test_every_level_has_the_same_metrics_and_verdict(runs):
    """Every stage runs whatever the level: the metrics (wall-clock times aside) and verdicts are the full run's."""
    metrics = {level: json.loads((run / "metrics.json").read_text()) for level, run in runs.items()}
    assert any(k.startswith("execute.") for k in metrics["full"])
    judged = {level: {k: v for k, v in m.items() if not WALL_CLOCK.search(k)} for level, m in metrics.items()}
    assert set(metrics["ik"]) == set(metrics["metrics"]) == set(metrics["full"])
    assert judged["ik"] == judged["metrics"] == judged["full"]
    manifests = {level: json.loads((run / "manifest.json").read_text()) for level, run in runs.items()}
    assert {level: (m["status"], m["violations"]) for level, m in manifests.items()} == dict.fromkeys(
        RECORD_LEVELS, (manifests["full"]["status"], manifests["full"]["violations"])
    )


@pytest.mark.integration
def test_a_metrics_run_reads_back_with_no_topics_and_names_its_level(runs):
    data = read_run(runs["metrics"])
    assert data.record == "metrics" and dict(data.topics) == {}
    assert dict(data.metrics) == json.loads((runs["metrics"] / "metrics.json").read_text())
    with pytest.raises(RecordingError, match="recorded with --record metrics") as exc:
        data["/ik/sample"]
    assert "\n" not in str(exc.value)


@pytest.mark.integration
def test_an_ik_run_reads_back_its_topics_and_names_its_level_for_the_others(runs):
    data = read_run(runs["ik"])
    assert data.record == "ik" and data.recorded_stages == ["path", "ik"]
    assert len(data["/ik/sample"]) == len(read_run(runs["full"])["/ik/sample"])
    with pytest.raises(
        RecordingError, match=r"no topic '/retime/sample': the run was recorded with --record ik \(.*path, ik only"
    ) as exc:
        data["/retime/sample"]
    assert "\n" not in str(exc.value)
    with pytest.raises(RecordingError, match=r"no topic '/nonsense' \(topics: "):
        data["/nonsense"]


@pytest.mark.integration
def test_read_runs_concatenates_the_runs_that_hold_a_topic(runs):
    frames = read_runs(runs.values(), topics=["/ik/sample", "/execute/sample"])
    assert set(frames["/ik/sample"]["run"]) == {runs["full"].name, runs["ik"].name}
    assert set(frames["/execute/sample"]["run"]) == {runs["full"].name}


@pytest.mark.integration
def test_inspect_and_compare_take_runs_of_every_level(runs):
    for level, run in runs.items():
        result = runner.invoke(app, ["inspect", str(run)])
        assert result.exit_code == 0, result.output
        assert ("record   " in result.output) == (level != "full")
    result = runner.invoke(app, ["inspect", str(runs["metrics"])])
    assert (
        "record   metrics (no run.mcap, no run.rrd, no topics" in result.output
        and "execute.duration_s" in result.output
    )
    same = runner.invoke(app, ["compare", str(runs["metrics"]), str(runs["metrics"])])
    assert same.exit_code == 0 and "identical" in same.output
    differ = runner.invoke(app, ["compare", str(runs["full"]), str(runs["ik"])])
    assert differ.exit_code == 1 and "/retime/sample" in differ.output  # topics only the full run holds


def _copy(run: Path, tmp_path: Path) -> Path:
    copy = tmp_path / run.parent.name / run.name
    shutil.copytree(run, copy)
    return copy


def _edit_manifest(run: Path, **changes) -> None:
    manifest = json.loads((run / "manifest.json").read_text())
    (run / "manifest.json").write_text(json.dumps({**manifest, **changes}))


@pytest.mark.integration
def test_a_recording_beside_a_metrics_run_is_refused(runs, tmp_path):
    for name in ("run.mcap", "run.rrd"):
        copy = _copy(runs["metrics"], tmp_path / name)
        shutil.copy(runs["full"] / name, copy / name)
        with pytest.raises(
            RecordingError, match=f"{name}: present, but manifest.json says the run was recorded with --record metrics"
        ):
            read_run(copy)


@pytest.mark.integration
@pytest.mark.parametrize(
    ("level", "claimed", "needle"),
    [
        ("ik", "full", "records record 'ik', but manifest.json says 'full'"),
        ("full", "metrics", "run.mcap: present"),
        ("ik", "bogus", "'record'"),
    ],
)
def test_a_manifest_claiming_another_level_is_refused(runs, tmp_path, level, claimed, needle):
    copy = _copy(runs[level], tmp_path)
    _edit_manifest(copy, record=claimed)
    with pytest.raises(RecordingError, match=re.escape(needle)):
        read_run(copy)
    result = runner.invoke(app, ["inspect", str(copy)])
    assert result.exit_code == 2 and len(result.output.strip().splitlines()) == 1


@pytest.mark.integration
def test_a_metrics_run_without_its_metrics_is_refused(runs, tmp_path):
    copy = _copy(runs["metrics"], tmp_path)
    (copy / "metrics.json").unlink()
    with pytest.raises(RecordingError, match="missing, but the run's status is 'complete'"):
        read_run(copy)


def test_an_unknown_level_is_refused_before_anything_is_written(tmp_path):
    with pytest.raises(
        InvalidArgumentError, match=r"record: unknown recording level 'everything' \(levels: full, ik, metrics\)"
    ):
        record_run(TASKS / "triangle.toml", stages=("path",), out_dir=tmp_path / "api", record="everything")
    result = runner.invoke(app, ["run", "triangle", "--record", "everything", "--out", str(tmp_path / "cli")])
    assert result.exit_code == 2
    assert result.output.strip() == "error: --record 'everything': unknown recording level (levels: full, ik, metrics)"
    assert not (tmp_path / "api").exists() and not (tmp_path / "cli").exists()


@pytest.mark.integration
def test_cli_run_records_at_the_level_asked(tmp_path):
    result = runner.invoke(app, ["run", "triangle", "--reps", "1", "--record", "metrics", "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    run = Path(result.output.strip().splitlines()[-1])
    assert _files(run) == ALWAYS and json.loads((run / "manifest.json").read_text())["record"] == "metrics"


@pytest.mark.integration
def test_a_failed_metrics_run_is_kept_with_its_manifest_only(tmp_path):
    """A circle whose far side is out of reach: the path stage fails; the run is kept as failed, its manifest alone, and
    reads back."""
    text = (
        (TASKS / "circle.toml")
        .read_text()
        .replace("arc_center = [0.31, -0.11, -0.35]", "arc_center = [0.31, -0.60, -0.35]")
    )  # [0.31, -0.40, 1.05]: relative to the left shoulder [0, 0.2, 1.4]
    task = tmp_path / "unreachable.toml"
    task.write_text(text.replace('robot = "../robots/humanoid"', f'robot = "{HUMANOID}"'))
    with pytest.raises(UnreachablePoseError):
        record_run(task, out_dir=tmp_path / "runs", record="metrics")
    (run,) = (tmp_path / "runs" / "circle").iterdir()
    assert _files(run) == {"manifest.json"}
    data = read_run(run)
    assert (data.status, data.record, dict(data.metrics), dict(data.topics)) == ("failed", "metrics", {}, {})
    assert "reach" in data.error or "workspace" in data.error
