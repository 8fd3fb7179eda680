"""Reading runs back into pandas: the only path reports and analyses use.

:func:`read_run` turns one run directory into a :class:`RunData` holding one DataFrame per MCAP
topic, with columns ``t`` (motion time [s]), ``rep`` (repetition), ``stage`` and one column per
message field (nested fields joined with dots: ``position.x``). A topic is decoded when it is
first used, so reading a run for its metrics or one topic does not decode its ``/tf``.
:func:`read_runs` concatenates many runs per topic with ``run`` and ``task`` columns added.

Reading a run verifies it first (:mod:`dualarm.record.verify`): a run that fails any check is a
:class:`RecordingError` naming the file and the fault, never a partial or silently different result.
"""

from __future__ import annotations

import json
import os
import stat
import warnings
from collections import defaultdict
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any, cast

import pandas as pd
from google.protobuf.json_format import MessageToDict
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory

from dualarm.errors import RecordingError, excerpt
from dualarm.files import cause
from dualarm.record.mcap_sink import STAGE_TOPICS
from dualarm.record.run_dir import MANIFEST, METRICS
from dualarm.record.sink import recorded_stages
from dualarm.record.verify import (
    MCAP_FILE,
    RRD_FILE,
    VerifiedMcap,
    _check_metrics,
    _check_one_run,
    _manifest,
    _metrics,
    _quote,
    _regular_file,
    verify_mcap,
)

_STAGE_OF_FAMILY = {family: stage for stage, family in STAGE_TOPICS.items()}


def stage_of(topic: str) -> str:
    """The pipeline stage a topic belongs to (``/task/...`` -> ``path``; ``/tf`` -> ``robot``)."""
    family = "/" + topic.strip("/").split("/")[0]
    if family in _STAGE_OF_FAMILY:
        return _STAGE_OF_FAMILY[family]
    return {"/tf": "robot", "/robot_description": "robot", "/metrics": "metrics"}.get(family, family.strip("/"))


#: Columns of ``/tf``: one row per transform (the per-transform timestamp equals ``t``).
TF_COLUMNS = (
    "parent_frame_id",
    "child_frame_id",
    "translation.x",
    "translation.y",
    "translation.z",
    "rotation.x",
    "rotation.y",
    "rotation.z",
    "rotation.w",
)


def _json_frame(times: list[float], payloads: list[bytes]) -> pd.DataFrame:
    """JSON messages -> a DataFrame (nested fields joined with dots).

    A message's own ``t`` wins over its log time.
    """
    df = pd.json_normalize(json.loads(b"[" + b",".join(payloads) + b"]"), sep=".")
    if "t" not in df:
        df.insert(0, "t", times)
    return df


def _frame_transforms(times: list[float], messages: list) -> pd.DataFrame:
    """``foxglove.FrameTransforms`` -> a row per transform."""
    rows = [
        (
            t,
            tr.parent_frame_id,
            tr.child_frame_id,
            tr.translation.x,
            tr.translation.y,
            tr.translation.z,
            tr.rotation.x,
            tr.rotation.y,
            tr.rotation.z,
            tr.rotation.w,
        )
        for t, message in zip(times, messages, strict=True)
        for tr in message.transforms
    ]
    return pd.DataFrame(rows, columns=("t", *TF_COLUMNS))


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
    """Other protobuf messages -> flat rows.

    A message holding a list of poses gives a row per pose, one of line entities (paths) a row per
    point.
    """
    rows: list[dict] = []
    for t, message in zip(times, messages, strict=True):
        data = MessageToDict(message, preserving_proto_field_name=True, always_print_fields_with_no_presence=True)
        items = data.pop("poses", None) if schema_name == "foxglove.PosesInFrame" else None
        entities = data.get("entities") if schema_name == "foxglove.SceneUpdate" else None
        if entities and all(e.get("lines") for e in entities):  # paths drawn as lines: a row per point
            rows.extend(
                {"t": t, "id": e["id"], "frame_id": e["frame_id"], "line": i, **_flatten(p)}
                for e in entities
                for i, line in enumerate(e["lines"])
                for p in line["points"]
            )
        elif items is None:
            rows.append({"t": t, **_flatten(data)})
        else:
            data.pop("timestamp", None)
            rows.extend({"t": t, **_flatten(data), **_flatten(item)} for item in items)
    return pd.DataFrame(rows)


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
        self._topics = tuple(
            dict.fromkeys(c.topic for i, c in sorted(mcap.summary.channels.items()) if counts.get(i, 0) > 0)
        )
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
                # B007 does not apply: the last schema and channel of the loop are read after it.
                for schema, channel, message in make_reader(stream, validate_crcs=True).iter_messages(  # noqa: B007
                    topics=[topic], log_time_order=True
                ):
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
            raise RecordingError(
                f"{excerpt(self._path)}: topic {_quote(topic)} is not "
                f"readable ({excerpt(f'{type(exc).__name__}: {exc}')})"
            ) from None
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
        """The messages of the verdict's violations, in order.

        Empty for a complete run, or a run recorded before verdicts.
        """
        violations = self.manifest.get("violations", [])
        return (
            [str(v.get("message", "")) for v in violations if isinstance(v, Mapping)]
            if isinstance(violations, list)
            else []
        )

    @property
    def error(self) -> str:
        """A failed run's error ("" otherwise)."""
        return str(self.manifest.get("error") or "")

    @property
    def record(self) -> str:
        """How much of the run was recorded: ``full``, ``ik`` or ``metrics``.

        See :data:`~dualarm.record.sink.RECORD_LEVELS`; ``full`` for a run recorded before levels.
        """
        return str(self.manifest.get("record", "full"))

    @property
    def recorded_stages(self) -> list[str]:
        """The stages whose products the run's recordings hold.

        :attr:`stages` for a ``full`` run, none for a ``metrics`` run.
        """
        return list(recorded_stages(self.record, self.stages))

    def lacks(self) -> str:
        """What the run's files lack at its recording level, for a message ("" for a ``full`` run)."""
        if self.record == "metrics":
            return f"no {MCAP_FILE}, no {RRD_FILE}, no topics: only {MANIFEST} and {METRICS}"
        if self.record != "full":
            return (
                f"{MCAP_FILE} and {RRD_FILE} hold the stages {', '.join(self.recorded_stages) or '(none)'} "
                f"only, not {', '.join(s for s in self.stages if s not in self.recorded_stages)}"
            )
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
            if self.record == "metrics" or (
                self.record != "full" and stage_of(topic) in self.stages and stage_of(topic) not in self.recorded_stages
            ):
                raise RecordingError(
                    f"{excerpt(self.directory)}: no topic {_quote(topic)}: the run "
                    f"was recorded with --record {self.record} ({self.lacks()})"
                )
            raise RecordingError(
                f"{excerpt(self.directory)}: no topic {_quote(topic)} (topics: {', '.join(self.topics)})"
            )
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
        raise RecordingError(
            f"{excerpt(directory)}: not a directory (a run directory "
            f"holds {MANIFEST}, {METRICS}, {MCAP_FILE} and {RRD_FILE})"
        )
    manifest = _manifest(directory / MANIFEST)
    if manifest.get("record") == "metrics":
        return _metrics_run(directory, manifest)
    mcap = verify_mcap(directory / MCAP_FILE)
    _check_one_run(manifest, mcap)
    metrics = _metrics(directory / METRICS)
    _check_metrics(directory / METRICS, str(manifest["status"]), metrics, mcap.metrics)
    _check_rrd(directory / RRD_FILE, str(manifest["run_id"]))
    return RunData(
        directory=directory,
        manifest=MappingProxyType(manifest),
        metrics=MappingProxyType(cast(dict[str, float], metrics or {})),
        topics=McapTopics(mcap),
    )


