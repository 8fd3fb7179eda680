"""``dualarm export RUN --ros2 DIR --csv FILE``: read back with the ROS 2 tools' own libraries, not ours.

The bag is opened with rosbags' rosbag2 reader (every message deserialised with its ROS 2 Humble types) and its MCAP
file with the mcap reader and mcap-ros2-support's decoder; the trajectory, the joint states and the frames are compared
with the run's own ``run.mcap`` read with the mcap reader (JSON and protobuf), to 1e-9.
"""

import json

import numpy as np
import pandas as pd
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoder
from mcap_ros2.decoder import DecoderFactory as Ros2Decoder

from tests.helpers import dualarm_subprocess

pytestmark = pytest.mark.integration
RUN = "carry_box"
TOPICS = {
    "/joint_trajectory": "trajectory_msgs/msg/JointTrajectory",
    "/joint_states": "sensor_msgs/msg/JointState",
    "/tf": "tf2_msgs/msg/TFMessage",
    "/tf_static": "tf2_msgs/msg/TFMessage",
    "/robot_description": "std_msgs/msg/String",
}


@pytest.fixture(scope="module")
def exported(shipped_runs, tmp_path_factory):
    """The shipped carry_box run, exported: (run directory, bag directory, CSV file)."""
    out = tmp_path_factory.mktemp("export")
    run = shipped_runs[RUN]
    done = dualarm_subprocess(["export", str(run), "--ros2", str(out / "bag"), "--csv", str(out / "motion.csv")])
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == [str(out / "bag"), str(out / "motion.csv")]
    return run, out / "bag", out / "motion.csv"


def _samples(run, topic: str) -> list[dict]:
    with (run / "run.mcap").open("rb") as f:
        return [json.loads(m.data) for _, _, m in make_reader(f).iter_messages(topics=[topic])]


def test_rosbags_reads_every_message_of_the_bag(exported):
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    _, bag, _ = exported
    store = get_typestore(Stores.ROS2_HUMBLE)
    with Reader(bag) as reader:
        assert {c.topic: c.msgtype for c in reader.connections} == TOPICS
        counts = {topic: 0 for topic in TOPICS}
        for connection, _, raw in reader.messages():
            store.deserialize_cdr(raw, connection.msgtype)
            counts[connection.topic] += 1
        latched = {
            c.topic
            for c in reader.connections
            if any(q.durability.name == "TRANSIENT_LOCAL" for q in c.ext.offered_qos_profiles)
        }
    assert counts["/joint_trajectory"] == counts["/robot_description"] == counts["/tf_static"] == 1
    assert counts["/joint_states"] > 100 and counts["/tf"] > 10
    assert latched == {"/robot_description", "/tf_static"}


def test_the_trajectory_and_joint_states_are_the_runs_to_1e_9(exported):
    """Decoded by mcap-ros2-support from the bag's MCAP file: names, times and positions as the run recorded them."""
    run, bag, _ = exported
    (mcap_file,) = bag.glob("*.mcap")
    with mcap_file.open("rb") as f:
        decoded = {
            topic: [
                (m.log_time, d)
                for _, _, m, d in make_reader(f, decoder_factories=[Ros2Decoder()]).iter_decoded_messages(
                    topics=[topic]
                )
            ]
            for topic in ("/joint_trajectory", "/joint_states")
            if not f.seek(0)
        }
    ((_, trajectory),) = decoded["/joint_trajectory"]
    smooth = _samples(run, "/smooth/sample")
    names = list(smooth[0]["position"])
    assert list(trajectory.joint_names) == names
    assert len(trajectory.points) == len(smooth)
    for point, sample in zip(trajectory.points, smooth, strict=True):
        t = point.time_from_start.sec + point.time_from_start.nanosec * 1e-9
        assert abs(t - sample["t"]) <= 1e-9
        assert np.abs(np.subtract(point.positions, [sample["position"][n] for n in names])).max() <= 1e-9
        assert np.abs(np.subtract(point.velocities, [sample["velocity"][n] for n in names])).max() <= 1e-9
    executed = _samples(run, "/execute/sample")
    assert len(decoded["/joint_states"]) == len(executed)
    for (log_time, state), sample in zip(decoded["/joint_states"], executed, strict=True):
        assert list(state.name) == list(sample["position"])
        assert abs(state.header.stamp.sec + state.header.stamp.nanosec * 1e-9 - sample["t"]) <= 1e-9
        assert abs(log_time * 1e-9 - sample["t"]) <= 1e-9
        assert np.abs(np.subtract(state.position, list(sample["position"].values()))).max() <= 1e-9


