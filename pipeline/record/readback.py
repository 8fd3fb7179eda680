"""Reading runs back into pandas: the only path reports and analyses use.

:func:`read_run` turns one run directory into a :class:`RunData` holding one DataFrame per MCAP
topic, with columns ``t`` (motion time [s]), ``rep`` (repetition), ``stage`` and one column per
message field (nested fields joined with dots: ``position.x``). A topic is decoded when it is
first used, so reading a run for its metrics or one topic does not decode its ``/tf``.
:func:`read_runs` concatenates many runs per topic with ``run`` and ``task`` columns added.

Reading a run validates it first; a run that fails any check is a :class:`RecordingError` naming
the file and the fault, never a partial or silently different result:

- ``run.mcap`` (:func:`verify_mcap`): read end to end with the ``mcap`` library's CRC checks (the
  data section's CRC in its DataEnd record and every chunk's CRC), plus the summary section's CRC
  of the footer, which the library does not check (one ``zlib.crc32``), and the DataEnd record's
  own bytes, which no CRC covers (compared with the library's encoding of it). A file written
  without these CRCs is refused: it cannot be verified.
- ``manifest.json`` (:class:`Manifest`) and ``metrics.json`` (:data:`METRIC_KEY`): a JSON object
  with the keys and types the readers use, checked with pydantic. The manifest's ``task`` must be
  a task name (:data:`TASK_NAME`, the task schema's rule) and its ``run_id`` a run id
  (:data:`RUN_ID`, the form of :func:`~dualarm.record.run_dir.new_run_id`), so neither can
  carry a path (``..``, ``/``) into the file names reports build from them.
- The files belong to one run: the manifest stored in ``run.mcap`` (MCAP metadata ``manifest``)
  agrees with ``manifest.json`` on task, run id, status, stages and recording level; ``metrics.json`` equals the
  metrics recorded on ``/metrics`` in ``run.mcap``, and exists whenever the status is
  ``complete`` or ``violated``; ``run.rrd`` is a regular file and not empty (its content is Rerun's to check).
- A run recorded below ``full`` (the manifest's ``record``, :data:`~dualarm.record.sink.RECORD_LEVELS`;
  a run without it is ``full``) is as valid: an ``ik`` run's files are checked as a full run's,
  its ``run.mcap`` holding the topics of the path and ik (or plan) stages only; a ``metrics`` run
  has no ``run.mcap`` and no ``run.rrd`` (one present beside it is refused) and no topics. Asking
  for a topic the run did not record names the level (:meth:`RunData.__getitem__`).
"""

from __future__ import annotations

import io
import json
import math
import os
import re
import stat
import zlib
from collections import defaultdict
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Annotated, Any, Literal, cast, get_args

import pandas as pd
from google.protobuf.json_format import MessageToDict
from mcap.data_stream import RecordBuilder
from mcap.exceptions import EndOfFile, InvalidMagic, McapError
from mcap.reader import SeekingReader, make_reader
from mcap.records import Chunk, DataEnd, Footer, Header
from mcap.stream_reader import MAGIC_SIZE, CRCValidationError, StreamReader, get_chunk_data_stream
from mcap.summary import Summary
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory
from pydantic import BaseModel, ConfigDict, Field, StringConstraints, TypeAdapter, ValidationError

from dualarm.errors import RecordingError, excerpt
from dualarm.files import cause, kind, read_text
from dualarm.record.recorder import STAGE_TOPICS
from dualarm.record.run_dir import MANIFEST, METRICS
from dualarm.record.sink import RecordLevel, recorded_stages

#: The recording files of a run directory.
MCAP_FILE, RRD_FILE = "run.mcap", "run.rrd"
#: A run's status (the manifest's ``status``): see :class:`RunData.status`.
Status = Literal["complete", "violated", "failed", "running"]
STATUSES: tuple[str, ...] = get_args(Status)
#: Statuses of a finished run, which has a ``metrics.json``.
FINISHED = ("complete", "violated")
#: A task's name, as the task schema requires it (letters, digits, ``_`` and ``-``).
TASK_NAME = r"[A-Za-z0-9_\-]+"
#: A run id, as :func:`~dualarm.record.run_dir.new_run_id` makes it: ``20261121-130501-a1b2c3``.
RUN_ID = r"[0-9]{8}-[0-9]{6}-[0-9a-f]{6}"
#: A key of ``metrics.json``: ``<stage>.<name>``. (These patterns match whole strings.)
METRIC_KEY = r"[a-z][a-z0-9_]*\.[A-Za-z0-9_.\-]+"

