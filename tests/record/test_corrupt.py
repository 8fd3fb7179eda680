"""Reading a damaged or inconsistent run directory: a RecordingError naming the file and the fault,
one line and exit 2 through ``inspect``, ``report`` and ``compare``; never a traceback, never a
silently different result.

The runs are real recordings made once per module; every case damages a copy. Where the MCAP
sections lie is found with the ``mcap`` library's own stream reader, not with our code.
"""

import json
import os
import random
import re
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from mcap.records import DataEnd, Footer
from mcap.stream_reader import StreamReader
from typer.testing import CliRunner

from dualarm.cli import app
from dualarm.errors import RecordingError, UnreachablePoseError
from dualarm.record.readback import read_run
from dualarm.record.run_dir import new_run_id
from dualarm.record.verify import RUN_ID, TASK_NAME
from dualarm.run import record_run
from dualarm.tasks import load_task
from tests.helpers import HUMANOID, TASKS

runner = CliRunner()
TRIANGLE = TASKS / "triangle.toml"
FILES = ("manifest.json", "metrics.json", "run.mcap", "run.rrd")


# --- real runs, made once ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def recordings(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("corrupt_runs")


@pytest.fixture(scope="module")
def triangle(recordings) -> Path:
    """MC-Inverse on the triangle, path and IK, one repetition."""
    return record_run(load_task(TRIANGLE, 1), "mc-inverse", stages=("path", "ik"), out_dir=recordings / "a").directory


@pytest.fixture(scope="module")
def triangle_twice(recordings) -> Path:
    """The same task and method with two repetitions: another run of the same task, other metrics."""
    return record_run(load_task(TRIANGLE, 2), "mc-inverse", stages=("path", "ik"), out_dir=recordings / "b").directory


@pytest.fixture(scope="module")
def pinv(recordings) -> Path:
    """pinv on the triangle, path and IK, one repetition: it leaves the joint limits (the TV-GDD paper's
    point about pinv), so the run finishes ``violated``, with its metrics."""
    return record_run(load_task(TRIANGLE, 1), "pinv", stages=("path", "ik"), out_dir=recordings / "p").directory


@pytest.fixture(scope="module")
def circle(recordings) -> Path:
    """Another task (the path stage only)."""
    return record_run(TASKS / "circle.toml", stages=("path",), out_dir=recordings / "c").directory


@pytest.fixture(scope="module")
def failed(recordings) -> Path:
    """A circle whose far side is out of reach: the path stage fails, the run is kept as failed (no metrics.json)."""
    text = (
        (TASKS / "circle.toml")
        .read_text()
        .replace("arc_center = [0.31, -0.11, -0.35]", "arc_center = [0.31, -0.60, -0.35]")
    )  # [0.31, -0.40, 1.05]: relative to the left shoulder [0, 0.2, 1.4]
    task = recordings / "unreachable.toml"
    task.write_text(text.replace('robot = "../robots/humanoid"', f'robot = "{HUMANOID}"'))
    with pytest.raises(UnreachablePoseError):
        record_run(task, out_dir=recordings / "f")
    (run,) = (recordings / "f" / "circle").iterdir()
    return run


def _copy(run: Path, tmp_path: Path) -> Path:
    copy = tmp_path / "copy" / run.parent.name / run.name
    shutil.copytree(run, copy)
    return copy


def _json(path: Path):
    return json.loads(path.read_text())


def _one_line(exc: pytest.ExceptionInfo) -> str:
    message = str(exc.value)
    assert "\n" not in message and message, message
    return message


def _read_error(run: Path) -> str:
    """The one-line RecordingError ``read_run(run)`` raises."""
    with pytest.raises(RecordingError) as exc:
        read_run(run)
    return _one_line(exc)


# --- the pristine runs read, and the rules accept what the writer makes ----------------------------


@pytest.mark.integration
@pytest.mark.parametrize("name", ["triangle", "triangle_twice", "pinv", "circle", "failed"])
def test_real_runs_read_with_the_files_contents(name, request):
    run = request.getfixturevalue(name)
    data = read_run(run)
    manifest = _json(run / "manifest.json")
    assert dict(data.manifest) == manifest
    if (run / "metrics.json").exists():
        assert dict(data.metrics) == _json(run / "metrics.json")
    else:
        assert manifest["status"] == "failed" and dict(data.metrics) == {}


@pytest.mark.integration
def test_run_ids_and_task_names_the_writer_makes_are_accepted(triangle, circle):
    for _ in range(20):
        assert re.fullmatch(RUN_ID, new_run_id())
    for run in (triangle, circle):
        assert re.fullmatch(RUN_ID, run.name) and re.fullmatch(TASK_NAME, run.parent.name)
    for task in TASKS.glob("*.toml"):
        assert re.fullmatch(TASK_NAME, load_task(task).name), task


