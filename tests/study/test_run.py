"""Running a study on Dask (dualarm.study.run): a small study on a LocalCluster and on a separately started scheduler
and workers, resume, a killed worker, a failing trial, and the refusals.

Every row is checked against the same trial run again alone, in this process, from the task file the study wrote
(dualarm.run_task): the study's rows are the pipeline's own numbers, wherever they ran.
"""

import os
import re
import subprocess
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path

import pandas as pd
import pytest

from dualarm.bench.study import loopback_cluster
from dualarm.cluster import connect
from dualarm.errors import DualarmError, OutputError, RecordingError, StageError, TaskFileError, UnreachablePoseError
from dualarm.run import run_task
from dualarm.study.run import PARTS, RESULTS, TASKS, VARYING, read_study, run_study, run_trial
from dualarm.study.spec import study_from_toml
from dualarm.study.trials import reachable_trial, trial, within_reach
from dualarm.tasks.load import load_task
from tests.helpers import dualarm_subprocess

REPO = Path(__file__).resolve().parents[2]
SPEC = """
name = "small"
methods = ["pinv", "dls-svd", "pybullet"]
trials = 4
repetitions = [2, 3]
period_s = [1.0, 1.5]
control_period_s = 0.02
"""


def _same(a: pd.DataFrame, b: pd.DataFrame) -> None:
    """Bit for bit, but for the columns that differ from run to run (VARYING)."""
    keep = [c for c in a.columns if c not in VARYING]
    pd.testing.assert_frame_equal(a[keep].reset_index(drop=True), b[keep].reset_index(drop=True), check_exact=True)


@pytest.fixture(scope="module")
def local(tmp_path_factory) -> tuple[Path, pd.DataFrame]:
    """The small study on a LocalCluster of 2 workers."""
    out = tmp_path_factory.mktemp("study") / "small"
    result = run_study(study_from_toml(SPEC), REPO, out, workers=2)
    assert result.ran == 4 and result.workers == 2
    return out, result.results


@pytest.mark.integration
def test_a_study_on_a_local_cluster_writes_a_row_per_trial_and_method(local):
    out, rows = local
    assert len(rows) == 4 * 3 and set(rows["worker"]) <= {"0", "1"}
    pd.testing.assert_frame_equal(pd.read_parquet(out / RESULTS), rows)
    pd.testing.assert_frame_equal(read_study(out), rows)
    assert sorted(p.name for p in (out / PARTS).iterdir()) == [f"trial-{i:06d}.parquet" for i in range(4)]
    assert (rows["reachable"]).all()


@pytest.mark.integration
def test_each_row_is_the_trial_run_alone_from_its_task_file(local):
    out, rows = local
    for _, row in rows.iterrows():
        task = load_task(out / TASKS / f"small-{row['trial']:06d}.toml")
        try:
            alone = run_task(task, row["method"], stages=("path", "ik"))
        except StageError as exc:
            assert row["status"] == "failed" and row["error"] == str(exc)
            continue
        for name, value in alone.metrics.items():
            if name not in VARYING:
                assert row[name] == value, (row["trial"], row["method"], name)
        failed = alone.metrics["ik.failed_reps"] > 0
        assert row["failed"] == failed
        assert row["inconsistent"] == (alone.metrics["ik.rep_joint_deviation_max_rad"] > 0.01 or failed)


@pytest.mark.integration
def test_resume_runs_only_the_trials_missing(local, tmp_path):
    out, rows = local
    copy = tmp_path / "small"
    subprocess.run(["cp", "-r", str(out), str(copy)], check=True)
    for i in (1, 3):
        (copy / PARTS / f"trial-{i:06d}.parquet").unlink()
    with pytest.raises(OutputError, match="--resume"):
        run_study(study_from_toml(SPEC), REPO, copy, workers=1)
    again = run_study(study_from_toml(SPEC), REPO, copy, workers=1, resume=True)
    assert again.ran == 2
    _same(again.results, rows)