_STAGE_OF_FAMILY = {family: stage for stage, family in STAGE_TOPICS.items()}


def stage_of(topic: str) -> str:
    """The pipeline stage a topic belongs to (``/task/...`` -> ``path``; ``/tf`` -> ``robot``)."""
    family = "/" + topic.strip("/").split("/")[0]
    if family in _STAGE_OF_FAMILY:
        return _STAGE_OF_FAMILY[family]
    return {"/tf": "robot", "/robot_description": "robot", "/metrics": "metrics"}.get(family, family.strip("/"))


#: Columns of ``/tf``: one row per transform (the per-transform timestamp equals ``t``).
_TF_COLUMNS = ("parent_frame_id", "child_frame_id", "translation.x", "translation.y", "translation.z", "rotation.x", "rotation.y", "rotation.z", "rotation.w")


def _json_frame(times: list[float], payloads: list[bytes]) -> pd.DataFrame:
    """JSON messages -> a DataFrame (nested fields joined with dots); a message's own ``t`` wins over its log time."""
    df = pd.json_normalize(json.loads(b"[" + b",".join(payloads) + b"]"), sep=".")
    if "t" not in df:
        df.insert(0, "t", times)
    return df


def _frame_transforms(times: list[float], messages: list) -> pd.DataFrame:
    """``foxglove.FrameTransforms`` -> a row per transform."""
    rows = [
        (t, tr.parent_frame_id, tr.child_frame_id, tr.translation.x, tr.translation.y, tr.translation.z, tr.rotation.x, tr.rotation.y, tr.rotation.z, tr.rotation.w)
        for t, message in zip(times, messages)
        for tr in message.transforms
    ]
    return pd.DataFrame(rows, columns=("t", *_TF_COLUMNS))


