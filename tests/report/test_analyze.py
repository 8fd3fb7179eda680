"""``dualarm analyze BAG``: a round trip through a bag as a real robot would record it.

Each run is executed in PyBullet, exported with ``dualarm export --ros2``, and its exported ``/joint_states`` written
again (rosbags' writer, ROS 2 Humble types) with Gaussian noise of 1e-4 rad on every position and the stamps moved by
up to 1 ms, seeded: what an encoder and a driver's clock add. ``dualarm consistency`` judges the same task and method
without any of it. The facts the analysis must meet are computed without it: the noise injected, the execution's own
repetition boundaries (run.mcap), and consistency's joint deviation.
"""

import csv
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from dualarm.record.readback import read_run
from tests.helpers import REPO, dualarm_subprocess

pytestmark = pytest.mark.integration
NOISE_RAD = 1e-4
JITTER_S = 1e-3
THRESHOLD_RAD = 0.01  # analyze's default, the study's [inconsistent] joint_deviation_rad
#: name -> (task, method, storage of the noisy bag); MC-Inverse repeats itself, TRAC-IK does not on the circle
CASES = {
    "mc-inverse": ("triangle", "mc-inverse", StoragePlugin.SQLITE3),
    "trac-ik": ("circle", "trac-ik", StoragePlugin.MCAP),
}


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open() as f:
        return list(csv.DictReader(f))


def noisy_bag(
    exported: Path, target: Path, storage: StoragePlugin, seed: int, rename: dict[str, str] | None = None
) -> None:
    """``exported``'s /joint_states with NOISE_RAD of noise and JITTER_S of stamp jitter, as the bag ``target``."""
    store = get_typestore(Stores.ROS2_HUMBLE)
    rng = np.random.default_rng(seed)
    with AnyReader([exported], default_typestore=store) as reader:
        states = [c for c in reader.connections if c.topic == "/joint_states"]
        messages = [(log, reader.deserialize(raw, c.msgtype)) for c, log, raw in reader.messages(connections=states)]
    types = store.types
    with Writer(target, version=8, storage_plugin=storage) as writer:
        connection = writer.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=store)
        for log, message in messages:
            stamp = 1_700_000_000 + message.header.stamp.sec + message.header.stamp.nanosec * 1e-9
            ns = int(round((stamp + rng.uniform(-JITTER_S, JITTER_S)) * 1e9))
            noisy = types["sensor_msgs/msg/JointState"](
                header=types["std_msgs/msg/Header"](
                    stamp=types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9), frame_id=""
                ),
                name=[(rename or {}).get(n, n) for n in message.name],
                position=message.position + rng.normal(0.0, NOISE_RAD, len(message.position)),
                velocity=np.empty(0),
                effort=np.empty(0),
            )
            writer.write(
                connection, 1_700_000_000 * 10**9 + log, store.serialize_cdr(noisy, "sensor_msgs/msg/JointState")
            )


@pytest.fixture(scope="module")
def trips(tmp_path_factory) -> dict[str, dict]:
    """Per case: the executed run, its noisy bag, analyze's outcome, and consistency's on the same task and method."""
    out = tmp_path_factory.mktemp("analyze")
    trips = {}
    for seed, (case, (task, method, storage)) in enumerate(CASES.items()):
        task_file = str(REPO / "tasks" / f"{task}.toml")
        ran = dualarm_subprocess(["run", task_file, "--ik", method, "--reps", "3", "--out", str(out / "runs")])
        assert ran.returncode in (0, 3), ran.stderr  # TRAC-IK's circle misses a few samples: violated, executed
        run = Path(ran.stdout.split()[-1])
        exported = out / f"{case}-export"
        assert dualarm_subprocess(["export", str(run), "--ros2", str(exported)]).returncode == 0
        bag = out / f"{case}-noisy"
        noisy_bag(exported, bag, storage, seed)
        analysis = out / f"{case}-analysis"
        done = dualarm_subprocess(
            ["analyze", str(bag), "--robot", "humanoid", "--task", task_file, "--out", str(analysis)]
        )
        judged = out / f"{case}-consistency"
        consistency = dualarm_subprocess(
            ["consistency", task_file, "--methods", method, "--reps", "3", "--out", str(judged)]
        )
        assert consistency.returncode in (0, 3), consistency.stderr
        trips[case] = {
            "run": run,
            "exported": exported,
            "done": done,
            "metrics": _rows(analysis / "analysis.csv")[0],
            "repetitions": _rows(analysis / "repetitions.csv"),
            "consistency": _rows(judged / "consistency.csv")[0],
            "analysis": analysis,
        }
    return trips


@pytest.mark.parametrize("case", CASES)
def test_analyze_gives_consistencys_verdict_on_the_noisy_bag_of_the_executed_run(trips, case):
    """MC-Inverse consistent, TRAC-IK not, as ``dualarm consistency`` finds without noise; exit 0 only when consistent
    (and within the limits)."""
    trip = trips[case]
    simulated = float(trip["consistency"]["rep_joint_deviation_max_rad"])
    assert (simulated > THRESHOLD_RAD) == (case == "trac-ik"), simulated
    assert trip["metrics"]["verdict"] == ("inconsistent" if simulated > THRESHOLD_RAD else "consistent")
    assert trip["done"].returncode == (3 if case == "trac-ik" else 0), trip["done"].stderr
    assert (trip["analysis"] / "joints_left.png").stat().st_size > 10_000