def test_the_frames_are_the_runs_split_into_moving_and_static(exported):
    """Every transform of the run's /tf (protobuf, read with the mcap reader) is in the bag's /tf at its time, or, when
    it never changes, once in /tf_static."""
    run, bag, _ = exported
    with (run / "run.mcap").open("rb") as f:
        recorded = [
            (m.log_time, tr)
            for _, _, m, d in make_reader(f, decoder_factories=[ProtobufDecoder()]).iter_decoded_messages(
                topics=["/tf"]
            )
            for tr in d.transforms
        ]
    (mcap_file,) = bag.glob("*.mcap")
    exported_tf = {}
    with mcap_file.open("rb") as f:
        for _, channel, m, d in make_reader(f, decoder_factories=[Ros2Decoder()]).iter_decoded_messages(
            topics=["/tf", "/tf_static"]
        ):
            for tr in d.transforms:
                key = (channel.topic == "/tf_static", tr.header.frame_id, tr.child_frame_id)
                exported_tf.setdefault(key, {})[0 if key[0] else m.log_time] = tr.transform
    static = {(p, c) for s, p, c in exported_tf if s}
    assert static and any(not s for s, _, _ in exported_tf)
    for log_time, tr in recorded:
        pair = (tr.parent_frame_id, tr.child_frame_id)
        got = exported_tf[(True, *pair)][0] if pair in static else exported_tf[(False, *pair)][log_time]
        a, b = (_seven(x) for x in (tr, got))
        assert np.abs(np.subtract(a, b)).max() <= 1e-9, pair


def _seven(transform) -> list[float]:
    """A transform's translation and rotation quaternion (x, y, z, qx, qy, qz, qw), of either message kind."""
    return [getattr(transform.translation, k) for k in "xyz"] + [getattr(transform.rotation, k) for k in "xyzw"]


def test_the_csv_holds_the_trajectory_in_si_units(exported):
    run, _, csv = exported
    table = pd.read_csv(csv)
    smooth = _samples(run, "/smooth/sample")
    names = list(smooth[0]["position"])
    assert list(table.columns) == ["t_s", *[f"{n}_rad" for n in names]]
    assert np.abs(table["t_s"].to_numpy() - [s["t"] for s in smooth]).max() <= 1e-9
    expected = np.array([[s["position"][n] for n in names] for s in smooth])
    assert np.abs(table.iloc[:, 1:].to_numpy() - expected).max() <= 1e-9


def test_export_refuses_in_one_line(exported, other_runs, tmp_path):
    """An existing target, a run recorded up to the IK (no timed trajectory), no output asked: one line, exit 2, and
    nothing written."""
    run, bag, _ = exported
    cases = [
        (["export", str(run), "--ros2", str(bag)], "exists"),
        (["export", str(other_runs["triangle_ik"]), "--ros2", str(tmp_path / "ik-bag")], "no timed trajectory"),
        (["export", str(run)], "give --ros2 DIR, --csv FILE, or both"),
    ]
    for args, says in cases:
        done = dualarm_subprocess(args)
        assert done.returncode == 2 and says in done.stderr and done.stderr.count("\n") == 1, (args, done.stderr)
    assert not (tmp_path / "ik-bag").exists() and list(tmp_path.iterdir()) == []
