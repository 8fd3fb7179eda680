"""``/ik/sample`` carries each sample's hand orientation error beside its position error.

Read with the ``mcap`` library and ``jsonschema`` (not dualarm's read-back), and checked against
PyBullet's forward kinematics of the recorded joints and the recorded ``/task/reference`` orientation.
"""

from __future__ import annotations

import json

import jsonschema
import numpy as np
import pytest
from mcap.reader import make_reader
from scipy.spatial.transform import Rotation

from dualarm.contracts.joint_path import JointPath
from dualarm.ik.velocity.pinv import settings_for
from dualarm.record.recorder import Recorder
from dualarm.run import record_run
from dualarm.sim.world import load_pybullet_robot
from dualarm.tasks import load_task
from tests.helpers import TASKS, still_path_fields


def read_topics(path, prefix: str) -> tuple[dict[str, dict], dict[str, list[dict]]]:
    """The JSON schemas and the decoded messages of every topic starting with ``prefix``."""
    schemas, messages = {}, {}
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            if channel.topic.startswith(prefix):
                schemas[channel.topic] = json.loads(schema.data)
                messages.setdefault(channel.topic, []).append(json.loads(message.data))
    return schemas, messages


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """pinv on one box carry in position task space: the hands' orientation is measured, not solved (errors of ~2
    rad)."""
    task = load_task(TASKS / "carry_box.toml", 1)
    run = record_run(
        task,
        "pinv",
        stages=("path", "ik"),
        out_dir=tmp_path_factory.mktemp("runs"),
        settings=settings_for(task, task_space="position"),
    )
    return task, run.directory / "run.mcap"


@pytest.mark.integration
def test_ik_samples_carry_the_orientation_error_pybullet_measures(recorded):
    task, mcap = recorded
    _, ik = read_topics(mcap, "/ik/sample")
    _, reference = read_topics(mcap, "/task/reference/")
    samples = ik["/ik/sample"]
    assert {s["task_space"] for s in samples} == {"position"}
    asked = {
        topic.rsplit("/", 1)[1]: {m["t"]: m["orientation"] for m in messages} for topic, messages in reference.items()
    }
    assert set(asked) == {"left", "right"}
    worst = 0.0
    with load_pybullet_robot(task.robot.urdf.path) as sim:
        sim.set_positions(list(task.initial_q), list(task.initial_q.values()))  # the locked joints
        for sample in samples[::20]:
            sim.set_positions(list(sample["position"]), list(sample["position"].values()))
            for hand, recorded_angle in sample["hand_orientation_error_rad"].items():
                q = asked[hand][sample["t"]]
                wanted = Rotation.from_quat([q["x"], q["y"], q["z"], q["w"]])
                reached = Rotation.from_matrix(sim.link_pose(f"{hand}_hand")[:3, :3])
                angle = (wanted.inv() * reached).magnitude()
                assert recorded_angle == pytest.approx(angle, abs=1e-6)
                worst = max(worst, angle)
    assert worst > 1.0  # position task space: the orientation is far off, and recorded so


@pytest.mark.integration
def test_ik_sample_schema_describes_the_field_and_every_message_matches(recorded):
    _, mcap = recorded
    schemas, messages = read_topics(mcap, "/ik/sample")
    schema = schemas["/ik/sample"]
    for key in ("hand_error_m", "hand_orientation_error_rad"):
        field = schema["properties"][key]
        assert field["type"] == "object" and set(field["properties"]) == {"left", "right"}
    assert schema["properties"]["task_space"]["enum"] == ["pose", "position"]
    validator = jsonschema.Draft202012Validator(schema)
    for message in messages["/ik/sample"]:
        validator.validate(message)


def test_a_path_without_orientation_records_none(tmp_path, humanoid):
    """A planner's path measures no orientation (NaN): its samples leave the field out instead of writing NaN, which is
    not JSON."""
    N = 4
    path = JointPath(**still_path_fields(N, joint="left_elbow", method="mcikrrt"))
    recorder = Recorder(tmp_path, "test", humanoid, {})
    recorder.joint_path(path, np.ones(1), {}, stage="plan")
    recorder.close({})
    _, messages = read_topics(tmp_path / "run.mcap", "/plan/sample")
    assert len(messages["/plan/sample"]) == N
    assert all("hand_orientation_error_rad" not in m and "task_space" not in m for m in messages["/plan/sample"])