@pytest.mark.integration
@pytest.mark.parametrize(
    ("name", "source", "why"),
    [
        ("trial-000001 (copy).parquet", 1, "its name is no trial-NNNNNN.parquet"),  # a file manager's copy
        ("trial-000009.parquet", 1, "its name is no trial-NNNNNN.parquet of trials 0 to 3"),  # no such trial
        ("trial-000002.parquet", 1, "rows of another study or trial than 2"),  # trial 1's rows under 2's name
    ],
)
def test_resume_trusts_only_parts_that_are_the_specs_trials(local, tmp_path, name, source, why):
    """A stale or copied part in parts/ (it was read and its rows doubled in trials.parquet, exit 0): refused in one
    line naming it, and trials.parquet is left as it was."""
    out, _ = local
    copy = tmp_path / "small"
    subprocess.run(["cp", "-r", str(out), str(copy)], check=True)
    (copy / PARTS / "trial-000002.parquet").unlink()
    (copy / PARTS / name).write_bytes((out / PARTS / f"trial-{source:06d}.parquet").read_bytes())
    table = (copy / RESULTS).read_bytes()
    with pytest.raises(RecordingError, match=re.escape(why)) as raised:
        run_study(study_from_toml(SPEC), REPO, copy, workers=1, resume=True)
    assert f"parts/{name}: not a part of study" in str(raised.value) and "\n" not in str(raised.value)
    assert (copy / RESULTS).read_bytes() == table


@pytest.mark.integration
def test_another_study_into_the_same_directory_is_refused(local):
    out, _ = local
    other = study_from_toml(SPEC.replace("trials = 4", "trials = 5"))
    with pytest.raises(OutputError, match="holds study 'small' of another spec"):
        run_study(other, REPO, out, resume=True)


@pytest.mark.integration
def test_the_cli_refuses_a_bad_spec_in_one_line(tmp_path):
    spec = tmp_path / "bad.toml"
    spec.write_text('name = "s"\ntrials = 10\nrepetitions = [9, 3]\n')
    done = dualarm_subprocess(["study", str(spec), "--out", str(tmp_path / "out")], 120)
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip().count("\n") == 0 and "repetitions: the low end 9 is above the high end 3" in done.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.integration
def test_a_separately_started_scheduler_and_workers_give_the_same_rows(local, tmp_path):
    """A scheduler and two `dask worker` processes on 127.0.0.1, started apart as two nodes would be."""
    _, rows = local
    with loopback_cluster(2, tmp_path) as address:
        result = run_study(study_from_toml(SPEC), REPO, tmp_path / "cluster", scheduler=address)
    assert result.workers == 2 and set(result.results["worker"]) == {"node-a", "node-b"}
    _same(result.results, rows)


@pytest.mark.integration
def test_an_unreachable_scheduler_is_one_line_and_leaves_no_table(tmp_path, monkeypatch):
    monkeypatch.setattr(
        "dualarm.cluster.CONNECT_TIMEOUT_S", 2.0
    )  # Dask retries a refused connection until the timeout (30 s for users)
    with pytest.raises(Exception, match="no Dask scheduler answers there"):
        with connect("tcp://127.0.0.1:9"):
            pass
    with pytest.raises(Exception, match="no Dask scheduler answers there"):
        run_study(study_from_toml(SPEC), REPO, tmp_path / "out", scheduler="tcp://127.0.0.1:9")
    assert not (tmp_path / "out" / RESULTS).exists()


def _server(reply: bytes | None):
    """A TCP server on 127.0.0.1 that accepts and sends ``reply`` after the first bytes, or never answers (None)."""
    import socket

    server = socket.create_server(("127.0.0.1", 0))

    def serve() -> None:
        held = []
        while True:
            connection, _ = server.accept()
            held.append(connection)
            if reply is not None:
                connection.recv(1000)
                connection.sendall(reply)

    threading.Thread(target=serve, daemon=True).start()
    return f"tcp://127.0.0.1:{server.getsockname()[1]}"


@pytest.mark.integration
@pytest.mark.parametrize(
    ("reply", "why"),
    [
        (None, "no Dask scheduler answers there within 3 s"),  # it hung past 420 s
        (b"HTTP/1.1 200 OK\r\nContent-Length: 5\r\n\r\nhello", "something answers there, but not in Dask's protocol"),
    ],
)
def test_a_scheduler_address_that_is_not_dask_is_one_line_within_the_timeout(monkeypatch, reply, why):
    """A server that accepts and never answers (the handshake was not bounded), or an HTTP server (a 74-line
    'Unable to allocate 3.07 EiB'): one line, within the connect timeout."""
    monkeypatch.setattr("dualarm.cluster.CONNECT_TIMEOUT_S", 3.0)
    address = _server(reply)
    start = time.monotonic()
    with pytest.raises(DualarmError, match=re.escape(why)) as raised:
        with connect(address):
            pass
    assert time.monotonic() - start < 10 and "\n" not in str(raised.value)


