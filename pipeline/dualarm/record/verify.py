"""A run directory verified before it is read: its files against their schemas, CRCs and each other.

A run that fails any check is a :class:`RecordingError` naming the file and the fault, never a
partial or silently different result:

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
  for a topic the run did not record names the level (:meth:`~dualarm.record.readback.RunData.__getitem__`).
"""

from __future__ import annotations

import io
import json
import math
import os
import re
import stat
import zlib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Annotated, Any, Literal, get_args

from mcap.data_stream import RecordBuilder
from mcap.exceptions import EndOfFile, InvalidMagic, McapError
from mcap.reader import SeekingReader
from mcap.records import Chunk, DataEnd, Footer, Header
from mcap.stream_reader import MAGIC_SIZE, CRCValidationError, StreamReader, get_chunk_data_stream
from mcap.summary import Summary
from pydantic import BaseModel, ConfigDict, Field, StringConstraints, TypeAdapter, ValidationError

from dualarm.errors import RecordingError, excerpt
from dualarm.files import cause, kind, read_text
from dualarm.record.run_dir import MANIFEST
from dualarm.record.sink import RecordLevel

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


def _quote(value: object) -> str:
    """A value read from a file, for a message: its repr, at most about 80 characters.

    See :func:`~dualarm.errors.excerpt`.
    """
    return excerpt(repr(value))


_JSON_TYPES = {
    dict: "an object",
    list: "a list",
    str: "a string",
    bool: "a boolean",
    int: "a number",
    float: "a number",
    type(None): "null",
}


def _json_type(value: object) -> str:
    return _JSON_TYPES.get(type(value), type(value).__name__)


def _regular_file(path: Path, what: str) -> os.stat_result:
    """``path``'s status if it is a regular file.

    Looked at before opening it (a FIFO would block the read).
    """
    try:
        status = os.stat(path)
    except (OSError, ValueError) as exc:
        raise RecordingError(f"{excerpt(path)}: cannot read the {what}: {cause(exc)}") from None
    if not stat.S_ISREG(status.st_mode):
        raise RecordingError(f"{excerpt(path)}: cannot read the {what}: it is {kind(path)}, not a regular file")
    return status


def _read_bytes(path: Path, what: str) -> bytes:
    """The bytes of the regular file ``path``, opened non-blocking and checked again once open.

    As :func:`~dualarm.files.read_text` does for text.
    """
    _regular_file(path, what)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOCTTY", 0))
        with os.fdopen(fd, "rb") as file:
            if not stat.S_ISREG(os.fstat(file.fileno()).st_mode):
                raise RecordingError(
                    f"{excerpt(path)}: cannot read the {what}: it was replaced by {kind(path)} while being opened"
                )
            return file.read()
    except OSError as exc:
        raise RecordingError(f"{excerpt(path)}: cannot read the {what}: {cause(exc)}") from None


def _json_object(path: Path, what: str) -> dict[str, Any]:
    """The JSON object in ``path`` (``what`` names the file in messages)."""
    text = read_text(path, what, RecordingError)
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        raise RecordingError(
            f"{excerpt(path)}: not valid JSON ({exc.msg}, line {exc.lineno} column {exc.colno})"
        ) from None
    except (ValueError, RecursionError) as exc:  # an integer of more than 4300 digits, nesting too deep
        raise RecordingError(f"{excerpt(path)}: not valid JSON ({excerpt(f'{type(exc).__name__}: {exc}')})") from None
    if not isinstance(value, dict):
        raise RecordingError(f"{excerpt(path)}: holds {_json_type(value)}, not a JSON object")
    return value


class ManifestViolation(BaseModel):
    """One of the verdict's violations in ``manifest.json`` (:class:`dualarm.contracts.verdict.Violation`)."""

    model_config = ConfigDict(extra="allow", strict=True, frozen=True)

    check: str
    stage: str
    message: str
    t_s: Annotated[float, Field(strict=True, allow_inf_nan=False)] | None = None


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
    violations: list[ManifestViolation] = []


