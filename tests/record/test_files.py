"""The recordings other tools open, checked with those tools' own readers, not dualarm.record.readback.

``run.mcap``: the ``mcap`` readers (sequential and indexed), ``jsonschema`` and ``protobuf`` decode
every message against the schema the file itself carries; ``/tf``, ``/robot_description``, the
metadata and the attachments are checked for what Foxglove's 3D panel and URDF layer need.
``run.rrd``: the ``rerun`` command line tool of this venv loads it (``rerun rrd verify``), and its
listing (``rerun rrd print``) shows a blueprint and every stage's robot.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tomllib
import xml.etree.ElementTree as ET
import zlib
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from google.protobuf.message import DecodeError, Message
from google.protobuf.unknown_fields import UnknownFieldSet
from mcap import records
from mcap.reader import make_reader
from mcap.stream_reader import StreamReader
from scipy.spatial.transform import Rotation

from dualarm.record.readback import read_run
from dualarm.report.run_report import run_label
from dualarm.run import record_run
from dualarm.tasks import load_task
from tests.helpers import HUMANOID, TASKS

pytestmark = pytest.mark.integration

URDF = HUMANOID / "humanoid.urdf"
RERUN = Path(sys.executable).parent / "rerun"
MCAP_MAGIC = b"\x89MCAP0\r\n"
#: Footer record: opcode (1), record length (8), summary_start (8), summary_offset_start (8), summary_crc (4).
FOOTER_SIZE = 1 + 8 + 8 + 8 + 4


@dataclass(frozen=True)
class RunSpec:
    task: Path
    method: str
    options: dict
    stages: tuple[str, ...]
    repetitions: int | None = None


#: The runs checked: the whole IK pipeline on one triangle, and a planned run with a scene.
RUNS = {
    "triangle": RunSpec(
        TASKS / "triangle.toml",
        "mc-inverse",
        {"stages": ("path", "ik", "retime", "smooth", "approach", "execute")},
        ("path", "ik", "retime", "smooth", "approach", "execute"),
        repetitions=1,
    ),
    "bowl_grasp": RunSpec(
        TASKS / "bowl_grasp.toml", "mcikrrt", {}, ("path", "plan", "retime", "smooth", "approach", "execute")
    ),
}


@pytest.fixture(scope="module")
def out_dir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("file_runs")


@pytest.fixture(scope="module", params=sorted(RUNS))
def run(request, out_dir) -> tuple[RunSpec, Path]:
    spec = RUNS[request.param]
    return spec, record_run(
        load_task(spec.task, spec.repetitions), spec.method, out_dir=out_dir, **spec.options
    ).directory


# -- the URDF, read here with xml.etree -----------------------------------------------------------


@dataclass(frozen=True)
class Urdf:
    name: str
    links: tuple[str, ...]
    parent: dict[str, str]  # child link -> parent link
    joints: dict[str, tuple[str, str]]  # joint name -> (type, child link)
    root: str
    element: ET.Element


def read_urdf(text: str) -> Urdf:
    robot = ET.fromstring(text)
    assert robot.tag == "robot"
    links = tuple(link.get("name") for link in robot.findall("link"))
    parent = {j.find("child").get("link"): j.find("parent").get("link") for j in robot.findall("joint")}
    joints = {j.get("name"): (j.get("type"), j.find("child").get("link")) for j in robot.findall("joint")}
    (root,) = [link for link in links if link not in parent]
    return Urdf(robot.get("name"), links, parent, joints, root, robot)


@pytest.fixture(scope="module")
def urdf() -> Urdf:
    return read_urdf(URDF.read_text())


def hand_tips() -> dict[str, str]:
    """Hand -> tip link of its chain, from robot.toml."""
    chains = tomllib.loads((HUMANOID / "robot.toml").read_text())["chains"]
    return {c["hand"]: c["tip"] for c in chains.values() if "hand" in c}


# -- MCAP: the file read twice, sequentially (no index) and through its summary -------------------


@dataclass
class McapFile:
    data: bytes
    header: records.Header
    footer: records.Footer
    summary: object
    schemas: dict[int, records.Schema]  # from the data section (the summary's are in ``summary``)
    channels: dict[int, records.Channel]  # from the data section
    messages: dict[str, list[records.Message]] = field(default_factory=dict)  # topic -> messages, file order
    indexed_counts: Counter = field(default_factory=Counter)  # topic -> messages read through the index
    metadata: list[records.Metadata] = field(default_factory=list)
    attachments: list[records.Attachment] = field(default_factory=list)

    def schema(self, topic: str) -> records.Schema:
        (channel,) = [c for c in self.summary.channels.values() if c.topic == topic]
        return self.summary.schemas[channel.schema_id]


def read_mcap(path: Path) -> McapFile:
    data = path.read_bytes()
    with path.open("rb") as f:
        stream = list(StreamReader(f, validate_crcs=True).records)
    header, footer = stream[0], stream[-1]
    assert isinstance(header, records.Header) and isinstance(footer, records.Footer)
    with path.open("rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        indexed = Counter(channel.topic for _, channel, _ in reader.iter_messages(log_time_order=False))
    out = McapFile(data, header, footer, summary, {}, {}, indexed_counts=indexed)
    ends = [i for i, record in enumerate(stream) if isinstance(record, records.DataEnd)]
    assert len(ends) == 1, "no DataEnd record between the data and the summary sections"
    for record in stream[: ends[0]]:  # the data section; the summary repeats schemas and channels
        if isinstance(record, records.Schema):
            out.schemas[record.id] = record
        elif isinstance(record, records.Channel):
            out.channels[record.id] = record
        elif isinstance(record, records.Message):
            out.messages.setdefault(out.channels[record.channel_id].topic, []).append(record)
        elif isinstance(record, records.Metadata):
            out.metadata.append(record)
        elif isinstance(record, records.Attachment):
            out.attachments.append(record)
    return out


@pytest.fixture(scope="module")
def mcap_file(run) -> McapFile:
    return read_mcap(run[1] / "run.mcap")


def _not_json(constant: str):
    raise ValueError(f"{constant} is not JSON")


def json_errors(schema: dict, payloads: list[bytes], limit: int = 5) -> list[str]:
    """Errors of ``payloads`` (JSON text) against the JSON Schema ``schema`` (itself checked first);
    NaN and Infinity, which Python writes but JSON does not allow, count as errors."""
    cls = jsonschema.validators.validator_for(schema)
    cls.check_schema(schema)
    validator = cls(schema, format_checker=cls.FORMAT_CHECKER)
    errors = []
    for i, payload in enumerate(payloads):
        try:
            instance = json.loads(payload, parse_constant=_not_json)
        except ValueError as exc:
            errors.append(f"message {i}: not JSON: {exc}")
            continue
        errors.extend(f"message {i}: {e.json_path}: {e.message}" for e in validator.iter_errors(instance))
        if len(errors) >= limit:
            break
    return errors


def protobuf_class(schema: records.Schema) -> type[Message]:
    """The message class of ``schema`` built from the FileDescriptorSet in the file, in a pool of its own."""
    files = list(descriptor_pb2.FileDescriptorSet.FromString(schema.data).file)
    pool, added = descriptor_pool.DescriptorPool(), set()
    while files:
        ready = [f for f in files if set(f.dependency) <= added]
        assert ready, f"{schema.name}: unresolvable dependencies {[f.dependency for f in files]}"
        for f in ready:
            pool.Add(f)
            added.add(f.name)
            files.remove(f)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))


def _unknown_fields(message: Message, path: str) -> list[str]:
    found = [f"{path}: {len(UnknownFieldSet(message))} unknown field(s)"] if len(UnknownFieldSet(message)) else []
    for fd, value in message.ListFields():
        if fd.message_type is None:
            continue
        if fd.message_type.GetOptions().map_entry:
            nested = value.values() if fd.message_type.fields_by_name["value"].message_type else []
        else:
            nested = value if fd.is_repeated else [value]
        for k, sub in enumerate(nested):
            found += _unknown_fields(sub, f"{path}.{fd.name}[{k}]")
    return found


def protobuf_errors(cls: type[Message], payloads: list[bytes], limit: int = 5) -> list[str]:
    """Errors of ``payloads`` as messages of ``cls``: undecodable, unknown fields, or bytes that
    re-serialising does not give back."""
    errors = []
    for i, payload in enumerate(payloads):
        message = cls()
        try:
            message.ParseFromString(payload)
        except DecodeError as exc:
            errors.append(f"message {i}: does not decode: {exc}")
            continue
        errors += [f"message {i}: {e}" for e in _unknown_fields(message, cls.DESCRIPTOR.full_name)]
        if message.SerializeToString() != payload:
            errors.append(f"message {i}: re-serialised bytes differ from the recorded ones")
        if len(errors) >= limit:
            break
    return errors


# -- MCAP tests ---------------------------------------------------------------------------------------


def test_mcap_has_summary_footer_and_consistent_statistics(mcap_file):
    data = mcap_file.data
    assert data.startswith(MCAP_MAGIC) and data.endswith(MCAP_MAGIC)
    footer = data[-len(MCAP_MAGIC) - FOOTER_SIZE : -len(MCAP_MAGIC)]
    assert footer[0] == records.Opcode.FOOTER and int.from_bytes(footer[1:9], "little") == 8 + 8 + 4
    summary_start, offset_start = int.from_bytes(footer[9:17], "little"), int.from_bytes(footer[17:25], "little")
    crc = int.from_bytes(footer[25:29], "little")
    assert (summary_start, offset_start, crc) == (
        mcap_file.footer.summary_start,
        mcap_file.footer.summary_offset_start,
        mcap_file.footer.summary_crc,
    )
    assert 0 < summary_start <= offset_start < len(data), "no summary section"
    assert crc in (0, zlib.crc32(data[summary_start : len(data) - len(MCAP_MAGIC) - 4]))

    summary = mcap_file.summary
    assert summary is not None and summary.statistics is not None and summary.chunk_indexes
    stats = summary.statistics
    iterated = {topic: len(ms) for topic, ms in mcap_file.messages.items()}
    by_topic = {summary.channels[cid].topic: n for cid, n in stats.channel_message_counts.items()}
    assert by_topic == iterated
    assert dict(mcap_file.indexed_counts) == iterated
    assert stats.message_count == sum(iterated.values())
    assert stats.channel_count == len(summary.channels) == len(mcap_file.channels)
    assert stats.schema_count == len(summary.schemas) == len(mcap_file.schemas)
    assert stats.attachment_count == len(mcap_file.attachments) == len(summary.attachment_indexes)
    assert stats.metadata_count == len(mcap_file.metadata) == len(summary.metadata_indexes)
    times = [m.log_time for ms in mcap_file.messages.values() for m in ms]
    assert (stats.message_start_time, stats.message_end_time) == (min(times), max(times))
    for cid, channel in summary.channels.items():
        assert mcap_file.channels[cid] == channel
        assert summary.schemas[channel.schema_id] == mcap_file.schemas[channel.schema_id]


def test_every_channel_has_a_schema_and_every_message_matches_it(mcap_file):
    checked = Counter()
    for channel in mcap_file.summary.channels.values():
        assert channel.schema_id in mcap_file.summary.schemas, f"{channel.topic}: no schema"
        schema = mcap_file.summary.schemas[channel.schema_id]
        assert schema.name, channel.topic
        payloads = [m.data for m in mcap_file.messages.get(channel.topic, [])]
        assert payloads, f"{channel.topic}: no messages"
        if schema.encoding == "jsonschema":
            assert channel.message_encoding == "json", channel.topic
            assert json_errors(json.loads(schema.data), payloads) == [], f"{channel.topic} ({schema.name})"
        else:
            assert (schema.encoding, channel.message_encoding) == ("protobuf", "protobuf"), channel.topic
            assert protobuf_errors(protobuf_class(schema), payloads) == [], f"{channel.topic} ({schema.name})"
        checked[schema.encoding] += len(payloads)
    assert checked["jsonschema"] > 0 and checked["protobuf"] > 0


def test_schema_checks_catch_bad_messages(mcap_file):
    """The checks above can fail: messages broken on purpose are caught."""
    schema = json.loads(mcap_file.schema("/execute/sample").data)
    good = json.loads(mcap_file.messages["/execute/sample"][0].data)
    assert json_errors(schema, [json.dumps(good).encode()]) == []
    joint = next(iter(good["position"]))
    for broken in (
        {**good, "rep": "first"},
        {k: v for k, v in good.items() if k != "t"},
        {**good, "position": {**good["position"], joint: "high"}},
    ):
        assert json_errors(schema, [json.dumps(broken).encode()]), broken
    assert json_errors(schema, [json.dumps({**good, "t": float("nan")}).encode()])  # NaN is not JSON
    assert json_errors(schema, [b'{"t": 0.0, "rep": 0'])
    with pytest.raises(jsonschema.SchemaError):
        json_errors({"type": "no-such-type"}, [])

    frames = protobuf_class(mcap_file.schema("/tf"))
    payload = mcap_file.messages["/tf"][0].data
    assert protobuf_errors(frames, [payload]) == []
    assert protobuf_errors(frames, [payload + b"\x78\x01"])  # field 15 (varint 1): unknown to FrameTransforms
    assert protobuf_errors(frames, [payload[:-3]])  # truncated


def _transforms(mcap_file: McapFile):
    """(log time [ns], FrameTransforms) of every /tf message."""
    cls = protobuf_class(mcap_file.schema("/tf"))
    return [(m.log_time, cls.FromString(m.data)) for m in mcap_file.messages["/tf"]]


def _world_position(frames: dict[str, tuple[str, np.ndarray, np.ndarray]], frame: str) -> np.ndarray:
    """Origin of ``frame`` in ``world``: child -> (parent, translation, quaternion xyzw)."""
    T = np.eye(4)
    seen = set()
    while frame != "world":
        assert frame not in seen, f"cycle through {frame}"
        seen.add(frame)
        parent, p, q = frames[frame]
        step = np.eye(4)
        step[:3, :3], step[:3, 3] = Rotation.from_quat(q).as_matrix(), p
        T = step @ T
        frame = parent
    return T[:3, 3]


def test_tf_is_one_robot_under_its_urdf_link_names_rooted_at_world(run, mcap_file, urdf):
    """/tf holds the executed robot alone, under the URDF's own link names (Foxglove's URDF layer places links by them),
    from t = 0."""
    channel_schema = mcap_file.schema("/tf")
    assert channel_schema.name == "foxglove.FrameTransforms"
    expected_parent = {urdf.root: "world", **urdf.parent}
    times = []
    for log_time, message in _transforms(mcap_file):
        times.append(log_time)
        parent = {}
        for t in message.transforms:
            assert t.child_frame_id not in parent, f"{t.child_frame_id} twice at {log_time}"
            parent[t.child_frame_id] = t.parent_frame_id
            # the header stamp Foxglove looks transforms up by is the log time (to 1 us: today some
            # are 1 ns early, Timestamp.from_epoch_secs truncating where the log time is rounded)
            stamp = t.timestamp.seconds * 10**9 + t.timestamp.nanos
            assert abs(stamp - log_time) <= 1000, f"{t.child_frame_id} stamped {stamp} ns, logged at {log_time} ns"
            q = [t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w]
            assert abs(np.linalg.norm(q) - 1) < 1e-6, f"{t.child_frame_id}: quaternion {q}"
        assert parent == expected_parent
    assert times[0] == 0 and times == sorted(times) and len(times) > 1  # from the start, never back in time


def test_tf_puts_the_hands_where_pybullet_measured_them(run, mcap_file):
    """Composing /tf down to each hand gives the hand positions PyBullet measured (/execute/sample) at the same instant,
    and the hands move."""
    tips = hand_tips()
    samples = {m.log_time: json.loads(m.data)["hand_position"] for m in mcap_file.messages["/execute/sample"]}
    hands = set(next(iter(samples.values())))
    assert hands and hands <= set(tips)
    positions: dict[str, list] = {hand: [] for hand in hands}
    for log_time, message in _transforms(mcap_file):
        frames = {
            t.child_frame_id: (
                t.parent_frame_id,
                [t.translation.x, t.translation.y, t.translation.z],
                [t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w],
            )
            for t in message.transforms
        }
        assert log_time in samples, f"/tf at {log_time} ns has no /execute/sample"
        for hand in hands:
            p = _world_position(frames, tips[hand])
            recorded = samples[log_time][hand]
            np.testing.assert_allclose(
                p, [recorded["x"], recorded["y"], recorded["z"]], atol=1e-6, err_msg=f"{hand} at {log_time} ns"
            )
            positions[hand].append(p)
    for hand, p in positions.items():
        travel = np.ptp(np.array(p), axis=0).max()
        assert travel > 0.05, f"the {hand} hand moves only {travel:.4f} m on /tf"


def test_robot_description_is_the_urdf(mcap_file, urdf):
    """The URDF as URDF 1.0 viewers read it: the same links and joints, no <capsule> (checked with PyBullet in
    tests/model/test_urdf.py)."""
    (message,) = mcap_file.messages["/robot_description"]
    text = json.loads(message.data)["data"]
    assert "<capsule" in URDF.read_text() and "<capsule" not in text
    described = read_urdf(text)
    assert described.name == urdf.name and described.links == urdf.links
    assert described.parent == urdf.parent


def test_metadata_holds_the_manifest_and_attachments_the_inputs(run, mcap_file):
    spec, run_dir = run
    manifest = json.loads((run_dir / "manifest.json").read_text())
    assert manifest["status"] == "complete" and tuple(manifest["stages"]) == spec.stages
    joint_path_stage = "plan" if "plan" in spec.stages else "ik"
    assert (
        manifest["settings"][joint_path_stage]["method"] == spec.method
    )  # a planner's name is not hidden by its settings
    assert run_label(read_run(run_dir)) == f"{run_dir.parent.name} {spec.method}"
    (metadata,) = mcap_file.metadata
    assert metadata.name == "manifest"
    assert {k: json.loads(v) for k, v in metadata.metadata.items()} == manifest
    attachments = {a.name: a for a in mcap_file.attachments}
    inputs = {spec.task.name: spec.task, "humanoid.urdf": URDF, "robot.toml": HUMANOID / "robot.toml"}
    assert set(attachments) == set(inputs)
    for name, path in inputs.items():
        assert attachments[name].data == path.read_bytes(), name
        assert attachments[name].media_type == ("application/xml" if name.endswith(".urdf") else "application/toml")


def test_environment_scene_update_holds_the_task_objects(run, mcap_file):
    spec, _ = run
    objects = {o["name"]: o for o in tomllib.loads(spec.task.read_text()).get("environment", [])}
    if not objects:
        assert "/task/environment" not in mcap_file.messages
        return
    schema = mcap_file.schema("/task/environment")
    assert schema.name == "foxglove.SceneUpdate"
    (message,) = mcap_file.messages["/task/environment"]
    update = protobuf_class(schema).FromString(message.data)
    entities = {e.id: e for e in update.entities}
    assert set(entities) == set(objects)
    kind = {"box": "cubes", "cylinder": "cylinders", "sphere": "spheres"}
    for name, obj in objects.items():
        entity = entities[name]
        assert entity.frame_id == "world"
        (primitive,) = getattr(entity, kind[obj["shape"]])
        position = primitive.pose.position
        np.testing.assert_allclose([position.x, position.y, position.z], obj["pose"]["position"], atol=1e-12)


# -- Rerun: the rerun command line tool of this venv --------------------------------------------------


def rerun_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [str(RERUN), *args], capture_output=True, text=True, timeout=120, env={**os.environ, "RERUN_ANALYTICS": "0"}
    )


@dataclass
class RrdListing:
    """What ``rerun rrd print --footers true`` lists: the stores announced (kind, application id,
    store id), the chunks (id, entity path, rows, columns), the blueprint activations, and the
    chunk ids of each store's footer manifest (``rrd print`` does not say which store a chunk
    belongs to, chunks of both stores interleave, the footers do)."""

    stores: list[tuple[str, str, str]] = field(default_factory=list)
    chunks: list[tuple[str, str, int, tuple[str, ...]]] = field(default_factory=list)
    activations: list[tuple[str, str, str, bool, bool]] = field(default_factory=list)
    footers: list[set[str]] = field(default_factory=list)

    def blueprint_footers(self) -> list[set[str]]:
        """The chunk ids of each blueprint store (each footer holding a ``/viewport``), in the file's order."""
        viewport = {cid for cid, entity, _, _ in self.chunks if entity == "/viewport"}
        return [f for f in self.footers if f & viewport]

    def store_chunks(self, kind: str) -> set[str]:
        """Chunk ids of the blueprint stores or of the recording."""
        blueprints = self.blueprint_footers()
        if kind == "Blueprint":
            return set().union(*blueprints)
        return set().union(*(f for f in self.footers if f not in blueprints))

    def entities(self, kind: str) -> dict[str, tuple[int, set[str]]]:
        """Entity -> (rows, columns) of the chunks of the store of ``kind``."""
        ids = self.store_chunks(kind)
        out: dict[str, tuple[int, set[str]]] = {}
        for cid, entity, rows, columns in self.chunks:
            if cid in ids:
                n, cols = out.get(entity, (0, set()))
                out[entity] = (n + rows, cols | set(columns))
        return out


