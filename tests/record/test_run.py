"""The run directory contract, the MCAP and Rerun files, read-back and determinism."""

import hashlib
import json
import subprocess
import sys
import tomllib
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from mcap.reader import make_reader
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from dualarm.cli import app
from dualarm.errors import TaskFileError, UnreachablePoseError
from dualarm.record.readback import read_run, read_runs
from dualarm.run import record_run
from dualarm.sim.world import load_pybullet_robot
from tests.helpers import HUMANOID, TASKS

TRIANGLE = TASKS / "triangle.toml"


@pytest.fixture(scope="module")
def out_dir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("recordings")


@pytest.fixture(scope="module")
def triangle_run(out_dir) -> Path:
    return record_run(
        TRIANGLE, stages=["path"], out_dir=out_dir, seed=0, command=["dualarm", "run", str(TRIANGLE)]
    ).directory


def _messages(run: Path) -> dict[str, list[bytes]]:
    with (run / "run.mcap").open("rb") as f:
        out: dict[str, list[bytes]] = {}
        for _, channel, message in make_reader(f).iter_messages(log_time_order=True):
            out.setdefault(channel.topic, []).append(message.data)
    return out


@pytest.mark.integration
def test_run_directory_contract(triangle_run, out_dir):
    assert triangle_run.parent == out_dir / "triangle"
    assert sorted(p.name for p in triangle_run.iterdir()) == [
        "foxglove-layout.json",
        "manifest.json",
        "metrics.json",
        "run.mcap",
        "run.rrd",
    ]
    assert not [p for p in triangle_run.parent.iterdir() if p.name.startswith(".")]


@pytest.mark.integration
def test_manifest(triangle_run):
    manifest = json.loads((triangle_run / "manifest.json").read_text())
    assert manifest["status"] == "complete" and manifest["error"] is None
    assert manifest["run_id"] == triangle_run.name
    assert manifest["task_sha256"] == hashlib.sha256(TRIANGLE.read_bytes()).hexdigest()
    assert manifest["robot_sha256"]["robot.toml"] == hashlib.sha256((HUMANOID / "robot.toml").read_bytes()).hexdigest()
    assert (
        manifest["robot_sha256"]["humanoid.urdf"]
        == hashlib.sha256((HUMANOID / "humanoid.urdf").read_bytes()).hexdigest()
    )
    assert manifest["seed"] == 0 and manifest["stages"] == ["path"]
    assert manifest["command"] == ["dualarm", "run", str(TRIANGLE)]
    for package in ("casadi", "pybullet", "rerun-sdk", "foxglove-sdk", "mcap"):
        assert manifest["packages"][package] != "not installed"
    assert manifest["started_at"] <= manifest["finished_at"]


@pytest.mark.integration
def test_metrics_match_the_task_file(triangle_run):
    spec = tomllib.loads(TRIANGLE.read_text())
    steps = sum(round(m["duration_s"] / spec["control_period_s"]) for m in spec["moves"])
    metrics = json.loads((triangle_run / "metrics.json").read_text())
    assert metrics["path.samples"] == 1 + spec["repetitions"] * steps
    assert metrics["path.duration_s"] == pytest.approx(
        spec["repetitions"] * sum(m["duration_s"] for m in spec["moves"])
    )
    assert metrics["path.repetitions"] == spec["repetitions"]
    wp = spec["waypoints"]
    perimeter = sum(np.linalg.norm(np.subtract(wp[a]["position"], wp[b]["position"])) for a, b in ("AB", "BC", "CA"))
    assert metrics["path.length_max_m"] == pytest.approx(spec["repetitions"] * perimeter, rel=1e-9)


@pytest.mark.integration
def test_mcap_schemas_metadata_and_attachments(triangle_run):
    with (triangle_run / "run.mcap").open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        schemas = {s.id: s for s in summary.schemas.values()}
        topics = {c.topic: c for c in summary.channels.values()}
        for channel in summary.channels.values():
            schema = schemas[channel.schema_id]
            assert schema.name, channel.topic
            if channel.message_encoding == "json":
                assert schema.encoding == "jsonschema"
                jsonschema.Draft202012Validator.check_schema(json.loads(schema.data))
            else:
                assert (channel.message_encoding, schema.encoding) == ("protobuf", "protobuf")
        assert schemas[topics["/tf"].schema_id].name == "foxglove.FrameTransforms"
        assert schemas[topics["/task/reference_path"].schema_id].name == "foxglove.SceneUpdate"
        validators = {
            t: jsonschema.Draft202012Validator(json.loads(schemas[c.schema_id].data))
            for t, c in topics.items()
            if c.message_encoding == "json"
        }
        for _, channel, message in reader.iter_messages():
            if channel.topic in validators:
                validators[channel.topic].validate(json.loads(message.data))
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
        assert json.loads(metadata["manifest"]["status"]) == "complete"
        attachments = {a.name: a.data for a in reader.iter_attachments()}
    assert attachments["triangle.toml"] == TRIANGLE.read_bytes()
    assert attachments["humanoid.urdf"] == (HUMANOID / "humanoid.urdf").read_bytes()
    assert attachments["robot.toml"] == (HUMANOID / "robot.toml").read_bytes()