# --- 1. bit flips in run.mcap ----------------------------------------------------------------------


def _sections(mcap: Path) -> tuple[int, int, int]:
    """(where DataEnd begins, where the summary begins, the file's size) [bytes], read with the mcap library."""
    data = mcap.read_bytes()
    with mcap.open("rb") as stream:
        records = list(StreamReader(stream, emit_chunks=True).records)
    (footer,) = [r for r in records if isinstance(r, Footer)]
    assert len([r for r in records if isinstance(r, DataEnd)]) == 1
    data_end = footer.summary_start - 13  # opcode (1) + length (8) + CRC (4)
    assert data[data_end] == 0x0F  # the DataEnd opcode
    return data_end, footer.summary_start, len(data)


def _flips(mcap: Path) -> list[tuple[int, int]]:
    """(byte, bit) pairs: 150 seeded in the data section and 150 in the summary section, a seeded bit
    of every byte of the leading magic and the header's start, and every bit of the DataEnd record,
    the footer and the trailing magic (where a flipped length or opcode could go unseen)."""
    data_end, summary_start, size = _sections(mcap)
    rng = np.random.default_rng(16)
    sampled = [*rng.integers(0, data_end, 150), *rng.integers(summary_start, size, 150), *range(0, 32)]
    every = [*range(data_end, summary_start), *range(size - 8 - 29, size)]
    return [(int(p), int(rng.integers(0, 8))) for p in sampled] + [(p, bit) for p in every for bit in range(8)]


def _flip(mcap: Path, original: bytes, byte: int, bit: int) -> None:
    data = bytearray(original)
    data[byte] ^= 1 << bit
    mcap.write_bytes(bytes(data))


@pytest.mark.integration
def test_every_bit_flip_in_run_mcap_is_refused_naming_the_file(triangle, tmp_path):
    """No flipped bit is read silently: every one, in data or summary, is a one-line RecordingError
    naming run.mcap (the format leaves no byte of the file outside a CRC or a checked field)."""
    run = _copy(triangle, tmp_path)
    mcap = run / "run.mcap"
    original = mcap.read_bytes()
    flips = _flips(mcap)
    assert len(flips) > 700
    read = []
    for byte, bit in flips:
        _flip(mcap, original, byte, bit)
        try:
            read_run(run)
        except RecordingError as exc:
            message = str(exc)
            assert "\n" not in message and "run.mcap: " in message, (byte, bit, message)
        else:
            read.append((byte, bit))
    assert read == [], f"flips read without complaint (byte, bit): {read}"
    mcap.write_bytes(original)
    assert read_run(run).metrics == read_run(triangle).metrics  # the copy itself is fine


@pytest.mark.integration
@pytest.mark.parametrize("section", ["data", "summary", "data_end", "footer"])
@pytest.mark.parametrize("command", ["inspect", "report", "compare"])
def test_a_flipped_bit_through_the_cli_is_one_line_and_exit_2(triangle, tmp_path, section, command):
    run = _copy(triangle, tmp_path)
    mcap = run / "run.mcap"
    data_end, summary_start, size = _sections(mcap)
    byte = {
        "data": data_end // 2,
        "summary": (summary_start + size) // 2,
        "data_end": data_end + 3,
        "footer": size - 12,
    }[section]
    _flip(mcap, mcap.read_bytes(), byte, 0)
    line = _cli_error(command, run, triangle, tmp_path)
    assert "run.mcap: " in line


# --- 2. the run's files, damaged one by one --------------------------------------------------------


def _json_list(path: Path) -> str:
    path.write_text(json.dumps([1, "two", None]))
    return "a list, not a JSON object"


def _string_values(path: Path) -> str:
    path.write_text(json.dumps({key: str(value) for key, value in _json(path).items()}))
    return "a string"


def _binary(path: Path) -> str:
    path.write_bytes(np.random.default_rng(7).bytes(512))
    return "not UTF-8"


def _truncated(path: Path) -> str:
    text = path.read_text()
    path.write_text(text[: len(text) // 2])
    return "not valid JSON"


def _directory(path: Path) -> str:
    path.unlink()
    path.mkdir()
    (path / "inside").write_text("{}")
    return "directory"


def _fifo(path: Path) -> str:
    path.unlink()
    os.mkfifo(path)  # reading it would block: it must be refused before it is opened
    return "FIFO"


def _missing(path: Path) -> str:
    path.unlink()
    return "No such file" if path.name != "metrics.json" else "missing, but the run's status is 'complete'"


def _empty(path: Path) -> str:
    path.write_bytes(b"")
    return {"run.rrd": "empty", "run.mcap": "not a readable MCAP"}.get(path.name, "not valid JSON")


def _half(path: Path) -> str:
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])  # a copy cut short
    return "Rerun cannot read it"


