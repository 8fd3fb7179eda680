"""``dualarm report`` never turns a recording's fields into paths unchecked: a copied run whose
manifest holds an absolute run id or a ``../`` task writes nothing anywhere (the whole temporary
tree is compared byte for byte before and after)."""

import json
import shutil
from dataclasses import replace
from pathlib import Path

import pytest
from typer.testing import CliRunner

from dualarm.cli import app
from dualarm.errors import RecordingError
from dualarm.record.readback import read_run
from dualarm.report.run_report import write_report, write_runs_report
from dualarm.run import record_run
from dualarm.tasks import load_task
from tests.helpers import TASKS

pytestmark = pytest.mark.integration

runner = CliRunner()


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Path:
    """MC-Inverse on the triangle, path and IK, one repetition."""
    return record_run(
        load_task(TASKS / "triangle.toml", 1),
        "mc-inverse",
        stages=("path", "ik"),
        out_dir=tmp_path_factory.mktemp("runs"),
    ).directory


def _tree(root: Path) -> dict[str, bytes | None]:
    """Every entry under ``root``: relative path -> the file's bytes (None for a directory)."""
    return {str(p.relative_to(root)): (None if p.is_dir() else p.read_bytes()) for p in sorted(root.rglob("*"))}


def _hostile_fields(victim: Path) -> list[dict[str, str]]:
    return [
        {"run_id": str(victim)},
        {"task": "../../x"},
        {"run_id": str(victim), "task": "../../x"},
        {"task": ".."},
        {"run_id": ".."},
        {"task": str(victim)},
    ]  # absolute paths inside the watched tree


@pytest.fixture
def sandbox(tmp_path, monkeypatch) -> tuple[Path, Path]:
    """(the tree watched, a victim directory in it holding a user's report files); the working directory is three levels
    down."""
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "summary.md").write_text("my notes\n")
    (victim / "hand_errors.png").write_bytes(b"my figure")
    cwd = tmp_path / "work" / "a" / "b"
    cwd.mkdir(parents=True)
    monkeypatch.chdir(cwd)
    return tmp_path, victim


@pytest.mark.parametrize("index", range(6))
def test_a_copied_run_with_a_hostile_manifest_writes_nothing_anywhere(run, sandbox, index):
    root, victim = sandbox
    fields = _hostile_fields(victim)[index]
    copy = root / "copied" / "triangle" / run.name
    shutil.copytree(run, copy)
    manifest = json.loads((copy / "manifest.json").read_text())
    (copy / "manifest.json").write_text(json.dumps({**manifest, **fields}))
    before = _tree(root)
    for args in (["report", str(copy)], ["report", str(copy), str(run)], ["report", str(run), str(copy)]):
        result = runner.invoke(app, args)
        assert result.exit_code == 2, result.output
        assert isinstance(result.exception, SystemExit) and "Traceback" not in result.output
        lines = [line for line in result.stderr.splitlines() if line.strip()]
        assert len(lines) == 1 and "manifest.json: " in lines[0], result.stderr
    assert _tree(root) == before


@pytest.mark.parametrize("index", range(6))
def test_write_report_refuses_fields_that_cannot_name_a_directory(run, sandbox, index):
    """The run data built in memory, past read_run's checks: write_report's default directory still refuses them."""
    root, victim = sandbox
    data = read_run(run)
    hostile = replace(data, manifest={**data.manifest, **_hostile_fields(victim)[index]})
    before = _tree(root)
    with pytest.raises(RecordingError, match=r"manifest\.json: .*cannot name a directory"):
        write_report(hostile)
    assert _tree(root) == before


def test_hostile_fields_are_only_text_when_the_report_directory_is_given(run, sandbox):
    root, victim = sandbox
    data = read_run(run)
    hostile = replace(data, manifest={**data.manifest, "run_id": str(victim), "task": "../../x"})
    before = _tree(root)
    out = write_report(hostile, root / "report")
    assert out == root / "report"
    after = _tree(root)
    assert {k: v for k, v in after.items() if k in before} == before  # nothing changed
    assert all(k == "report" or k.startswith("report/") for k in set(after) - set(before))
    assert f"# Run {victim}" in (out / "summary.md").read_text()


def test_report_without_out_writes_under_reports_task_run_id_only(run, sandbox):
    root, _ = sandbox
    manifest = json.loads((run / "manifest.json").read_text())
    before = _tree(root)
    result = runner.invoke(app, ["report", str(run)])
    assert result.exit_code == 0, result.output
    expected = Path("reports") / manifest["task"] / manifest["run_id"]
    assert Path(result.stdout.strip().splitlines()[-1]) == expected
    after = _tree(root)
    assert {k: v for k, v in after.items() if k in before} == before
    home = Path("work/a/b") / expected
    new = {Path(k) for k in set(after) - set(before)}
    assert home / "summary.md" in new
    assert all(p == home or home in p.parents or p in home.parents for p in new), sorted(new)


def test_several_runs_without_out_write_under_reports_task_first_run_id(run, sandbox):
    root, _ = sandbox
    manifest = json.loads((run / "manifest.json").read_text())
    out = write_runs_report([run, run])
    assert out == Path("reports") / manifest["task"] / f"{manifest['run_id']}+1"
    assert (Path.cwd() / out / "report.md").is_file()
    assert sorted(p.name for p in (root / "work" / "a" / "b" / "reports").iterdir()) == [manifest["task"]]