@pytest.mark.integration
def test_log_time_is_motion_time(triangle_run):
    with (triangle_run / "run.mcap").open("rb") as f:
        for _, _channel, message in make_reader(f).iter_messages(topics=["/task/reference/left"]):
            assert message.log_time == round(json.loads(message.data)["t"] * 1e9)


@pytest.mark.integration
def test_readback_reference_equals_the_task_waypoints(triangle_run):
    ref = read_run(triangle_run)["/task/reference/left"]
    assert list(ref.columns[:3]) == ["t", "rep", "stage"]
    assert (ref["stage"] == "path").all()
    np.testing.assert_allclose(np.diff(ref["t"]), 0.01, atol=1e-12)
    assert sorted(ref["rep"].unique()) == [0, 1, 2, 3, 4]
    spec = tomllib.loads(TRIANGLE.read_text())
    for k, name in ((0, "A"), (200, "B"), (400, "C"), (600, "A"), (3000, "A")):
        wp = spec["waypoints"][name]
        row = ref.iloc[k]
        np.testing.assert_allclose(
            row[["position.x", "position.y", "position.z"]].to_numpy(float),
            np.add(wp["position"], (0.0, 0.2, 1.4)),
            atol=1e-12,
        )  # frame = "left.shoulder" (scale 1 here)
        quat = row[["orientation.x", "orientation.y", "orientation.z", "orientation.w"]].to_numpy(float)
        angle = (Rotation.from_quat(quat).inv() * Rotation.from_euler("xyz", wp["rpy"])).magnitude()
        assert angle < 1e-9


@pytest.mark.integration
def test_tf_places_the_hand_where_pybullet_does(triangle_run, humanoid):
    """Composing /tf from world to left_hand (a run of the path stage alone shows the path robot) gives PyBullet's hand
    pose at the initial configuration (triangle.toml's ``[initial]`` table read with tomllib, the joints it does not
    name at 0), which puts the hand on waypoint A."""
    tf = read_run(triangle_run)["/tf"]
    assert set(tf["child_frame_id"]) == set(humanoid.urdf.links)
    parent = dict(zip(tf["child_frame_id"], tf["parent_frame_id"], strict=True))
    rows = tf.set_index("child_frame_id")
    T = np.eye(4)
    link = "left_hand"
    while link != "world":
        r = rows.loc[link]
        step = np.eye(4)
        step[:3, :3] = Rotation.from_quat(
            [r["rotation.x"], r["rotation.y"], r["rotation.z"], r["rotation.w"]]
        ).as_matrix()
        step[:3, 3] = [r["translation.x"], r["translation.y"], r["translation.z"]]
        T = step @ T
        link = parent[link]
    data = tomllib.loads(TRIANGLE.read_text())
    initial = {name: data["initial"].get(name, 0.0) for name in humanoid.home("ready")}
    with load_pybullet_robot(humanoid.urdf.path) as sim:
        sim.set_positions(list(initial), list(initial.values()))
        expected = sim.link_pose("left_hand")
    np.testing.assert_allclose(T, expected, atol=1e-6)
    assert (
        np.linalg.norm(T[:3, 3] - np.add(data["waypoints"]["A"]["position"], (0.0, 0.2, 1.4))) < 1e-6
    )  # frame = "left.shoulder" (scale 1 here)


@pytest.mark.integration
def test_rerun_file_verifies_with_the_rerun_cli(triangle_run):
    rerun = Path(sys.executable).parent / "rerun"
    result = subprocess.run(
        [str(rerun), "rrd", "verify", str(triangle_run / "run.rrd")],
        capture_output=True,
        text=True,
        env={"RERUN_ANALYTICS": "0", "PATH": ""},
    )
    assert result.returncode == 0, result.stderr


@pytest.mark.integration
def test_same_command_gives_identical_messages(triangle_run, out_dir):
    again = record_run(TRIANGLE, stages=["path"], out_dir=out_dir, seed=0).directory
    assert again != triangle_run
    assert _messages(again) == _messages(triangle_run)


@pytest.mark.integration
def test_read_runs_concatenates_with_run_column(triangle_run, out_dir):
    runs = sorted(p for p in (out_dir / "triangle").iterdir())
    frames = read_runs(runs)
    ref = frames["/task/reference/left"]
    assert set(ref["run"]) == {p.name for p in runs}
    assert (ref["task"] == "triangle").all()
    assert len(ref) == 3001 * len(runs)