def _garbage(path: Path) -> str:
    path.write_bytes(random.Random(0).randbytes(5000))
    return "Rerun cannot read it"


def _nan(path: Path) -> str:
    values = _json(path)
    values[sorted(values)[0]] = float("nan")
    path.write_text(json.dumps(values))  # NaN is no JSON number, but Python's json writes and reads it
    return "finite number"


def _boolean(path: Path) -> str:
    values = _json(path)
    values[sorted(values)[0]] = True
    path.write_text(json.dumps(values))
    return "a boolean"


def _bad_key(path: Path) -> str:
    values = _json(path)
    values["no_stage_here"] = 1.0
    path.write_text(json.dumps(values))
    return "'no_stage_here' is not a metric key"


def _manifest_edit(key: str, value: object, fault: str) -> Callable[[Path], str]:
    def edit(path: Path) -> str:
        manifest = _json(path)
        if value is _DELETE:
            del manifest[key]
        else:
            manifest[key] = value
        path.write_text(json.dumps(manifest))
        return fault

    edit.__name__ = f"{key}={value!r}"
    return edit


class _Deleted:
    """The value of a key taken out of the manifest (its repr names the test case the same in every process)."""

    def __repr__(self) -> str:
        return "<deleted>"


_DELETE = _Deleted()
JSON_DAMAGE = [_json_list, _string_values, _binary, _truncated, _directory, _fifo, _missing, _empty]
CASES = [
    *[("manifest.json", d) for d in JSON_DAMAGE],
    *[("metrics.json", d) for d in [*JSON_DAMAGE, _nan, _boolean, _bad_key]],
    *[("run.mcap", d) for d in (_directory, _fifo, _missing, _empty)],
    *[("run.rrd", d) for d in (_directory, _fifo, _missing, _empty, _half, _garbage)],
    ("manifest.json", _manifest_edit("run_id", _DELETE, "key 'run_id' is missing")),
    ("manifest.json", _manifest_edit("status", "bogus", "'status'")),
    ("manifest.json", _manifest_edit("status", None, "'status'")),
    ("manifest.json", _manifest_edit("stages", "path,ik", "'stages'")),
    ("manifest.json", _manifest_edit("settings", [], "'settings'")),
    ("manifest.json", _manifest_edit("run_id", "/etc/passwd", "not a run id")),
    ("manifest.json", _manifest_edit("task", "../../x", "not a task name")),
    ("manifest.json", _manifest_edit("task", 7, "'task'")),
    ("manifest.json", _manifest_edit("error", {"nested": 1}, "'error'")),
    ("manifest.json", _manifest_edit("violations", "none", "'violations'")),
    ("manifest.json", _manifest_edit("violations", [{"message": 3}], "'violations'")),
]


def _case_id(case) -> str:
    file, damage = case
    return f"{file}-{damage.__name__.strip('_')}"


@pytest.mark.integration
@pytest.mark.parametrize("case", CASES, ids=_case_id)
def test_a_damaged_file_is_a_recording_error_naming_it(triangle, tmp_path, case):
    file, damage = case
    run = _copy(triangle, tmp_path)
    fault = damage(run / file)
    message = _read_error(run)
    assert f"{file}: " in message and fault in message, message


@pytest.mark.integration
@pytest.mark.parametrize("command", ["inspect", "report", "compare"])
@pytest.mark.parametrize("case", CASES, ids=_case_id)
def test_a_damaged_file_through_the_cli_is_one_line_and_exit_2(triangle, tmp_path, case, command):
    file, damage = case
    run = _copy(triangle, tmp_path)
    damage(run / file)
    line = _cli_error(command, run, triangle, tmp_path)
    assert f"{file}: " in line


def _cli_error(command: str, run: Path, good: Path, tmp_path: Path) -> str:
    """The one stderr line of ``command`` on the damaged ``run`` (with ``good`` as the other run of compare)."""
    args = {
        "inspect": [str(run)],
        "report": [str(run), "--out", str(tmp_path / "report")],
        "compare": [str(good), str(run)],
    }[command]
    result = runner.invoke(app, [command, *args])
    assert result.exit_code == 2, (result.exit_code, result.output, result.exception)
    assert isinstance(result.exception, SystemExit), repr(result.exception)
    assert "Traceback" not in result.output
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    return lines[0]