_METRICS = TypeAdapter(
    dict[
        Annotated[str, StringConstraints(pattern=f"^{METRIC_KEY}$")],
        Annotated[float, Field(strict=True, allow_inf_nan=False)] | None,
    ]
)
#: What a value that fails a pattern should be, by the key it sits at.
_PATTERNS = {
    "run_id": "a run id (like 20261121-130501-a1b2c3)",
    "task": "a task name (letters, digits, '_' and '-')",
    "[key]": "a metric key <stage>.<name>",
}


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
        problem = (
            f"{'key' if loc[-1] == '[key]' else 'value of ' + key} {_quote(error['input'])} "
            f"is not {_PATTERNS.get(str(loc[-1]), 'of the right form')}"
        )
    else:
        problem = (
            f"value of {key} is {_json_type(error['input'])} "
            f"{_quote(error['input'])}: {error['msg'][0].lower()}{error['msg'][1:]}"
        )
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
    """``value``, the ``task`` or ``run_id`` of the run in ``directory``, when it may name a directory.

    A task name (:data:`TASK_NAME`) or a run id (:data:`RUN_ID`), which hold no ``/`` and are never
    ``.`` or ``..``.

    Raises:
        RecordingError: it is not, naming the run's manifest.
    """
    if isinstance(value, str) and re.fullmatch(TASK_NAME if field == "task" else RUN_ID, value):
        return value
    raise RecordingError(
        f"{excerpt(directory / MANIFEST)}: {field} {_quote(value)} "
        f"is not {_PATTERNS[field]}; it cannot name a directory"
    )


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
    """Check every byte of an MCAP file.

    Magic, record structure, data section CRC, chunk CRCs (the ``mcap`` library's checks), summary
    CRC and the DataEnd record (here).

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
    # Each chunk decompressed and its CRC checked; its records are not parsed, as the CRC covers each of their bytes as
    # written (parsing them in pure Python took 20 s of a reproduction report's 46 s in a profile).
    for chunk in chunks:
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
    """Read ``path`` end to end, checking every CRC it carries.

    Returns its summary, stored manifest and recorded metrics.

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
        raise RecordingError(
            f"{excerpt(path)}: corrupt MCAP recording ({part} CRC mismatch: the file was altered after it was written)"
        ) from None
    except EndOfFile:
        raise RecordingError(
            f"{excerpt(path)}: not a readable MCAP recording (truncated: "
            "it ends inside a record; its writer never finished?)"
        ) from None
    except InvalidMagic:
        raise RecordingError(
            f"{excerpt(path)}: not a readable MCAP recording (it does not begin and end with the MCAP magic bytes)"
        ) from None
    except Exception as exc:  # any other failure to parse (struct, McapError, JSON, zstd...) is corruption
        raise RecordingError(
            f"{excerpt(path)}: not a readable MCAP recording ({excerpt(f'{type(exc).__name__}: {exc}')})"
        ) from None
    return VerifiedMcap(
        path=path,
        summary=summary,
        manifest=MappingProxyType(manifest),
        metrics=None if metrics is None else MappingProxyType(metrics),
    )


def _check_one_run(manifest: Mapping[str, object], mcap: VerifiedMcap) -> None:
    """``manifest.json`` and the manifest stored in ``run.mcap`` agree.

    On task, run id, status, stages and recording level.
    """
    for key in ("task", "run_id", "status", "stages", "record"):
        stored = mcap.manifest.get(key)
        if stored != manifest.get(key):
            raise RecordingError(
                f"{excerpt(mcap.path)}: records {key} {_quote(stored)}, but {MANIFEST} "
                f"says {_quote(manifest.get(key))}: the files are not of one run"
            )


def _same_metric(value: float | None, recorded: object) -> bool:
    if not isinstance(recorded, (int, float)) or isinstance(recorded, bool):
        return value is None and recorded is None
    return (value is None and not math.isfinite(recorded)) or value == recorded


def _check_metrics(
    path: Path,
    status: str,
    metrics: Mapping[str, float | None] | None,
    recorded: Mapping[str, object] | None,
    *,
    in_mcap: bool = True,
) -> None:
    """``metrics.json`` exists if the run finished and equals the metrics recorded in ``run.mcap``.

    Equal only when ``in_mcap``: the run has a ``run.mcap``.
    """
    if metrics is None:
        if status in FINISHED:
            raise RecordingError(
                f"{excerpt(path)}: missing, but the run's status is '{status}' (a finished run has its metrics)"
            )
        return
    if not in_mcap:
        return
    if recorded is None:
        raise RecordingError(
            f"{excerpt(path)}: {MCAP_FILE} records no metrics for this run (status '{status}'): not this run's metrics"
        )
    extra, lacking = sorted(set(metrics) - set(recorded)), sorted(set(recorded) - set(metrics))
    if extra or lacking:
        raise RecordingError(
            f"{excerpt(path)}: keys differ from the metrics {MCAP_FILE} records (here "
            f"only: {_quote(extra)}; there only: {_quote(lacking)}): not this run's metrics"
        )
    for key, value in metrics.items():
        if not _same_metric(value, recorded[key]):
            raise RecordingError(
                f"{excerpt(path)}: {key} = {_quote(value)}, but {MCAP_FILE} "
                f"records {_quote(recorded[key])}: not this run's metrics"
            )