def _task_copy(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "task.toml"
    path.write_text(text.replace('robot = "../robots/humanoid"', f'robot = "{HUMANOID}"'))
    return path


@pytest.mark.integration
def test_failed_stage_leaves_a_failed_run(tmp_path):
    """A circle whose far side is out of reach: the path stage fails mid-way, the run is kept as failed."""
    text = (
        (TASKS / "circle.toml")
        .read_text()
        .replace("arc_center = [0.31, -0.11, -0.35]", "arc_center = [0.31, -0.60, -0.35]")
    )  # [0.31, -0.40, 1.05]: relative to the left shoulder [0, 0.2, 1.4]
    task = _task_copy(tmp_path, text)
    with pytest.raises(UnreachablePoseError, match=r"moves\[0\]"):
        record_run(task, out_dir=tmp_path / "out")
    (run,) = (tmp_path / "out" / "circle").iterdir()
    manifest = json.loads((run / "manifest.json").read_text())
    assert manifest["status"] == "failed" and "moves[0]" in manifest["error"]
    assert not (run / "metrics.json").exists()
    assert read_run(run).status == "failed"


def test_malformed_task_writes_nothing(tmp_path):
    task = _task_copy(tmp_path, TRIANGLE.read_text().replace("control_period_s = 0.01", "control_period_s = -1"))
    with pytest.raises(TaskFileError, match="control_period_s"):
        record_run(task, out_dir=tmp_path / "out")
    assert not (tmp_path / "out").exists()


@pytest.mark.integration
def test_cli_run_prints_the_run_directory_last_and_inspect_reads_it(tmp_path):
    runner = CliRunner()
    result = runner.invoke(app, ["run", str(TRIANGLE), "--stages", "path", "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    run = Path(result.stdout.strip().splitlines()[-1])
    assert run.is_dir() and run.parent == tmp_path / "triangle"
    shown = runner.invoke(app, ["inspect", str(run)])
    assert shown.exit_code == 0
    assert "/task/reference/left" in shown.stdout and "path.samples" in shown.stdout


@pytest.mark.integration
def test_inspect_names_the_directory_and_cuts_a_huge_error(triangle_run, tmp_path, monkeypatch):
    """``inspect .`` names the run's directory; a 10 MB error in the manifest is printed cut to 2,000 characters
    (it was printed whole)."""
    import json
    import shutil

    run = tmp_path / triangle_run.name
    shutil.copytree(triangle_run, run)
    manifest = json.loads((run / "manifest.json").read_text())
    manifest["error"] = "x" * 10_000_000
    (run / "manifest.json").write_text(json.dumps(manifest))
    monkeypatch.chdir(run)
    shown = CliRunner().invoke(app, ["inspect", "."])
    assert shown.exit_code == 0, shown.output[:2000]
    assert str(run) in shown.stdout.splitlines()[0] and len(shown.stdout) < 20_000


@pytest.mark.integration
@pytest.mark.parametrize("damage", ["garbage", "truncated", "no manifest"])
def test_cli_inspect_refuses_a_corrupt_recording(triangle_run, tmp_path, damage):
    broken = tmp_path / "run"
    broken.mkdir()
    if damage != "no manifest":
        (broken / "manifest.json").write_bytes((triangle_run / "manifest.json").read_bytes())
    data = (triangle_run / "run.mcap").read_bytes()
    (broken / "run.mcap").write_bytes(b"not an mcap file" if damage == "garbage" else data[: len(data) // 3])
    result = CliRunner().invoke(app, ["inspect", str(broken)])
    assert result.exit_code == 2
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and str(broken) in lines[0]
    assert "Traceback" not in result.output


@pytest.mark.integration
def test_ik_run_records_joints_bounds_and_robot(tmp_path, humanoid):
    run = record_run(TASKS / "ball_game.toml", "tvgdd", stages=("path", "ik"), out_dir=tmp_path).directory
    data = read_run(run)
    sample, bounds = data["/ik/sample"], data["/ik/bounds"]
    assert len(sample) == len(bounds) == data.metrics["path.samples"]
    assert (sample["stage"] == "ik").all() and (sample["method"] == "tvgdd").all()
    arm_joints = [n for n in humanoid.joint_names if not n.startswith("waist")]
    for joint in arm_joints:
        qd = sample[f"velocity.{joint}"].to_numpy()
        assert np.all(qd >= bounds[f"zeta_lower.{joint}"].to_numpy() - 1e-9) and np.all(
            qd <= bounds[f"zeta_upper.{joint}"].to_numpy() + 1e-9
        )
    errors = sample[["hand_error_m.left", "hand_error_m.right"]].to_numpy()
    assert data.metrics["ik.position_error_max_m"] == pytest.approx(errors.max(), rel=1e-12)
    tf = data["/tf"]  # a run that stops after IK shows the IK robot
    assert set(tf["child_frame_id"]) == set(humanoid.urdf.links) and np.isclose(tf["t"].max(), sample["t"].max())
    assert json.loads((run / "manifest.json").read_text())["settings"]["ik"]["qp_plugin"] == "daqp"