# --- 3. files of different runs in one directory ---------------------------------------------------


@pytest.mark.integration
def test_metrics_json_of_another_run_of_the_same_task_is_refused(triangle, triangle_twice, tmp_path):
    run = _copy(triangle, tmp_path)
    shutil.copy(triangle_twice / "metrics.json", run / "metrics.json")
    assert _json(run / "metrics.json") != _json(triangle / "metrics.json")
    message = _read_error(run)
    assert "metrics.json: " in message and "not this run's metrics" in message


@pytest.mark.integration
def test_metrics_json_differing_in_one_value_is_refused(triangle, tmp_path):
    run = _copy(triangle, tmp_path)
    metrics = _json(run / "metrics.json")
    key = "path.samples"
    metrics[key] += 1
    (run / "metrics.json").write_text(json.dumps(metrics))
    message = _read_error(run)
    assert "metrics.json: " in message and key in message


@pytest.mark.integration
def test_a_deleted_metrics_json_of_a_complete_or_violated_run_is_refused(triangle, pinv, tmp_path):
    statuses = set()
    for run in (triangle, pinv):
        status = _json(run / "manifest.json")["status"]
        statuses.add(status)
        copy = _copy(run, tmp_path / status)
        (copy / "metrics.json").unlink()
        message = _read_error(copy)
        assert "metrics.json: " in message and f"missing, but the run's status is '{status}'" in message
    assert statuses == {"complete", "violated"}


@pytest.mark.integration
def test_metrics_json_beside_a_failed_run_is_refused(failed, triangle, tmp_path):
    run = _copy(failed, tmp_path)
    shutil.copy(triangle / "metrics.json", run / "metrics.json")
    message = _read_error(run)
    assert "metrics.json: " in message and "records no metrics" in message


@pytest.mark.integration
def test_run_mcap_of_another_task_is_refused(triangle, circle, tmp_path):
    run = _copy(triangle, tmp_path)
    shutil.copy(circle / "run.mcap", run / "run.mcap")
    message = _read_error(run)
    assert "run.mcap: " in message and "task 'circle'" in message and "'triangle'" in message


@pytest.mark.integration
def test_run_rrd_of_another_run_is_refused(triangle, triangle_twice, tmp_path):
    """Rerun's reader opens it whole, but the recording it holds is another run's (it passed before)."""
    run = _copy(triangle, tmp_path)
    shutil.copy(triangle_twice / "run.rrd", run / "run.rrd")
    message = _read_error(run)
    assert "run.rrd: " in message and f"not run {triangle.name}'s" in message and triangle_twice.name in message


@pytest.mark.integration
def test_manifest_json_of_another_run_is_refused(triangle, triangle_twice, tmp_path):
    run = _copy(triangle, tmp_path)
    shutil.copy(triangle_twice / "manifest.json", run / "manifest.json")
    message = _read_error(run)
    assert "run.mcap: " in message and triangle.name in message and triangle_twice.name in message


@pytest.mark.integration
@pytest.mark.parametrize("status", ["failed", "violated", "running"])
def test_a_status_the_recording_does_not_hold_is_refused(triangle, tmp_path, status):
    run = _copy(triangle, tmp_path)
    manifest = _json(run / "manifest.json")
    manifest["status"] = status
    (run / "manifest.json").write_text(json.dumps(manifest))
    message = _read_error(run)
    assert "run.mcap: " in message and "status 'complete'" in message and repr(status) in message


@pytest.mark.integration
@pytest.mark.parametrize("case", ["metrics", "mcap", "manifest", "rrd"])
@pytest.mark.parametrize("command", ["inspect", "report", "compare"])
def test_a_mixed_run_through_the_cli_is_one_line_and_exit_2(triangle, triangle_twice, circle, tmp_path, case, command):
    run = _copy(triangle, tmp_path)
    if case == "rrd":
        (run / "run.rrd").unlink()
    else:
        source = {"metrics": triangle_twice, "mcap": circle, "manifest": triangle_twice}[case]
        name = {"metrics": "metrics.json", "mcap": "run.mcap", "manifest": "manifest.json"}[case]
        shutil.copy(source / name, run / name)
    line = _cli_error(command, run, triangle, tmp_path)
    assert {"metrics": "metrics.json: ", "mcap": "run.mcap: ", "manifest": "run.mcap: ", "rrd": "run.rrd: "}[
        case
    ] in line


def test_a_run_directory_that_is_a_file_or_missing_is_one_line(tmp_path):
    (tmp_path / "file").write_text("x")
    for path, fault in ((tmp_path / "file", "not a directory"), (tmp_path / "none", "no such run directory")):
        message = _read_error(path)
        assert fault in message