@pytest.mark.integration
def test_a_killed_worker_has_its_trial_retried_on_another(local, tmp_path):
    """A worker process killed while it runs a trial: the scheduler gives the trial to another, and the rows are the
    same."""
    _, rows = local
    from distributed import Client, LocalCluster

    killed: list[str] = []
    with (
        LocalCluster(n_workers=2, threads_per_worker=1, dashboard_address=None, silence_logs=40) as cluster,
        Client(cluster) as client,
    ):

        def kill_one_busy_worker() -> None:
            for _ in range(600):
                busy = {w: keys for w, keys in client.processing().items() if keys}
                started = [
                    w
                    for w, state in client.run(
                        lambda dask_worker: [t.key for t in dask_worker.state.tasks.values() if t.state == "executing"]
                    ).items()
                    if state
                ]
                if busy and started:
                    pids = client.run(os.getpid)
                    killed.append(started[0])
                    os.kill(pids[started[0]], 9)
                    return
                time.sleep(0.05)

        killer = threading.Thread(target=kill_one_busy_worker)
        killer.start()
        result = run_study(study_from_toml(SPEC), REPO, tmp_path / "killed", scheduler=cluster.scheduler_address)
        killer.join()
    assert killed, "no worker was killed mid-trial"
    assert (result.results["status"] != "error").all()
    _same(result.results, rows)


@pytest.mark.integration
def test_a_method_that_raises_is_its_rows_error_not_a_lost_trial(monkeypatch):
    """A bug in one method (an exception that is not dualarm's) is that row's error, and the other methods still run."""

    def broken(*args, **kwargs):
        raise ZeroDivisionError("a bug")

    from dualarm.ik.velocity import pinv

    monkeypatch.setitem(pinv.METHODS, "pinv", replace(pinv.METHODS["pinv"], solve=broken))
    result = run_trial(study_from_toml(SPEC), str(REPO), 0)
    by_method = {r["method"]: r for r in result.rows}
    assert by_method["pinv"]["status"] == "error" and by_method["pinv"]["error"] == "ZeroDivisionError: a bug"
    assert by_method["pinv"]["failed"] and by_method["pinv"]["inconsistent"]
    assert by_method["dls-svd"]["status"] in ("complete", "violated") and by_method["pybullet"]["status"] in (
        "complete",
        "violated",
    )


def test_a_shape_out_of_reach_fails_mc_inverse_in_its_row_and_is_drawn_again_when_checked():
    """With [centre] reachable = false a shape far out is kept and fails MC-Inverse (a `failed` row, its message); with
    the check, every draw before the one kept is out of reach (the analytic check) and the one kept is within."""
    far = (
        SPEC.replace('["pinv", "dls-svd", "pybullet"]', '["mc-inverse"]')
        + "[centre]\nx = [0.8, 0.9]\ny = [0.0, 0.1]\nz = [-0.2, -0.1]\n"
    )
    unchecked = study_from_toml(far + "reachable = false\n")
    with pytest.raises(UnreachablePoseError, match="cannot reach"):
        reachable_trial(unchecked, 0, REPO)
    row = run_trial(unchecked, str(REPO), 0).rows[0]
    assert (
        row["status"] == "failed"
        and row["failed"]
        and row["inconsistent"]
        and "cannot reach" in row["error"]
        and not row["reachable"]
    )
    near = study_from_toml(far.replace("x = [0.8, 0.9]", "x = [0.1, 0.2]") + "reachable = false\n")
    drawn, task = reachable_trial(near, 0, REPO)
    assert not within_reach(task), "the trial is within reach: move it"
    row = run_trial(near, str(REPO), 0).rows[0]
    assert row["status"] == "failed" and "MC-Inverse" in row["error"]
    checked = study_from_toml(SPEC + "[centre]\nx = [0.35, 0.55]\n")
    draws = [reachable_trial(checked, i, REPO) for i in range(3)]
    assert all(d.features["reachable"] and within_reach(t) for d, t in draws)
    assert any(d.features["draw"] > 0 for d, _ in draws)
    for i, (d, _) in enumerate(draws):
        for earlier in range(d.features["draw"]):
            assert not within_reach(load_task_dict(trial(checked, i, earlier).task))


