"""The reproduction's runner: its output directory is claimed, never a user's, and its workers are watched."""

import json
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
    RunDirectory.create(out / "runs", "triangle", {}).staging.joinpath("run.mcap").write_bytes(
        b"half"
    )  # stopped half-way
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


@pytest.mark.integration
def test_a_part_that_takes_its_workers_down_is_failed_and_the_others_go_on(tmp_path, monkeypatch):
    """On a scheduler and two `dask worker`s started apart: each worker that starts ball-game-pinv is killed (SIGKILL)
    as the part reports progress; Dask retries it on another until its allowed failures are spent, then it is a failed
    part (KilledWorker); table-i completes.

    The scheduler allows one failure (Dask's default is 3): one retry shows the retry, and each
    further one costs a worker's restart.
    """
    from distributed import Client

    from dualarm.bench.study import loopback_cluster

    out = tmp_path / "repro"
    claimed = prepare(out)
    killed: list[int] = []
    monkeypatch.setenv("DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES", "1")  # read by the scheduler's process
    with loopback_cluster(2, tmp_path) as address, Client(address) as client:

        def on_progress(name: str, fraction: float, text: str) -> None:
            if name != "ball-game-pinv" or fraction >= 1.0:
                return
            running = [
                w for w, keys in client.processing().items() if any("reproduce-ball-game-pinv" in str(k) for k in keys)
            ]
            for pid in client.run(
                os.getpid, workers=running, on_error="ignore"
            ).values():  # a worker already killed may still be listed
                if pid not in killed:
                    os.kill(pid, signal.SIGKILL)
                    killed.append(pid)

        results = {r.name: r for r in run_parts(out, ["ball-game-pinv", "table-i"], 2, on_progress, scheduler=address)}
    claimed.release()
    assert len(killed) >= 2  # retried on another worker at least once
    assert results["ball-game-pinv"].status == "failed" and results["ball-game-pinv"].error.startswith(
        "KilledWorker: "
    ), results["ball-game-pinv"]
    assert results["table-i"].status == "complete"
    index = json.loads((out / PARTS_FILE).read_text())
    assert {p["name"]: p["status"] for p in index["parts"]} == {"ball-game-pinv": "failed", "table-i": "complete"}