def _flatten(data: Mapping, prefix: str = "") -> dict:
    """Nested mappings -> one level, keys joined with dots."""
    out = {}
    for key, value in data.items():
        if isinstance(value, Mapping):
            out.update(_flatten(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def _protobuf_frame(schema_name: str, times: list[float], messages: list) -> pd.DataFrame:
    """Other protobuf messages -> flat rows; a message holding a list of poses gives a row per pose, one of line entities (paths) a row per point."""
    rows: list[dict] = []
    for t, message in zip(times, messages):
        data = MessageToDict(message, preserving_proto_field_name=True, always_print_fields_with_no_presence=True)
        items = data.pop("poses", None) if schema_name == "foxglove.PosesInFrame" else None
        entities = data.get("entities") if schema_name == "foxglove.SceneUpdate" else None
        if entities and all(e.get("lines") for e in entities):  # paths drawn as lines: a row per point
            rows.extend({"t": t, "id": e["id"], "frame_id": e["frame_id"], "line": i, **_flatten(p)} for e in entities for i, line in enumerate(e["lines"]) for p in line["points"])
        elif items is None:
            rows.append({"t": t, **_flatten(data)})
        else:
            data.pop("timestamp", None)
            rows.extend({"t": t, **_flatten(data), **_flatten(item)} for item in items)
    return pd.DataFrame(rows)


# --- messages and files -----------------------------------------------------------------------------


def _quote(value: object) -> str:
    """A value read from a file, for a message: its repr, at most about 80 characters (:func:`~dualarm.errors.excerpt`)."""
    return excerpt(repr(value))


_JSON_TYPES = {dict: "an object", list: "a list", str: "a string", bool: "a boolean", int: "a number", float: "a number", type(None): "null"}


def _json_type(value: object) -> str:
    return _JSON_TYPES.get(type(value), type(value).__name__)


def _regular_file(path: Path, what: str) -> os.stat_result:
    """``path``'s status if it is a regular file; looked at before opening it (a FIFO would block the read)."""
    try:
        status = os.stat(path)
    except (OSError, ValueError) as exc:
        raise RecordingError(f"{excerpt(path)}: cannot read the {what}: {cause(exc)}") from None
    if not stat.S_ISREG(status.st_mode):
        raise RecordingError(f"{excerpt(path)}: cannot read the {what}: it is {kind(path)}, not a regular file")
    return status


def _read_bytes(path: Path, what: str) -> bytes:
    """The bytes of the regular file ``path``, opened non-blocking and checked again once open (as :func:`~dualarm.files.read_text` does for text)."""
    _regular_file(path, what)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOCTTY", 0))
        with os.fdopen(fd, "rb") as file:
            if not stat.S_ISREG(os.fstat(file.fileno()).st_mode):
                raise RecordingError(f"{excerpt(path)}: cannot read the {what}: it was replaced by {kind(path)} while being opened")
            return file.read()
    except OSError as exc:
        raise RecordingError(f"{excerpt(path)}: cannot read the {what}: {cause(exc)}") from None


def _json_object(path: Path, what: str) -> dict[str, Any]:
    """The JSON object in ``path`` (``what`` names the file in messages)."""
    text = read_text(path, what, RecordingError)
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        raise RecordingError(f"{excerpt(path)}: not valid JSON ({exc.msg}, line {exc.lineno} column {exc.colno})") from None
    except (ValueError, RecursionError) as exc:  # an integer of more than 4300 digits, nesting too deep
        raise RecordingError(f"{excerpt(path)}: not valid JSON ({excerpt(f'{type(exc).__name__}: {exc}')})") from None
    if not isinstance(value, dict):
        raise RecordingError(f"{excerpt(path)}: holds {_json_type(value)}, not a JSON object")
    return value


# --- manifest.json and metrics.json ----------------------------------------------------------------


class Manifest(BaseModel):
    """The keys of ``manifest.json`` that readers use, with their types; other keys are kept as they are."""

    model_config = ConfigDict(extra="allow", strict=True, frozen=True)

    run_id: Annotated[str, StringConstraints(pattern=f"^{RUN_ID}$")]
    status: Status
    task: Annotated[str, StringConstraints(pattern=f"^{TASK_NAME}$")]
    stages: list[str]
    settings: dict[str, dict[str, Any]]
    error: str | None = None
    task_file: str | None = None
    record: RecordLevel = "full"


_METRICS = TypeAdapter(dict[Annotated[str, StringConstraints(pattern=f"^{METRIC_KEY}$")], Annotated[float, Field(strict=True, allow_inf_nan=False)] | None])
#: What a value that fails a pattern should be, by the key it sits at.
_PATTERNS = {"run_id": "a run id (like 20261121-130501-a1b2c3)", "task": "a task name (letters, digits, '_' and '-')", "[key]": "a metric key <stage>.<name>"}


def _invalid(path: Path, exc: ValidationError) -> RecordingError:
    """The first of pydantic's complaints about ``path``'s content, as one line naming the key."""
    errors = exc.errors()
    error = errors[0]
    loc = error["loc"]
    key = _quote(loc[0]) if loc else "(top level)"
    key += "".join(f"[{_quote(part)}]" for part in loc[1:] if part != "[key]")
    if error["type"] == "missing":
        problem = f"key {key} is missing"
    elif error["type"] == "string_pattern_mismatch":
        problem = f"{'key' if loc[-1] == '[key]' else 'value of ' + key} {_quote(error['input'])} is not {_PATTERNS.get(str(loc[-1]), 'of the right form')}"
    else:
        problem = f"value of {key} is {_json_type(error['input'])} {_quote(error['input'])}: {error['msg'][0].lower()}{error['msg'][1:]}"
    more = len(errors) - 1
    return RecordingError(f"{excerpt(path)}: {problem}" + (f" (and {more} more problems)" if more else ""))


def _manifest(path: Path) -> dict[str, Any]:
    data = _json_object(path, "run manifest")
    try:
        Manifest.model_validate(data)
    except ValidationError as exc:
        raise _invalid(path, exc) from None
    return data


def _metrics(path: Path) -> dict[str, float | None] | None:
    """``metrics.json`` (None when the file does not exist)."""
    if not os.path.lexists(path):
        return None
    data = _json_object(path, "run metrics")
    try:
        return _METRICS.validate_python(data)
    except ValidationError as exc:
        raise _invalid(path, exc) from None


def path_name(value: object, field: Literal["task", "run_id"], directory: Path) -> str:
    """``value``, the ``task`` or ``run_id`` of the run in ``directory``, when it may name a directory: a task name (:data:`TASK_NAME`) or a run id (:data:`RUN_ID`), which hold no ``/`` and are never ``.`` or ``..``.

    Raises:
        RecordingError: it is not, naming the run's manifest.
    """
    if isinstance(value, str) and re.fullmatch(TASK_NAME if field == "task" else RUN_ID, value):
        return value
    raise RecordingError(f"{excerpt(directory / MANIFEST)}: {field} {_quote(value)} is not {_PATTERNS[field]}; it cannot name a directory")


# --- run.mcap --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class VerifiedMcap:
    """A ``run.mcap`` whose CRCs all hold (see :func:`verify_mcap`).

    Attributes:
        path: the file.
        summary: its summary section (schemas, channels, statistics, chunk indexes).
        manifest: the manifest stored in it as MCAP metadata ``manifest`` (key -> value).
        metrics: the values of its ``/metrics`` message, or None when it has none.
    """

    path: Path
    summary: Summary
    manifest: Mapping[str, object]
    metrics: Mapping[str, object] | None


def _encoded(record: DataEnd) -> bytes:
    """A record's bytes as the ``mcap`` library writes them."""
    builder = RecordBuilder()
    record.write(builder)
    return builder.end()


def _verify_crcs(data: bytes) -> None:
    """Check every byte of an MCAP file: magic, record structure, data section CRC, chunk CRCs (the ``mcap`` library's checks), summary CRC and the DataEnd record (here).

    Raises:
        McapError, CRCValidationError, ...: what the library raises, or McapError naming the fault.
    """
    stream = io.BytesIO(data)
    records = list(StreamReader(stream, validate_crcs=True, emit_chunks=True, record_size_limit=len(data)).records)
    if stream.tell() != len(data):
        raise McapError(f"{len(data) - stream.tell()} bytes after the end of the recording")
    if not records or not isinstance(records[0], Header):
        raise McapError("it does not begin with a header record")
    data_ends = [r for r in records if isinstance(r, DataEnd)]
    footer = records[-1]
    if len(data_ends) != 1 or not isinstance(footer, Footer):
        raise McapError(f"{len(data_ends)} DataEnd records, not one: the record structure is damaged")
    chunks = [r for r in records if isinstance(r, Chunk)]
    if data_ends[0].data_section_crc == 0 or footer.summary_crc == 0 or any(c.uncompressed_crc == 0 for c in chunks):
        raise McapError("written without CRCs, so it cannot be verified")
    if footer.summary_start == 0:
        raise McapError("no summary section (its writer never finished)")
    summary_end = len(data) - MAGIC_SIZE - 4  # the summary CRC covers the summary and the footer up to the CRC itself
    if not 0 < footer.summary_start <= summary_end:
        raise McapError("its footer points outside the file")
    if zlib.crc32(data[footer.summary_start : summary_end]) != footer.summary_crc:
        raise McapError("summary section CRC mismatch: the index or statistics were altered after writing")
    data_end = _encoded(data_ends[0])
    if data[footer.summary_start - len(data_end) : footer.summary_start] != data_end:
        raise McapError("damaged DataEnd record (it is not where the footer says the data section ends)")
    for chunk in chunks:  # decompressed and its CRC checked; its records are not parsed, as the CRC covers each of their bytes as written (parsing them in pure Python took 20 s of a reproduction report's 46 s in a profile)
        get_chunk_data_stream(chunk, validate_crc=True)


def _stored_manifest(reader: SeekingReader) -> dict[str, object]:
    found = [m for m in reader.iter_metadata() if m.name == "manifest"]
    if len(found) != 1:
        raise McapError(f"{len(found)} 'manifest' metadata records, not one")
    return {key: json.loads(value) for key, value in found[0].metadata.items()}


def _recorded_metrics(reader: SeekingReader) -> dict[str, object] | None:
    messages = [message for _, _, message in reader.iter_messages(topics=["/metrics"], log_time_order=False)]
    if not messages:
        return None
    if len(messages) > 1:
        raise McapError(f"{len(messages)} /metrics messages, not one")
    payload = json.loads(messages[0].data)
    values = payload.get("values") if isinstance(payload, dict) else None
    if not isinstance(values, dict):
        raise McapError("its /metrics message holds no values")
    return values


def verify_mcap(path: Path) -> VerifiedMcap:
    """Read ``path`` end to end, checking every CRC it carries; return its summary, stored manifest and recorded metrics.

    Raises:
        RecordingError: the file is missing, not a regular file, not MCAP, truncated, unfinished,
            written without CRCs, or any CRC or record does not match (a flipped bit anywhere).
    """
    data = _read_bytes(path, "MCAP recording")
    try:
        _verify_crcs(data)
        reader = SeekingReader(io.BytesIO(data), validate_crcs=True, record_size_limit=len(data))
        summary = reader.get_summary()
        if summary is None or summary.statistics is None:
            raise McapError("no summary statistics (its writer never finished)")
        manifest, metrics = _stored_manifest(reader), _recorded_metrics(reader)
    except CRCValidationError as exc:
        part = "data section" if isinstance(exc.record, DataEnd) else type(exc.record).__name__.lower()
        raise RecordingError(f"{excerpt(path)}: corrupt MCAP recording ({part} CRC mismatch: the file was altered after it was written)") from None
    except EndOfFile:
        raise RecordingError(f"{excerpt(path)}: not a readable MCAP recording (truncated: it ends inside a record; its writer never finished?)") from None
    except InvalidMagic:
        raise RecordingError(f"{excerpt(path)}: not a readable MCAP recording (it does not begin and end with the MCAP magic bytes)") from None
    except Exception as exc:  # any other failure to parse (struct, McapError, JSON, zstd...) is corruption
        raise RecordingError(f"{excerpt(path)}: not a readable MCAP recording ({excerpt(f'{type(exc).__name__}: {exc}')})") from None
    return VerifiedMcap(path=path, summary=summary, manifest=MappingProxyType(manifest), metrics=None if metrics is None else MappingProxyType(metrics))


# --- one run -----------------------------------------------------------------------------------------


def _check_one_run(manifest: Mapping[str, object], mcap: VerifiedMcap) -> None:
    """``manifest.json`` and the manifest stored in ``run.mcap`` agree on task, run id, status, stages and recording level."""
    for key in ("task", "run_id", "status", "stages", "record"):
        stored = mcap.manifest.get(key)
        if stored != manifest.get(key):
            raise RecordingError(f"{excerpt(mcap.path)}: records {key} {_quote(stored)}, but {MANIFEST} says {_quote(manifest.get(key))}: the files are not of one run")


def _same_metric(value: float | None, recorded: object) -> bool:
    if not isinstance(recorded, (int, float)) or isinstance(recorded, bool):
        return value is None and recorded is None
    return (value is None and not math.isfinite(recorded)) or value == recorded


def _check_metrics(path: Path, status: str, metrics: Mapping[str, float | None] | None, recorded: Mapping[str, object] | None, *, in_mcap: bool = True) -> None:
    """``metrics.json`` exists if the run finished and (``in_mcap``: the run has a ``run.mcap``) equals the metrics recorded in ``run.mcap``."""
    if metrics is None:
        if status in FINISHED:
            raise RecordingError(f"{excerpt(path)}: missing, but the run's status is '{status}' (a finished run has its metrics)")
        return
    if not in_mcap:
        return
    if recorded is None:
        raise RecordingError(f"{excerpt(path)}: {MCAP_FILE} records no metrics for this run (status '{status}'): not this run's metrics")
    extra, lacking = sorted(set(metrics) - set(recorded)), sorted(set(recorded) - set(metrics))
    if extra or lacking:
        raise RecordingError(f"{excerpt(path)}: keys differ from the metrics {MCAP_FILE} records (here only: {_quote(extra)}; there only: {_quote(lacking)}): not this run's metrics")
    for key, value in metrics.items():
        if not _same_metric(value, recorded[key]):
            raise RecordingError(f"{excerpt(path)}: {key} = {_quote(value)}, but {MCAP_FILE} records {_quote(recorded[key])}: not this run's metrics")


# --- reading ------------------------------------------------------------------------------------


class McapTopics(Mapping[str, pd.DataFrame]):
    """The topics of one verified MCAP file, each decoded into a DataFrame on first access and kept.

    Columns: ``t`` (motion time [s]), ``rep`` (repetition, 0 where a message has none), ``stage``,
    then one column per message field (nested fields joined with dots: ``position.x``). Rows are in
    log-time order (messages of equal time in the order written).

    Raises:
        RecordingError: a topic's data cannot be decoded or its chunk's CRC no longer holds (at access).
    """

    def __init__(self, mcap: VerifiedMcap) -> None:
        self._path = mcap.path
        statistics = mcap.summary.statistics
        counts = statistics.channel_message_counts if statistics is not None else {}
        self._topics = tuple(dict.fromkeys(c.topic for i, c in sorted(mcap.summary.channels.items()) if counts.get(i, 0) > 0))
        self._frames: dict[str, pd.DataFrame] = {}

    def __getitem__(self, topic: str) -> pd.DataFrame:
        if topic not in self._topics:
            raise KeyError(topic)
        if topic not in self._frames:
            self._frames[topic] = self._read(topic)
        return self._frames[topic]

    def __iter__(self):
        return iter(self._topics)

    def __len__(self) -> int:
        return len(self._topics)

    def _read(self, topic: str) -> pd.DataFrame:
        times: list[float] = []
        payloads: list[bytes] = []
        try:
            with self._path.open("rb") as stream:
                for schema, channel, message in make_reader(stream, validate_crcs=True).iter_messages(topics=[topic], log_time_order=True):
                    times.append(message.log_time / 1e9)
                    payloads.append(message.data)
            if channel.message_encoding == "json":
                df = _json_frame(times, payloads)
            else:
                decode = ProtobufDecoderFactory().decoder_for(channel.message_encoding, schema)
                if decode is None or schema is None:
                    raise McapError(f"no decoder for message encoding {_quote(channel.message_encoding)}")
                messages = [decode(data) for data in payloads]
                if schema.name == "foxglove.FrameTransforms":
                    df = _frame_transforms(times, messages)
                else:
                    df = _protobuf_frame(schema.name, times, messages)
        except Exception as exc:  # any failure to decode (struct, McapError, protobuf, JSON...) is corruption
            raise RecordingError(f"{excerpt(self._path)}: topic {_quote(topic)} is not readable ({excerpt(f'{type(exc).__name__}: {exc}')})") from None
        if "rep" not in df:
            df["rep"] = 0
        df["stage"] = stage_of(topic)
        first = ["t", "rep", "stage"]
        return df[first + [c for c in df.columns if c not in first]]


@dataclass(frozen=True)
class RunData:
    """One run read back.

    Attributes:
        directory: the run directory.
        manifest: manifest.json.
        metrics: metrics.json (``<stage>.<name>`` -> value, None where not finite; empty for a
            run that did not finish).
        topics: topic -> DataFrame (columns ``t``, ``rep``, ``stage``, fields), each topic decoded
            from run.mcap on first access.
    """

    directory: Path
    manifest: Mapping[str, object]
    metrics: Mapping[str, float]
    topics: Mapping[str, pd.DataFrame]

    @property
    def run_id(self) -> str:
        """The run's id."""
        return str(self.manifest.get("run_id", self.directory.name))

    @property
    def status(self) -> str:
        """One of :data:`STATUSES`: ``complete``, ``violated``, ``failed`` or ``running``."""
        return str(self.manifest.get("status"))

    @property
    def task(self) -> str | None:
        """The task's name (None if the manifest has none)."""
        task = self.manifest.get("task")
        return None if task is None else str(task)

    @property
    def stages(self) -> list[str]:
        """The stages the run ran, in order (empty if the manifest has none)."""
        stages = self.manifest.get("stages", [])
        return [str(s) for s in stages] if isinstance(stages, list) else []

    @property
    def violations(self) -> list[str]:
        """The messages of the verdict's violations, in order (empty for a complete run, or a run recorded before verdicts)."""
        violations = self.manifest.get("violations", [])
        return [str(v.get("message", "")) for v in violations if isinstance(v, Mapping)] if isinstance(violations, list) else []

    @property
    def error(self) -> str:
        """A failed run's error ("" otherwise)."""
        return str(self.manifest.get("error") or "")

    @property
    def record(self) -> str:
        """How much of the run was recorded: ``full``, ``ik`` or ``metrics`` (:data:`~dualarm.record.sink.RECORD_LEVELS`; ``full`` for a run recorded before levels)."""
        return str(self.manifest.get("record", "full"))

    @property
    def recorded_stages(self) -> list[str]:
        """The stages whose products the run's recordings hold (:attr:`stages` for a ``full`` run, none for a ``metrics`` run)."""
        return list(recorded_stages(self.record, self.stages))

    def lacks(self) -> str:
        """What the run's files lack at its recording level, for a message ("" for a ``full`` run)."""
        if self.record == "metrics":
            return f"no {MCAP_FILE}, no {RRD_FILE}, no topics: only {MANIFEST} and {METRICS}"
        if self.record != "full":
            return f"{MCAP_FILE} and {RRD_FILE} hold the stages {', '.join(self.recorded_stages) or '(none)'} only, not {', '.join(s for s in self.stages if s not in self.recorded_stages)}"
        return ""

    def setting(self, stage: str, key: str) -> object:
        """The manifest's ``settings[stage][key]`` (None where the run has none)."""
        settings = self.manifest.get("settings")
        of_stage = settings.get(stage) if isinstance(settings, Mapping) else None
        return of_stage.get(key) if isinstance(of_stage, Mapping) else None

    def __getitem__(self, topic: str) -> pd.DataFrame:
        """The DataFrame of ``topic``.

        Raises:
            RecordingError: the run has no such topic (naming its topics, or the recording level
                that left the topic out: a ``metrics`` run, or an ``ik`` run asked for a later stage).
        """
        if topic not in self.topics:
            if self.record == "metrics" or (self.record != "full" and stage_of(topic) in self.stages and stage_of(topic) not in self.recorded_stages):
                raise RecordingError(f"{excerpt(self.directory)}: no topic {_quote(topic)}: the run was recorded with --record {self.record} ({self.lacks()})")
            raise RecordingError(f"{excerpt(self.directory)}: no topic {_quote(topic)} (topics: {', '.join(self.topics)})")
        return self.topics[topic]


def read_run(directory: str | Path) -> RunData:
    """Read one run directory, validating it first (see the module's docstring).

    Raises:
        RecordingError: the directory is missing; a file is missing, not a regular file,
            unreadable or malformed; a CRC of ``run.mcap`` does not hold; or the files are not of
            one run. The message names the file and the fault.
    """
    directory = Path(directory)
    try:
        is_directory = stat.S_ISDIR(os.stat(directory).st_mode)
    except FileNotFoundError:
        raise RecordingError(f"{excerpt(directory)}: no such run directory") from None
    except (OSError, ValueError) as exc:
        raise RecordingError(f"{excerpt(directory)}: cannot read the run directory: {cause(exc)}") from None
    if not is_directory:
        raise RecordingError(f"{excerpt(directory)}: not a directory (a run directory holds {MANIFEST}, {METRICS}, {MCAP_FILE} and {RRD_FILE})")
    manifest = _manifest(directory / MANIFEST)
    if manifest.get("record") == "metrics":
        return _metrics_run(directory, manifest)
    mcap = verify_mcap(directory / MCAP_FILE)
    _check_one_run(manifest, mcap)
    metrics = _metrics(directory / METRICS)
    _check_metrics(directory / METRICS, str(manifest["status"]), metrics, mcap.metrics)
    if _regular_file(directory / RRD_FILE, "Rerun recording").st_size == 0:
        raise RecordingError(f"{excerpt(directory / RRD_FILE)}: empty (not a Rerun recording)")
    return RunData(directory=directory, manifest=MappingProxyType(manifest), metrics=MappingProxyType(cast(dict[str, float], metrics or {})), topics=McapTopics(mcap))


def _metrics_run(directory: Path, manifest: dict[str, Any]) -> RunData:
    """A run recorded with ``--record metrics``: its manifest and metrics, no topics; a recording beside it is refused."""
    for name in (MCAP_FILE, RRD_FILE):
        if os.path.lexists(directory / name):
            raise RecordingError(f"{excerpt(directory / name)}: present, but {MANIFEST} says the run was recorded with --record metrics (no {MCAP_FILE}, no {RRD_FILE}): the files are not of one run")
    metrics = _metrics(directory / METRICS)
    _check_metrics(directory / METRICS, str(manifest["status"]), metrics, None, in_mcap=False)
    return RunData(directory=directory, manifest=MappingProxyType(manifest), metrics=MappingProxyType(cast(dict[str, float], metrics or {})), topics=MappingProxyType({}))


def read_runs(directories: Iterable[str | Path], topics: Iterable[str] | None = None) -> dict[str, pd.DataFrame]:
    """Many runs, concatenated per topic (only ``topics`` when given), with ``run`` (run id) and ``task`` columns added."""
    wanted = None if topics is None else set(topics)
    per_topic: dict[str, list[pd.DataFrame]] = defaultdict(list)
    for directory in directories:
        run = read_run(directory)
        for topic in run.topics:
            if wanted is None or topic in wanted:
                per_topic[topic].append(run[topic].assign(run=run.run_id, task=run.task))
    return {topic: pd.concat(frames, ignore_index=True) for topic, frames in per_topic.items()}