def load_task_dict(task: dict):
    from dualarm.tasks.load import task_from_dict

    return task_from_dict(task, base_dir=REPO)


@pytest.mark.integration
def test_duckdb_reads_the_table_as_pandas_does(local):
    """The README's query: DuckDB on DIR/trials.parquet, against the same rates from pandas."""
    import duckdb

    out, rows = local
    query = (
        'select method, avg(inconsistent::int) as p, median("ik.rep_joint_deviation_max_rad") as deviation'
        f" from '{out / RESULTS}' group by method order by method"
    )
    got = duckdb.sql(query).df().set_index("method")
    expected = rows.groupby("method").agg(
        p=("inconsistent", "mean"), deviation=("ik.rep_joint_deviation_max_rad", "median")
    )
    pd.testing.assert_frame_equal(got, expected, check_names=False, check_index_type=False)


def test_a_robot_the_reach_check_cannot_use_is_refused_before_anything_is_written(tmp_path):
    spec = study_from_toml(SPEC.replace('name = "small"', 'name = "small"\nrobot = "humanoid_offset"'))
    with pytest.raises(
        TaskFileError, match=r"centre.reachable: the reach check needs S-R-S arms .*set \[centre\] reachable = false"
    ):
        run_study(spec, REPO, tmp_path / "out")
    assert not (tmp_path / "out").exists()


@pytest.mark.integration
def test_a_worker_builds_its_solvers_once_not_per_trial(monkeypatch):
    """Trials run one after another in one process, as on a worker: after the first, the later trials load the robot
    into PyBullet, build DLS's Function, the hand stacks and IPOPT's start problem no more (counted at the libraries'
    calls)."""
    import casadi

    from dualarm.ik.pose_level import baselines, dls
    from dualarm.ik.velocity import stack

    spec = study_from_toml(SPEC.replace('"pybullet"]', '"pybullet", "tvgdd"]') + 'hands = ["left"]\n')
    calls = {"pybullet": 0, "dls": 0, "nlpsol": 0}

    def counted(name, function):
        def call(*args, **kwargs):
            calls[name] += 1
            return function(*args, **kwargs)

        return call

    monkeypatch.setattr(baselines, "load_pybullet_robot", counted("pybullet", baselines.load_pybullet_robot))
    monkeypatch.setattr(dls.DlsSolver, "_build", counted("dls", dls.DlsSolver._build))
    monkeypatch.setattr(casadi, "nlpsol", counted("nlpsol", casadi.nlpsol))
    for cache in (dls._solver, stack._stack):
        cache.cache_clear()
    run_trial(spec, str(REPO), 0)
    first, stacks = dict(calls), stack._stack.cache_info().misses
    assert first["pybullet"] == first["dls"] == 1 and first["nlpsol"] >= 1 and stacks >= 1
    for index in (1, 2):
        run_trial(spec, str(REPO), index)
    assert calls == first and stack._stack.cache_info().misses == stacks


@pytest.mark.parametrize("hands", ['["both"]', '["right", "left"]'])
def test_a_hand_the_robot_does_not_have_is_refused_before_anything_is_written(tmp_path, hands):
    """The Panda drives one hand, `right`: a carry (both) or a left-hand trial is refused in one line, naming the
    key."""
    spec = study_from_toml(SPEC.replace('name = "small"', f'name = "small"\nrobot = "panda"\nhands = {hands}'))
    with pytest.raises(TaskFileError, match=r"^hands: robot 'panda' has no left hand \(hands: right\)$"):
        run_study(spec, REPO, tmp_path / "out")
    assert not (tmp_path / "out").exists()


def _affinity() -> list[list[int]]:
    """The cores of every thread of this process, as the OS has them."""
    return [sorted(os.sched_getaffinity(int(t))) for t in os.listdir("/proc/self/task")]


