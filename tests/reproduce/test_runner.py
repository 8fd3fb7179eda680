"""The reproduction's runner: its output directory is claimed, never a user's, and its workers are watched."""

import json
import multiprocessing
import os
import signal

import pytest

from dualarm.errors import DualarmError, OutputError
from dualarm.record.run_dir import MARKER, RunDirectory, claim_output_dir
from dualarm.reproduce.runner import PARTS_FILE, parts_named, prepare, run_parts
from tests.record.test_run_dir import tree


def test_a_users_directory_is_refused_and_nothing_is_deleted(tmp_path):
    """The case of issue 16: report.md (the user's notes), precious.txt and sub/data.csv."""
    mine = tmp_path / "mine"
    (mine / "sub").mkdir(parents=True)
    (mine / "report.md").write_text("# my notes\n")
    (mine / "precious.txt").write_text("keep me\n")
    (mine / "sub" / "data.csv").write_text("a,b\n1,2\n")
    before = tree(mine)
    with pytest.raises(OutputError, match="not a reproduction directory made by dualarm"):
        prepare(mine)
    assert tree(mine) == before


def test_an_earlier_reproduction_is_emptied_and_locked_while_claimed(tmp_path):
    out = tmp_path / "repro"
    prepare(out).release()
    RunDirectory.create(out / "runs", "triangle", {}).staging.joinpath("run.mcap").write_bytes(b"half")  # stopped half-way
    (out / PARTS_FILE).write_text("{}")
    claimed = prepare(out)
    assert [p.name for p in out.iterdir()] == [MARKER]
    with pytest.raises(OutputError, match="in use by another dualarm process"):
        prepare(out)
    claimed.release()


def test_a_plan_directory_is_not_a_reproduction(tmp_path):
    claim_output_dir(tmp_path / "p", "plan").release()
    with pytest.raises(OutputError, match="its .dualarm marker says 'plan'"):
        prepare(tmp_path / "p")


def test_an_unknown_part_is_quoted_short():
    with pytest.raises(DualarmError) as caught:
        parts_named(["x" * 10_000])
    message = str(caught.value)
    assert len(message) < 250 and "x" * 38 + "..." in message and "table-i" in message


def test_a_worker_that_dies_is_a_failed_part_and_the_others_go_on(tmp_path):
    """ball-game-pinv's worker is killed (SIGKILL) as it starts its run; table-i, in another worker, completes."""
    out = tmp_path / "repro"
    claimed = prepare(out)
    killed: list[int] = []

    def on_progress(name: str, fraction: float, text: str) -> None:
        if name == "ball-game-pinv" and fraction < 1.0 and not killed:
            (worker,) = [p for p in multiprocessing.active_children() if p.name == "dualarm reproduce ball-game-pinv"]
            os.kill(worker.pid, signal.SIGKILL)
            killed.append(worker.pid)

    results = {r.name: r for r in run_parts(out, ["ball-game-pinv", "table-i"], 2, on_progress)}
    claimed.release()
    assert killed
    assert results["ball-game-pinv"].status == "failed" and results["ball-game-pinv"].error == f"its worker process ended with exit code {-signal.SIGKILL}"
    assert results["table-i"].status == "complete"
    index = json.loads((out / PARTS_FILE).read_text())
    assert {p["name"]: p["status"] for p in index["parts"]} == {"ball-game-pinv": "failed", "table-i": "complete"}
    assert not multiprocessing.active_children()