_STORE = r'StoreInfo \{\s*store_id: StoreId\(\s*(?P<kind>\w+),\s*"(?P<app>[^"]*)",\s*"(?P<sid>[^"]*)"'
_CHUNK = (
    r"^Chunk\(chunk_(?P<cid>\w+)\) with (?P<rows>\d+) rows \([^)]*\) - (?P<entity>\S+)"
    r" - data columns: \[(?P<columns>[^\]]*)\]"
)
_ACTIVATION = (
    r'BlueprintActivationCommand\(StoreId\((?P<akind>\w+), "(?P<aapp>[^"]*)", "(?P<aid>[^"]*)"\),'
    r" make_active: (?P<active>\w+), make_default: (?P<default>\w+)\)"
)
_FOOTER_CHUNK_ID = r"┆\s*([0-9a-f]{32})\s*┆"


def rrd_listing(path: Path) -> RrdListing:
    result = rerun_cli("rrd", "print", "--footers", "true", str(path))
    assert result.returncode == 0, result.stderr
    body, *footers = re.split(r"^.*METADATA:.*$", result.stdout, flags=re.MULTILINE)
    listing = RrdListing(footers=[set(re.findall(_FOOTER_CHUNK_ID, footer)) for footer in footers])
    for m in re.finditer("|".join((_STORE, _CHUNK, _ACTIVATION)), body, re.MULTILINE):
        if m["kind"]:
            if (m["kind"], m["app"], m["sid"]) not in listing.stores:
                listing.stores.append((m["kind"], m["app"], m["sid"]))
        elif m["entity"]:
            listing.chunks.append((m["cid"].lower(), m["entity"], int(m["rows"]), tuple(m["columns"].split())))
        else:
            listing.activations.append((m["akind"], m["aapp"], m["aid"], m["active"] == "true", m["default"] == "true"))
    return listing