@pytest.mark.integration
@pytest.mark.skipif(
    not hasattr(os, "sched_getaffinity") or len(os.sched_getaffinity(0)) < 2 or not Path("/proc/self/task").exists(),
    reason="needs 2 cores and Linux's per-thread affinity",
)
def test_local_workers_are_each_pinned_to_a_core_of_their_own():
    """A LocalCluster of 2 workers: every thread of worker i, and a task's thread, runs on core i only (read back from
    the OS); the client's process is left alone."""
    cores = sorted(os.sched_getaffinity(0))[:2]
    with connect(workers=2) as client:
        threads = client.run(_affinity)
        tasks = [
            client.submit(lambda: sorted(os.sched_getaffinity(0)), pure=False, workers=[w]).result() for w in threads
        ]
        names = {w: info["name"] for w, info in client.scheduler_info(n_workers=-1)["workers"].items()}
    assert {names[w]: {tuple(a) for a in affinity} for w, affinity in threads.items()} == {
        0: {(cores[0],)},
        1: {(cores[1],)},
    }
    assert sorted(tasks) == [[cores[0]], [cores[1]]]
    assert len(os.sched_getaffinity(0)) >= 2


@pytest.mark.integration
def test_every_server_of_a_local_cluster_listens_on_this_machine_only():
    """The scheduler, its HTTP routes (the dashboard), the worker and its nanny: every listening socket of this process
    and its children, read back from the OS (psutil), is bound to 127.0.0.1 (the dashboard was on every interface)."""
    import psutil

    with connect(workers=1):
        processes = [psutil.Process(), *psutil.Process().children(recursive=True)]
        bound = {
            c.laddr.ip for p in processes for c in p.net_connections(kind="inet") if c.status == psutil.CONN_LISTEN
        }
    assert bound == {"127.0.0.1"}


@pytest.mark.integration
def test_a_worker_that_dies_while_the_local_cluster_starts_is_one_line(tmp_path):
    """A worker process that ends as it starts (a Dask preload script that exits, as a kill at that moment does):
    one line saying the cluster did not start (a RuntimeError 'Nanny failed to start' traceback)."""
    import dask

    (tmp_path / "dies.py").write_text("import os\nos._exit(3)\n")
    with dask.config.set({"distributed.worker.preload": [str(tmp_path / "dies.py")]}):
        with pytest.raises(DualarmError, match="the local Dask cluster did not start") as raised:
            with connect(workers=1):
                pass
    assert "\n" not in str(raised.value)


@pytest.mark.integration
def test_ctrl_c_while_the_local_cluster_starts_leaves_no_traceback_at_exit():
    """SIGINT as the worker's nanny starts, in a process of its own: KeyboardInterrupt comes out of connect() and the
    process exits without output on stderr (Dask's exit hook printed a 28-line 'AssertionError: Status.init' traceback
    closing the half-started cluster)."""
    script = """
import os, signal
import distributed.nanny
start = distributed.nanny.Nanny.start_unsafe
async def interrupted(self):
    os.kill(os.getpid(), signal.SIGINT)
    return await start(self)
distributed.nanny.Nanny.start_unsafe = interrupted
from dualarm.cluster import connect
try:
    with connect(workers=1):
        print("started")
except KeyboardInterrupt:
    print("interrupted")
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert (done.returncode, done.stdout, done.stderr) == (0, "interrupted\n", "")


@pytest.mark.integration
def test_trials_are_submitted_a_few_per_worker_at_a_time(tmp_path, monkeypatch):
    """12 trials on one worker: never more than IN_FLIGHT_PER_WORKER submitted and unfinished (every trial was
    submitted first: a million took 60 s before the first showed), and every trial has its rows."""
    from distributed import Client

    from dualarm.study.run import IN_FLIGHT_PER_WORKER

    submitted, in_flight = [], []
    submit = Client.submit

    def counting(self, *args, **kwargs):
        submitted.append(args[3])
        return submit(self, *args, **kwargs)

    monkeypatch.setattr(Client, "submit", counting)
    spec = study_from_toml(SPEC.replace("trials = 4", "trials = 12").replace('"pinv", "dls-svd", "pybullet"', '"pinv"'))
    done = run_study(
        spec, REPO, tmp_path / "out", workers=1, progress=lambda n, *_: in_flight.append(len(submitted) - n)
    )
    assert sorted(submitted) == list(range(12)) and sorted(done.results["trial"]) == list(range(12))
    assert max(in_flight) <= IN_FLIGHT_PER_WORKER
