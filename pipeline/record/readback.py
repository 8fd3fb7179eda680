"""Reading runs back into pandas: the only path reports and analyses use.

:func:`read_run` turns one run directory into a :class:`RunData` holding one DataFrame per MCAP
topic, with columns ``t`` (motion time [s]), ``rep`` (repetition), ``stage`` and one column per
message field (nested fields joined with dots: ``position.x``). :func:`read_runs` concatenates
many runs per topic with ``run`` and ``task`` columns added.
"""

from __future__ import annotations

import json
from collections import defaultdict
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType

import pandas as pd
from google.protobuf.json_format import MessageToDict
from mcap.decoder import DecoderFactory as McapDecoderFactory
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory

from pipeline.errors import RecordingError
from pipeline.record.recorder import STAGE_TOPICS
from pipeline.record.run_dir import MANIFEST, METRICS

_STAGE_OF_FAMILY = {family: stage for stage, family in STAGE_TOPICS.items()}


class _JsonDecoderFactory(McapDecoderFactory):
    """Decodes MCAP messages with ``json`` encoding into Python objects."""

    def decoder_for(self, message_encoding, schema):  # noqa: D102 - mcap interface
        if message_encoding == "json":
            return lambda data: json.loads(data)
        return None


def stage_of(topic: str) -> str:
    """The pipeline stage a topic belongs to (``/task/...`` -> ``path``; ``/tf`` -> ``robot``)."""
    family = "/" + topic.strip("/").split("/")[0]
    if family in _STAGE_OF_FAMILY:
        return _STAGE_OF_FAMILY[family]
    return {"/tf": "robot", "/robot_description": "robot", "/metrics": "metrics"}.get(family, family.strip("/"))


def _flatten(data: Mapping, prefix: str = "") -> dict:
    """Nested mappings -> one level, keys joined with dots."""
    out = {}
    for key, value in data.items():
        if isinstance(value, Mapping):
            out.update(_flatten(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def _rows(schema_name: str, message, log_time_s: float) -> list[dict]:
    """Flat rows of one decoded message; a Foxglove message holding a list of transforms or poses
    gives one row per item."""
    if isinstance(message, dict):
        return [{"t": log_time_s, **_flatten(message)}]
    data = MessageToDict(message, preserving_proto_field_name=True, always_print_fields_with_no_presence=True)
    if schema_name in ("foxglove.FrameTransforms", "foxglove.PosesInFrame"):
        items = data.pop("transforms", None) or data.pop("poses", None) or []
        data.pop("timestamp", None)
        return [{"t": log_time_s, **_flatten(data), **_flatten(item)} for item in items]
    return [{"t": log_time_s, **_flatten(data)}]


@dataclass(frozen=True)
class RunData:
    """One run read back.

    Attributes:
        directory: the run directory.
        manifest: manifest.json.
        metrics: metrics.json (empty for a failed run).
        topics: topic -> DataFrame (columns ``t``, ``rep``, ``stage``, fields).
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
        """``complete`` or ``failed``."""
        return str(self.manifest.get("status"))

    def __getitem__(self, topic: str) -> pd.DataFrame:
        if topic not in self.topics:
            raise RecordingError(f"{self.directory}: no topic '{topic}' (topics: {', '.join(self.topics)})")
        return self.topics[topic]


def _read_json(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        raise RecordingError(f"{path}: missing (not a complete run directory)") from None
    except json.JSONDecodeError as exc:
        raise RecordingError(f"{path}: not valid JSON ({exc.msg}, line {exc.lineno})") from None


def read_mcap(path: Path) -> dict[str, pd.DataFrame]:
    """Every topic of an MCAP file as a DataFrame (columns ``t``, ``rep``, ``stage``, fields)."""
    rows: dict[str, list[dict]] = defaultdict(list)
    try:
        with path.open("rb") as stream:
            reader = make_reader(stream, decoder_factories=[_JsonDecoderFactory(), ProtobufDecoderFactory()])
            for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=True):
                rows[channel.topic].extend(_rows(schema.name if schema else "", decoded, message.log_time / 1e9))
    except FileNotFoundError:
        raise RecordingError(f"{path}: missing (not a complete run directory)") from None
    except Exception as exc:  # any failure to decode (struct, McapError, protobuf, JSON...) is corruption
        raise RecordingError(f"{path}: not a readable MCAP recording ({type(exc).__name__}: {exc})") from None
    frames = {}
    for topic, topic_rows in rows.items():
        df = pd.DataFrame(topic_rows)
        if "rep" not in df:
            df["rep"] = 0
        df["stage"] = stage_of(topic)
        first = ["t", "rep", "stage"]
        frames[topic] = df[first + [c for c in df.columns if c not in first]]
    return frames


def read_run(directory: str | Path) -> RunData:
    """Read one run directory.

    Raises:
        RecordingError: the directory, its manifest or its MCAP file is missing or unreadable.
    """
    directory = Path(directory)
    if not directory.is_dir():
        raise RecordingError(f"{directory}: no such run directory")
    manifest = _read_json(directory / MANIFEST)
    metrics = _read_json(directory / METRICS) if (directory / METRICS).exists() else {}
    topics = read_mcap(directory / "run.mcap")
    return RunData(directory=directory, manifest=MappingProxyType(manifest), metrics=MappingProxyType(metrics), topics=MappingProxyType(topics))


def read_runs(directories: Iterable[str | Path]) -> dict[str, pd.DataFrame]:
    """Many runs, concatenated per topic, with ``run`` (run id) and ``task`` columns added."""
    per_topic: dict[str, list[pd.DataFrame]] = defaultdict(list)
    for directory in directories:
        run = read_run(directory)
        for topic, df in run.topics.items():
            per_topic[topic].append(df.assign(run=run.run_id, task=run.manifest.get("task")))
    return {topic: pd.concat(frames, ignore_index=True) for topic, frames in per_topic.items()}
