"""Output directories: made and marked, reused only when dualarm wrote everything in them, locked, refused in one
message naming the path and the cause; whole writes."""

import errno
import fcntl
import os
from pathlib import Path

import pytest

from dualarm.errors import InvalidArgumentError, OutputError
from dualarm.record import run_dir
from dualarm.record.run_dir import MARKER, RunDirectory, claim_output_dir, write_whole


def tree(directory: Path) -> dict[str, bytes | None]:
    """Every entry under ``directory``: a file's bytes, None for a directory."""
    return {
        str(p.relative_to(directory)): (p.read_bytes() if p.is_file() else None) for p in sorted(directory.rglob("*"))
    }


def plant(directory: Path) -> dict[str, bytes | None]:
    """A user's files in ``directory`` (made if missing); returns its tree."""
    (directory / "sub").mkdir(parents=True, exist_ok=True)
    (directory / "precious.txt").write_bytes(b"keep me\n")
    (directory / "sub" / "data.csv").write_bytes(b"a,b\n1,2\n")
    return tree(directory)


def test_a_new_directory_is_made_with_a_marker_naming_its_kind(tmp_path):
    target = tmp_path / "a" / "b" / "plan"
    with claim_output_dir(target, "plan") as claimed:
        assert claimed.path == target and target.is_dir()
        assert [p.name for p in target.iterdir()] == [MARKER]
        assert (target / MARKER).read_text().splitlines()[0] == "dualarm plan"


def test_a_directory_dualarm_made_is_reused_with_its_own_files(tmp_path):
    target = tmp_path / "plan"
    claim_output_dir(target, "plan").release()
    (target / "plan_trials.csv").write_text("trial\n0\n")
    (target / ".plan_summary.json.partial").write_text("{")  # a write cut short
    with claim_output_dir(target, "plan"):
        pass


@pytest.mark.parametrize("kind", ["plan", "consistency", "report", "reproduction"])
def test_a_users_directory_is_refused_naming_an_entry_and_left_alone(tmp_path, kind):
    target = tmp_path / "mine"
    before = plant(target)
    with pytest.raises(OutputError) as caught:
        claim_output_dir(target, kind)
    message = str(caught.value)
    assert str(target) in message and "precious.txt" in message and f"not a {kind} directory" in message
    assert tree(target) == before


def test_a_foreign_entry_in_a_marked_directory_is_named_and_nothing_changes(tmp_path):
    target = tmp_path / "report"
    claim_output_dir(target, "report").release()
    (target / "summary.md").write_text("# Run\n")
    (target / "inner").mkdir()
    claim_output_dir(target / "inner", "report").release()
    (target / "inner" / "notes.txt").write_text("mine\n")
    before = tree(target)
    with pytest.raises(
        OutputError, match=r"holds 'inner/notes.txt', which dualarm does not write into a report directory"
    ):
        claim_output_dir(target, "report")
    assert tree(target) == before


def test_an_empty_directory_is_taken_and_marked(tmp_path):
    with claim_output_dir(tmp_path, "consistency"):
        assert (tmp_path / MARKER).read_text().startswith("dualarm consistency\n")


def test_another_kind_is_refused(tmp_path):
    claim_output_dir(tmp_path / "x", "plan").release()
    with pytest.raises(OutputError, match=r"not a report directory \(its \.dualarm marker says 'plan'\)"):
        claim_output_dir(tmp_path / "x", "report")


def test_unknown_kind_is_an_invalid_argument(tmp_path):
    with pytest.raises(InvalidArgumentError, match="kinds: recordings, plan"):
        claim_output_dir(tmp_path, "holiday")


def test_recordings_take_any_directory_and_touch_nothing_else(tmp_path):
    """A recordings directory only gains runs: a user's files do not stop a run and stay as they were."""
    before = plant(tmp_path)
    (tmp_path / "triangle").mkdir()
    (tmp_path / "triangle" / "notes.txt").write_bytes(b"mine")
    before = tree(tmp_path)
    run = RunDirectory.create(tmp_path, "triangle", {})
    assert (
        run.staging.parent == tmp_path / "triangle"
        and run.staging.is_dir()
        and run.final.parent == tmp_path / "triangle"
    )
    after = tree(tmp_path)
    assert {k: v for k, v in after.items() if k in before} == before
    assert set(after) - set(before) == {
        str(run.staging.relative_to(tmp_path))
    }  # no marker: the directory is not dualarm's
    del run


def test_a_run_never_takes_the_name_of_an_existing_entry(tmp_path, monkeypatch):
    (tmp_path / "triangle" / "20260101-000000-aaaaaa").mkdir(parents=True)
    ids = iter(["20260101-000000-aaaaaa", "20260101-000000-bbbbbb"])
    monkeypatch.setattr(run_dir, "new_run_id", lambda: next(ids))
    run = RunDirectory.create(tmp_path, "triangle", {})
    assert run.run_id == "20260101-000000-bbbbbb"
    assert not any((tmp_path / "triangle" / "20260101-000000-aaaaaa").iterdir())


@pytest.mark.parametrize("name", ["", ".", "..", "a/b", "../up"])
def test_a_task_name_that_is_not_one_component_is_refused(tmp_path, name):
    with pytest.raises(InvalidArgumentError, match="task_name"):
        RunDirectory.create(tmp_path, name, {})
    assert not any(tmp_path.iterdir())


def _os_cases(tmp_path: Path) -> dict[str, tuple[Path | str, str]]:
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    return {
        "regular file": (a_file, "exists and is not a directory"),
        "through a file": (a_file / "out", os.strerror(errno.ENOTDIR)),
        "too long": (tmp_path / ("x" * 300), os.strerror(errno.ENAMETOOLONG)),
        "empty": ("", "the output path is empty"),
        "NUL byte": (str(tmp_path / "a\0b"), "cannot hold a NUL byte"),
    }