@pytest.mark.parametrize("case", CASES)
def test_analyze_estimates_the_noise_it_was_given_and_reports_no_more_than_it_as_deviation(trips, case):
    """The noise sigma estimated from the data is the injected 1e-4 rad within 10 %; on MC-Inverse's bag the largest
    deviation between repetitions is within the noise floor analyze derives from it (nothing beyond noise)."""
    metrics = trips[case]["metrics"]
    assert float(metrics["noise_rad"]) == pytest.approx(NOISE_RAD, rel=0.1)
    if case == "mc-inverse":
        assert float(metrics["rep_joint_deviation_max_rad"]) <= float(metrics["noise_floor_rad"]), metrics
        assert float(metrics["rep_beyond_noise_max_rad"]) == 0.0
    else:
        assert float(metrics["rep_beyond_noise_max_rad"]) > THRESHOLD_RAD


@pytest.mark.parametrize("case", CASES)
def test_repetitions_are_cut_where_the_execution_began_each(trips, case):
    """Cut where the hands pass the task's start pose (forward kinematics of the noisy positions): three repetitions,
    each starting within 50 ms of where the execute stage's own repetition index changes in run.mcap (where the hands
    rest at the start pose between repetitions, any sample of the rest is a pass: 25 ms apart on one TRAC-IK circle)."""
    executed = read_run(trips[case]["run"])["/execute/sample"]
    t, rep = executed["t"].to_numpy(), executed["rep"].to_numpy()
    begins = [t[rep == r][0] for r in np.unique(rep)[1:]]
    cut = trips[case]["repetitions"]
    assert len(cut) == 3
    offset = t[0] - 0.0  # the bag's first sample is the execution's first
    assert np.allclose([float(r["start_s"]) + offset for r in cut[1:]], begins, atol=0.05)


def test_a_bag_without_the_robots_joint_names_is_refused_and_joint_map_reads_it(trips, tmp_path):
    """A driver naming the joints j0, j1, ...: refused in one line naming the map option; with --joint-map the same
    verdict as the bag with the URDF's names."""
    exported = trips["mc-inverse"]["exported"]
    with AnyReader([exported], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        connection = next(c for c in reader.connections if c.topic == "/joint_states")
        names = next(reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages([connection])).name
    rename = {n: f"j{k}" for k, n in enumerate(names)}
    noisy_bag(exported, tmp_path / "renamed", StoragePlugin.MCAP, 5, rename)
    task = str(REPO / "tasks" / "triangle.toml")
    refused = dualarm_subprocess(["analyze", str(tmp_path / "renamed"), "--robot", "humanoid", "--task", task])
    assert refused.returncode == 2 and refused.stderr.count("\n") == 1 and "--joint-map" in refused.stderr
    mapping = ",".join(f"{bag}={urdf}" for urdf, bag in rename.items())
    args = ["analyze", str(tmp_path / "renamed"), "--robot", "humanoid", "--task", task, "--joint-map", mapping]
    done = dualarm_subprocess([*args, "--out", str(tmp_path / "out")])
    assert done.returncode == 0, done.stderr
    assert _rows(tmp_path / "out" / "analysis.csv")[0]["verdict"] == "consistent"


@pytest.mark.parametrize(
    "args, says",
    [
        (["/etc/hostname"], "not a readable ROS 2 bag"),
        (["{bag}", "--topic", "/nope"], "no topic /nope"),
        (["{bag}", "--reps", "5"], "found 3 repetitions"),
        (["{bag}", "--joint-map", "oops"], "is not BAG_NAME=URDF_NAME"),
        (["{bag}", "--reps", "3", "--period", "2"], "not both"),
    ],
)
def test_bad_input_is_one_line_exit_2_and_writes_nothing(trips, tmp_path, args, says):
    bag = str(trips["mc-inverse"]["exported"])
    out = tmp_path / "out"
    done = dualarm_subprocess(["analyze", *(a.format(bag=bag) for a in args), "--robot", "humanoid", "--out", str(out)])
    assert done.returncode == 2 and done.stderr.count("\n") == 1 and says in done.stderr, done.stderr
    assert not out.exists() or not any(out.iterdir())


def test_a_cut_empty_or_ros1_bag_is_one_line_exit_2(trips, tmp_path):
    """The noisy MCAP cut in half (a recorder killed), a directory without metadata.yaml, a ROS 1 bag."""
    (mcap,) = (trips["trac-ik"]["run"].parent.parent.parent / "trac-ik-noisy").glob("*.mcap")
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(mcap.read_bytes()[: mcap.stat().st_size // 2])
    (tmp_path / "empty").mkdir()
    ros1 = tmp_path / "ros1.bag"
    store = get_typestore(Stores.ROS1_NOETIC)
    with Writer1(ros1) as writer:
        connection = writer.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=store)
        types = store.types
        state = types["sensor_msgs/msg/JointState"](
            header=types["std_msgs/msg/Header"](
                seq=0, stamp=types["builtin_interfaces/msg/Time"](sec=1, nanosec=0), frame_id=""
            ),
            name=["left_elbow"],
            position=np.zeros(1),
            velocity=np.empty(0),
            effort=np.empty(0),
        )
        writer.write(connection, 1, store.serialize_ros1(state, "sensor_msgs/msg/JointState"))
    for bag, says in ((cut, "not a readable ROS 2 bag"), (tmp_path / "empty", "metadata"), (ros1, "a ROS 1 bag")):
        done = dualarm_subprocess(["analyze", str(bag), "--robot", "humanoid", "--out", str(tmp_path / "out")])
        assert done.returncode == 2 and done.stderr.count("\n") == 1 and says in done.stderr, done.stderr
    assert not (tmp_path / "out").exists()