def rrd_rows(path: Path, entity: str) -> str:
    """The table of ``entity``'s rows, as ``rerun rrd print -vvv`` shows it."""
    result = rerun_cli("rrd", "print", "-vvv", "--entity", entity, str(path))
    assert result.returncode == 0, result.stderr
    return result.stdout


def blueprint_views(path: Path, listing: RrdListing) -> list[str]:
    """The rows (class, name, origin) of the blueprint's views."""
    assert any(kind == "Blueprint" for kind, _, _ in listing.stores), f"no blueprint store, only {listing.stores}"
    views = sorted({e for e in listing.entities("Blueprint") if re.fullmatch(r"/view/[0-9a-f-]+", e)})
    return [
        line
        for view in views
        for line in rrd_rows(path, view).splitlines()
        if "┆" in line and line.strip("│ ").startswith("row_")
    ]


@pytest.fixture(scope="module")
def rrd(run) -> tuple[Path, RrdListing]:
    path = run[1] / "run.rrd"
    return path, rrd_listing(path)


def test_rrd_verifies_with_the_rerun_cli(rrd):
    path, _ = rrd
    result = rerun_cli("rrd", "verify", str(path))
    assert result.returncode == 0, result.stdout + result.stderr
    assert "verified without error" in result.stdout + result.stderr