@pytest.mark.parametrize("case", ["regular file", "through a file", "too long", "empty", "NUL byte"])
@pytest.mark.parametrize("kind", ["recordings", "report"])
def test_system_refusals_are_one_line_naming_the_path_and_the_cause(tmp_path, case, kind):
    path, cause = _os_cases(tmp_path)[case]
    before = tree(tmp_path)
    with pytest.raises(OutputError) as caught:
        claim_output_dir(path, kind)
    message = str(caught.value)
    assert cause in message and "\n" not in message and len(message) < 200
    if case in ("regular file", "through a file"):
        assert str(path) in message
    assert tree(tmp_path) == before


def test_an_unwritable_place_is_one_line(tmp_path):
    if os.geteuid() == 0:  # root writes anywhere but where the system forbids it
        place = Path("/sys/dualarm-test")
        try:
            place.mkdir()
        except PermissionError as exc:
            cause = exc.strerror
        else:
            place.rmdir()
            pytest.skip("/sys is writable here")
    else:
        (tmp_path / "locked").mkdir(mode=0o500)
        place, cause = tmp_path / "locked" / "out", os.strerror(errno.EACCES)
    with pytest.raises(OutputError, match="cannot create the directory") as caught:
        claim_output_dir(place, "report")
    assert str(place) in str(caught.value) and cause in str(caught.value)


def test_a_claimed_directory_is_locked_until_released(tmp_path):
    first = claim_output_dir(tmp_path / "r", "report")
    with pytest.raises(OutputError, match="in use by another dualarm process"):
        claim_output_dir(tmp_path / "r", "report")
    # the lock is the system's: flock on the directory is refused to anyone else too
    fd = os.open(tmp_path / "r", os.O_RDONLY)
    with pytest.raises(BlockingIOError):
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    first.release()
    fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    os.close(fd)
    claim_output_dir(tmp_path / "r", "report").release()


def test_runs_share_a_recordings_directory(tmp_path):
    first = RunDirectory.create(tmp_path / "rec", "triangle", {})
    second = RunDirectory.create(tmp_path / "rec", "triangle", {})
    assert first.staging != second.staging
    with pytest.raises(OutputError, match="in use"):  # but no one may empty it meanwhile
        claim_output_dir(tmp_path / "rec", "plan")
    del first, second
    assert (tmp_path / "rec" / MARKER).read_text().startswith("dualarm recordings")


def _reproduction(out: Path) -> None:
    """A reproduction's tree as dualarm writes it."""
    claimed = claim_output_dir(out, "reproduction")
    RunDirectory.create(out / "runs", "triangle", {}).staging.joinpath("run.mcap").write_bytes(b"x")
    claim_output_dir(out / "plan" / "bowl_grasp-mcikrrt", "plan").release()
    write_whole(out / "plan" / "bowl_grasp-mcikrrt" / "plan_trials.csv", "trial\n")
    claim_output_dir(out / "consistency" / "triangle", "consistency").release()
    claim_output_dir(out / "figures" / "ball-game-pinv", "report").release()
    (out / "figures" / "planning_times.png").write_bytes(b"png")
    write_whole(out / "parts.json", "{}")
    write_whole(out / "report.md", "# r\n")
    claimed.release()


def test_clear_empties_a_reproduction_that_holds_only_dualarms_files(tmp_path):
    _reproduction(tmp_path / "out")
    with claim_output_dir(tmp_path / "out", "reproduction") as claimed:
        claimed.clear()
    assert [p.name for p in (tmp_path / "out").iterdir()] == [MARKER]


@pytest.mark.parametrize(
    "where", ["runs/triangle/notes.txt", "figures/ball-game-pinv/mine.md", "plan/my.csv", "consistency/triangle/runs"]
)
def test_clear_deletes_nothing_when_a_foreign_entry_is_deep_inside(tmp_path, where):
    out = tmp_path / "out"
    _reproduction(out)
    (out / where).parent.mkdir(parents=True, exist_ok=True)
    (out / where).write_text("mine\n")
    before = tree(out)
    with (
        pytest.raises(OutputError, match=f"holds '{where}'"),
        claim_output_dir(out, "reproduction") as claimed,
    ):  # refused by the claim (in the recordings: by clear)
        claimed.clear()
    assert tree(out) == before


def test_clear_refuses_while_a_run_adds_to_its_recordings(tmp_path):
    out = tmp_path / "out"
    _reproduction(out)
    running = RunDirectory.create(out / "runs", "circle", {})
    before = tree(out)
    with (
        claim_output_dir(out, "reproduction") as claimed,
        pytest.raises(OutputError, match="runs: in use by another dualarm process"),
    ):
        claimed.clear()
    assert tree(out) == before
    del running


def test_write_whole_is_whole_or_nothing(tmp_path, monkeypatch):
    target = tmp_path / "table.csv"
    target.write_text("old\n")

    def interrupted(src, dst):
        raise KeyboardInterrupt

    monkeypatch.setattr(run_dir.os, "replace", interrupted)
    with pytest.raises(KeyboardInterrupt):
        write_whole(target, "new\n")
    monkeypatch.undo()
    assert target.read_text() == "old\n" and [p.name for p in tmp_path.iterdir()] == ["table.csv"]

    with pytest.raises(OutputError, match=f"{target}: exists and is not a directory"):
        write_whole(target / "x.csv", "x")
    with pytest.raises(
        OutputError, match=f"{target}/x: cannot create the directory \\({os.strerror(errno.ENOTDIR)}\\)"
    ):
        write_whole(target / "x" / "y.csv", "x")
    assert [p.name for p in tmp_path.iterdir()] == ["table.csv"]
