"""Reading runs back into pandas: the only path reports and analyses use.

:func:`read_run` turns one run directory into a :class:`RunData` holding one DataFrame per MCAP
topic, with columns ``t`` (motion time [s]), ``rep`` (repetition), ``stage`` and one column per
message field (nested fields joined with dots: ``position.x``). A topic is decoded when it is
first used, so reading a run for its metrics or one topic does not decode its ``/tf``.
:func:`read_runs` concatenates many runs per topic with ``run`` and ``task`` columns added.
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
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory

from dualarm.errors import RecordingError
from dualarm.record.recorder import STAGE_TOPICS
from dualarm.record.run_dir import MANIFEST, METRICS

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
    """Other protobuf messages -> flat rows; a message holding a list of poses or entities gives a row per item."""
    rows = []
    for t, message in zip(times, messages):
        data = MessageToDict(message, preserving_proto_field_name=True, always_print_fields_with_no_presence=True)
        items = data.pop("poses", None) if schema_name == "foxglove.PosesInFrame" else None
        if items is None:
            rows.append({"t": t, **_flatten(data)})
        else:
            data.pop("timestamp", None)
            rows.extend({"t": t, **_flatten(data), **_flatten(item)} for item in items)
    return pd.DataFrame(rows)


class McapTopics(Mapping[str, pd.DataFrame]):
    """The topics of one MCAP file, each decoded into a DataFrame on first access and kept.

    Columns: ``t`` (motion time [s]), ``rep`` (repetition, 0 where a message has none), ``stage``,
    then one column per message field (nested fields joined with dots: ``position.x``). Rows are in
    log-time order (messages of equal time in the order written).

    Raises:
        RecordingError: the file is missing, unfinished or not MCAP (at construction), or a
            topic's data cannot be decoded (at access).
    """

    def __init__(self, path: Path) -> None:
        self._path = path
        try:
            with path.open("rb") as stream:
                summary = make_reader(stream).get_summary()
        except FileNotFoundError:
            raise RecordingError(f"{path}: missing (not a complete run directory)") from None
        except Exception as exc:  # any failure to read the summary (struct, McapError...) is corruption
            raise RecordingError(f"{path}: not a readable MCAP recording ({type(exc).__name__}: {exc})") from None
        if summary is None or summary.statistics is None:
            raise RecordingError(f"{path}: not a readable MCAP recording (no summary: its writer never finished)")
        counts = summary.statistics.channel_message_counts
        self._topics = tuple(dict.fromkeys(c.topic for i, c in sorted(summary.channels.items()) if counts.get(i, 0) > 0))
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
                for schema, channel, message in make_reader(stream).iter_messages(topics=[topic], log_time_order=True):
                    times.append(message.log_time / 1e9)
                    payloads.append(message.data)
            if channel.message_encoding == "json":
                df = _json_frame(times, payloads)
            else:
                decode = ProtobufDecoderFactory().decoder_for(channel.message_encoding, schema)
                if decode is None or schema is None:
                    raise McapError(f"no decoder for message encoding '{channel.message_encoding}'")
                messages = [decode(data) for data in payloads]
                if schema.name == "foxglove.FrameTransforms":
                    df = _frame_transforms(times, messages)
                else:
                    df = _protobuf_frame(schema.name, times, messages)
        except Exception as exc:  # any failure to decode (struct, McapError, protobuf, JSON...) is corruption
            raise RecordingError(f"{self._path}: topic {topic} is not readable ({type(exc).__name__}: {exc})") from None
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
        metrics: metrics.json (empty for a failed run).
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
        """``complete`` or ``failed``."""
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

    def setting(self, stage: str, key: str) -> object:
        """The manifest's ``settings[stage][key]`` (None where the run has none)."""
        settings = self.manifest.get("settings")
        of_stage = settings.get(stage) if isinstance(settings, Mapping) else None
        return of_stage.get(key) if isinstance(of_stage, Mapping) else None

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
    topics = McapTopics(directory / "run.mcap")
    return RunData(directory=directory, manifest=MappingProxyType(manifest), metrics=MappingProxyType(metrics), topics=topics)


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