def _check_rrd(path: Path, run_id: str) -> None:
    """Refuse ``path`` unless Rerun's own reader opens it whole and it holds the one recording ``run_id``.

    ``rerun.chunk.RrdReader`` decodes the file's footer (a recording dualarm closed has one): a truncated or garbage
    file, or one without a footer, is refused naming Rerun's reason.
    """
    if _regular_file(path, "Rerun recording").st_size == 0:
        raise RecordingError(f"{excerpt(path)}: empty (not a Rerun recording)")
    from rerun.chunk import RrdReader

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # Rerun warns, and reads on, where the footer is missing: a cut file
        try:
            recordings = [entry.recording_id for entry in RrdReader(path).recordings()]
        except (RuntimeError, ValueError, OSError, Warning) as exc:
            reason = str(exc).removeprefix(f"Failed to read RRD file at {path}: ")
            raise RecordingError(f"{excerpt(path)}: Rerun cannot read it ({excerpt(reason, 160)})") from None
    if recordings != [run_id]:
        raise RecordingError(
            f"{excerpt(path)}: holds the recordings {excerpt(', '.join(recordings) or 'none', 80)}, not run {run_id}'s"
        )


def _metrics_run(directory: Path, manifest: dict[str, Any]) -> RunData:
    """A run recorded with ``--record metrics``: its manifest and metrics, no topics.

    A recording beside it is refused.
    """
    for name in (MCAP_FILE, RRD_FILE):
        if os.path.lexists(directory / name):
            raise RecordingError(
                f"{excerpt(directory / name)}: present, but {MANIFEST} says the run was recorded "
                f"with --record metrics (no {MCAP_FILE}, no {RRD_FILE}): the files are not of one run"
            )
    metrics = _metrics(directory / METRICS)
    _check_metrics(directory / METRICS, str(manifest["status"]), metrics, None, in_mcap=False)
    return RunData(
        directory=directory,
        manifest=MappingProxyType(manifest),
        metrics=MappingProxyType(cast(dict[str, float], metrics or {})),
        topics=MappingProxyType({}),
    )


def read_runs(directories: Iterable[str | Path], topics: Iterable[str] | None = None) -> dict[str, pd.DataFrame]:
    """Many runs, concatenated per topic, with ``run`` (run id) and ``task`` columns added.

    Only ``topics`` when given.
    """
    wanted = None if topics is None else set(topics)
    per_topic: dict[str, list[pd.DataFrame]] = defaultdict(list)
    for directory in directories:
        run = read_run(directory)
        for topic in run.topics:
            if wanted is None or topic in wanted:
                per_topic[topic].append(run[topic].assign(run=run.run_id, task=run.task))
    return {topic: pd.concat(frames, ignore_index=True) for topic, frames in per_topic.items()}