@pytest.mark.parametrize("damage", ["truncated", "garbage"])
def test_rerun_cli_refuses_a_damaged_rrd(rrd, tmp_path, damage):
    path, _ = rrd
    data = path.read_bytes()
    broken = tmp_path / "run.rrd"
    broken.write_bytes(data[: len(data) // 2] if damage == "truncated" else b"not a rerun recording\n" * 64)
    result = rerun_cli("rrd", "verify", str(broken))
    assert result.returncode != 0, result.stdout + result.stderr


def test_rrd_holds_the_recording_and_an_active_blueprint(run, rrd):
    """The layout before the data, so that a viewer opening the file never shows its default layout; then, after the
    data, the same layout with each plot's value range, activated last."""
    _, run_dir = run
    path, listing = rrd
    assert listing.stores[0] == ("Recording", "dualarm", run_dir.name)
    blueprints = [s for s in listing.stores if s[0] == "Blueprint"]
    assert [app for _, app, _ in blueprints] == ["dualarm", "dualarm"]
    assert all(("Blueprint", "dualarm", sid, True, True) in listing.activations for _, _, sid in blueprints)
    assert listing.activations[-1][2] == blueprints[-1][2]  # the final layout is the active one
    order = [cid for cid, entity, _, _ in listing.chunks if entity != "/__properties"]
    blueprint_footers = listing.blueprint_footers()
    assert len(blueprint_footers) == 2
    first = min(blueprint_footers, key=lambda chunks: min(order.index(c) for c in chunks))
    assert set(order[: len(first)]) == first
    # one footer manifest per store, and together they hold exactly the chunks listed
    assert len(listing.footers) == len(listing.stores) == 3
    assert sorted(c for f in listing.footers for c in f) == sorted(c[0] for c in listing.chunks)
    blueprint = listing.entities("Blueprint")
    assert "/viewport" in blueprint
    assert all(
        re.fullmatch(r"/(viewport|(blueprint|selection|time)_panel|container/.+|view/.+)", e) for e in blueprint
    ), sorted(blueprint)
    rows = blueprint_views(path, listing)
    assert any("[3D]" in row and "[/]" in row for row in rows), rows
    assert any("[TimeSeries]" in row and "[/plots]" in row for row in rows), rows


def test_blueprint_check_fails_on_an_rrd_without_blueprint(tmp_path):
    import rerun as rr

    path = tmp_path / "bare.rrd"
    stream = rr.RecordingStream("dualarm", recording_id="bare")
    stream.save(path)
    stream.log("world/point", rr.Points3D([[0.0, 0.0, 0.0]]))
    stream.flush()
    stream.disconnect()
    listing = rrd_listing(path)
    assert [s[0] for s in listing.stores] == ["Recording"] and not listing.activations
    with pytest.raises(AssertionError, match="no blueprint store"):
        blueprint_views(path, listing)


def test_rrd_has_every_stage_robot(run, rrd, mcap_file, urdf):
    """Each stage's URDF under /<stage>/<robot>, hung from the world by /<stage>/root, its fixed
    frames in its own /<stage>/tf_static (static data logged twice to one entity replaces the
    first in the viewer, so one shared entity would keep one stage's) and each moving joint
    animated once per /tf message of the stage."""
    spec, _ = run
    path, listing = rrd
    entities = listing.entities("Recording")
    tf_messages = len(mcap_file.messages["/tf"])
    for stage in spec.stages:
        static = rrd_rows(path, f"/{stage}/tf_static")
        robot = f"/{stage}/{urdf.name}"
        assert robot in entities, f"no {robot}"
        for link in urdf.element.findall("link"):
            for kind in ("visual", "collision"):
                for i in range(len(link.findall(kind))):
                    pattern = rf"{re.escape(robot)}/{kind}_geometries/(\w+/)?{link.get('name')}/{kind}_{i}"
                    assert any(re.fullmatch(pattern, e) for e in entities), (
                        f"{stage}: no {kind} {i} of {link.get('name')}"
                    )
        for joint, (kind, child) in urdf.joints.items():
            assert f"[{stage}/{child}]" in static, f"/{stage}/tf_static has no {stage}/{child}"
            if kind == "fixed":
                continue
            rows, columns = entities.get(f"/{stage}/transforms/{joint}", (0, set()))
            assert {"Transform3D:child_frame", "Transform3D:parent_frame", "Transform3D:quaternion"} <= columns, (
                f"{stage}/{joint}: {columns}"
            )
            if stage == "execute":  # the robot on /tf
                assert rows == tf_messages, f"/{stage}/transforms/{joint}: {rows} rows, /tf has {tf_messages} messages"
            else:
                assert rows >= 1 if stage in ("path", "approach") else rows > 1, (
                    f"/{stage}/transforms/{joint}: {rows} rows"
                )
        root = rrd_rows(path, f"/{stage}/root")
        assert "[tf#/]" in root and f"[{stage}/{urdf.root}]" in root, root
        if stage != "path":
            assert any(e.startswith(f"/plots/{stage}/") for e in entities), f"no /plots/{stage}"
        if stage in ("ik", "plan", "retime", "smooth", "execute"):
            assert any(
                e.startswith(f"/world/{stage}/") and "LineStrips3D:strips" in c for e, (_, c) in entities.items()
            ), f"no hand traces of {stage}"
    for obj in tomllib.loads(spec.task.read_text()).get("environment", []):
        assert f"/world/environment/{obj['name']}" in entities


def test_the_series_of_a_plot_have_colours_of_their_own(rrd):
    """Within a plot the run opens on (the IK's and the execution's hand errors; a stage's joint positions), no two
    series share a colour, as Rerun's own ``rrd print`` reads them (Rerun's default, from the path's hash, repeats)."""
    path, listing = rrd
    entities = listing.entities("Recording")

    def colour(entity: str) -> int:
        (packed,) = re.findall(r"^│ │ row_\w+\s*┆\s*\[(\d+)\]", rrd_rows(path, entity), re.MULTILINE)
        return int(packed)

    plots = {
        "hand error": sorted(e for e in entities if re.fullmatch(r"/plots/(ik|execute)/hand_error_m/\w+", e)),
        "joint positions": sorted(e for e in entities if e.startswith("/plots/smooth/position/")),
    }
    for plot, series in plots.items():
        colours = [colour(entity) for entity in series]
        assert len(series) >= 2 and len(set(colours)) == len(colours), (plot, dict(zip(series, colours, strict=True)))
