"""Run directories, and every output directory.

A run directory:
``<out>/<task>/<run-id>/{run.mcap, run.rrd, foxglove-layout.json, manifest.json, metrics.json}``.

A run recorded with ``--record metrics`` holds only ``manifest.json`` and ``metrics.json``
(:data:`~dualarm.record.sink.RECORD_LEVELS`).

A run is written into a hidden temporary directory beside its final place and renamed into place
once finished, so a directory named by a run id is never half-written. A failed run is renamed
too, with ``status: failed`` and the error in its manifest and no ``metrics.json``.

No command deletes or overwrites a file it did not write. Every command calls
:func:`claim_output_dir` before it writes into a directory: a directory dualarm makes carries a
marker (:data:`MARKER`) naming its kind, and an existing directory is reused only when its marker
names the kind and every entry in it is one dualarm writes there (:data:`KINDS`); anything else is
refused, naming the entry. A recordings directory is the exception that needs none: runs are only
ever added to it under new names, so it takes any directory, and what it holds besides runs is
left alone. A claimed directory is locked while the command writes (``fcntl.flock``): a second
command into it is refused; runs may share a recordings directory.
"""

from __future__ import annotations

import contextlib
import fcntl
import fnmatch
import hashlib
import json
import math
import os
import platform
import secrets
import shutil
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import TYPE_CHECKING

from dualarm.errors import InvalidArgumentError, OutputError, excerpt

if TYPE_CHECKING:
    from dualarm.contracts.verdict import Verdict

MANIFEST = "manifest.json"
METRICS = "metrics.json"
PACKAGES = (
    "dualarm",
    "casadi",
    "numpy",
    "scipy",
    "pybullet",
    "mcap",
    "foxglove-sdk",
    "rerun-sdk",
    "pandas",
    "pydantic",
    "toppra",
    "ruckig",
)


def sha256_file(path: Path) -> str:
    """SHA-256 of a file's bytes."""
    return hashlib.sha256(path.read_bytes()).hexdigest()


def package_versions() -> dict[str, str]:
    """Installed versions of the packages a run depends on."""
    out = {"python": platform.python_version()}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def write_whole(path: Path, text: str | bytes) -> Path:
    """Write ``text`` (or bytes) beside ``path``, then rename it into place.

    A file that exists is complete. Creates ``path``'s directory; returns ``path``.

    Nothing is left beside ``path`` when the write fails or is interrupted.

    Raises:
        OutputError: the system refuses the write (naming ``path`` and the reason: no space, no permission, ...).
    """
    partial = path.with_name(f".{path.name}.partial")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise OutputError(f"{excerpt(path.parent)}: exists and is not a directory", str(path.parent)) from None
    except OSError as exc:
        raise _os_error(path.parent, "cannot create the directory", exc) from None
    try:
        partial.write_bytes(text) if isinstance(text, bytes) else partial.write_text(text)
        os.replace(partial, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            partial.unlink(missing_ok=True)
        if isinstance(exc, OSError):
            raise _os_error(path, "cannot write", exc) from None
        raise
    return path


#: The file dualarm writes into every output directory it makes (or finds empty); its first line
#: is ``dualarm <kind>``.
MARKER = ".dualarm"
#: Markers of earlier versions: name -> kind.
LEGACY_MARKERS = {".dualarm-reproduction": "reproduction"}
#: Foxglove's layout of a run, written beside its ``run.mcap``.
FOXGLOVE_LAYOUT = "foxglove-layout.json"
#: The files of a run directory (a run recorded below ``full`` holds some of them).
RUN_FILES = ("run.mcap", "run.rrd", FOXGLOVE_LAYOUT, MANIFEST, METRICS)
#: What a write interrupted half-way leaves beside ``name`` (:func:`write_whole`, a run's staging directory).
PARTIAL = ".{}.partial"


@dataclass(frozen=True)
class Layout:
    """What dualarm writes into a directory of one kind.

    Attributes:
        files: name patterns (``fnmatch``) of the files it writes there, besides the marker; the
            :data:`PARTIAL` of each is dualarm's too.
        dirs: name pattern -> the subdirectory's layout, or a kind's name for a subdirectory that
            carries its own marker.
        add_only: dualarm only adds entries under new names (exclusive ``mkdir``) and never deletes
            or rewrites one, so an entry it did not write can come to no harm and does not stop it.
            Several processes may add to the directory at once.
    """

    files: tuple[str, ...] = ()
    dirs: Mapping[str, Layout | str] = field(default_factory=dict)
    add_only: bool = False


_RUN = Layout(files=RUN_FILES)
_RUN_ID = "????????-??????-??????"
_TASK = Layout(dirs={_RUN_ID: _RUN, PARTIAL.format(_RUN_ID): _RUN})
#: What ``study report`` writes into a study's directory, and the digests of them it writes last
#: (:mod:`dualarm.study.report`).
STUDY_REPORT_FILES = (
    "report.md",
    "methods.csv",
    "features.csv",
    "logit.csv",
    "methods.png",
    "features.png",
    "deviations.png",
)
STUDY_REPORT_DIGESTS = "report.sha256"
#: Every kind of output directory and what dualarm writes into it.
#:
#: - ``recordings`` (``run --out``, ``plan --recordings``, a consistency's or a reproduction's
#:   ``runs/``): ``<task>/<run-id>/`` trees, added beside the others and never deleted; an entry
#:   dualarm did not write is left alone and does not stop a run. An existing directory without
#:   the marker is used too (the repository's ``recordings/`` holds ``.gitkeep``), unmarked.
#: - ``plan``, ``consistency``, ``analysis``, ``report``: rewritten in place by the next command into them.
#: - ``reproduction``: emptied by the next reproduction, after checking at every depth that it
#:   holds only what dualarm writes there.
#:
#: A writer that adds a file to one of these directories adds its name here, or the next command
#: into the directory refuses it as foreign.
KINDS: Mapping[str, Layout] = {
    "recordings": Layout(dirs={"*": _TASK}, add_only=True),
    "plan": Layout(files=("plan_trials.csv", "plan_summary.json")),
    "consistency": Layout(
        files=("consistency.csv", "consistency.md", "joints_*.png", "arm_angle.png"), dirs={"runs": "recordings"}
    ),
    "analysis": Layout(files=("analysis.csv", "repetitions.csv", "analysis.md", "joints_*.png", "arm_angle.png")),
    "report": Layout(
        files=(
            "summary.md",
            "hand_errors.png",
            "joints_vs_bounds.png",
            "velocities_vs_bounds.png",
            "bound_profiles.png",
            "*_excursions.csv",
            "runs.csv",
            "runs.md",
            "report.md",
            "ik_hand_errors.png",
            "tracking_errors.png",
            "limit_ratios.png",
            "arm_angle_*.png",
            "joints_*.png",
        ),
        dirs={"*": "report"},
    ),
    "study": Layout(
        files=(
            "study.json",
            "trials.parquet",
            STUDY_REPORT_DIGESTS,
            *STUDY_REPORT_FILES,
        ),
        dirs={"parts": Layout(files=("trial-*.parquet",)), "tasks": Layout(files=("*.toml",)), "runs": "recordings"},
    ),
    "reproduction": Layout(
        files=("parts.json", "report.md", "table_i.json", *LEGACY_MARKERS),
        dirs={
            "runs": "recordings",
            "consistency": Layout(dirs={"*": "consistency"}),
            "plan": Layout(dirs={"*": "plan"}),
            "figures": Layout(files=("*.png",), dirs={"*": "report"}),
        },
    ),
}


class OutputDir:
    """An output directory claimed by :func:`claim_output_dir`.

    It is locked (``fcntl.flock`` on the directory: shared for an add-only kind, else exclusive)
    until :meth:`release`, the end of a ``with`` block, or until this object is dropped.

    Attributes:
        path: the directory.
        kind: its kind (:data:`KINDS`).
    """

    def __init__(self, path: Path, kind: str, fd: int) -> None:
        self.path, self.kind, self._fd = path, kind, fd

    def release(self) -> None:
        """Unlock the directory (again: nothing)."""
        fd, self._fd = self._fd, -1
        if fd >= 0:
            os.close(fd)  # closing the last descriptor of the open file releases its flock

    def __enter__(self) -> OutputDir:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    def __del__(self) -> None:
        self.release()

    def clear(self) -> None:
        """Delete everything in the directory but its marker.

        Once every entry at every depth is one dualarm writes there and no directory inside is in
        use.

        Raises:
            OutputError: an entry dualarm does not write (nothing is deleted), or a directory inside
                locked by another process.
        """
        held: list[int] = []
        try:
            foreign = _foreign(self.path, KINDS[self.kind], strict=True, held=held)
            if foreign is not None:
                raise _foreign_error(self.path, self.kind, foreign)
            _write_marker(self.path, self.kind)
            for entry in os.scandir(self.path):
                if entry.name != MARKER:
                    shutil.rmtree(entry.path) if entry.is_dir(follow_symlinks=False) else os.unlink(entry.path)
        except OSError as exc:
            raise _os_error(self.path, "cannot empty the directory", exc) from None
        finally:
            for fd in held:
                os.close(fd)


def claim_output_dir(path: str | Path, kind: str) -> OutputDir:
    """Make or reuse ``path`` as an output directory of ``kind``, locked.

    Every command calls this before it writes there.

    A missing directory is made (with its parents) and marked (:data:`MARKER`); an empty one is
    marked. An existing one is reused only when its marker names ``kind`` and every entry in it is
    one dualarm writes into such a directory (:data:`KINDS`) -- except that an add-only kind
    (recordings) takes any directory and leaves what it did not write alone. The lock is held while
    the returned :class:`OutputDir` lives.

    Raises:
        InvalidArgumentError: an unknown ``kind``.
        OutputError: an empty path or one with a NUL byte; a path the system refuses (a regular
            file, a path through a file, too long, no permission); a directory dualarm did not make
            or that holds an entry it does not write (named); a directory locked by another process.
    """
    if kind not in KINDS:
        raise InvalidArgumentError(
            "kind", f"unknown kind of output directory '{excerpt(kind)}' (kinds: {', '.join(KINDS)})"
        )
    layout = KINDS[kind]
    target = _output_path(path)
    _make(target, kind)
    try:
        fd = os.open(target, os.O_RDONLY | os.O_DIRECTORY)
    except OSError as exc:
        raise _os_error(target, "cannot open the directory", exc) from None
    claimed = OutputDir(target, kind, fd)
    try:
        fcntl.flock(fd, (fcntl.LOCK_SH if layout.add_only else fcntl.LOCK_EX) | fcntl.LOCK_NB)
    except BlockingIOError:
        claimed.release()
        raise OutputError(
            f"{excerpt(target)}: in use by another dualarm process "
            "(locked); wait for it to end or give another output directory",
            str(target),
        ) from None
    try:
        _check(target, kind, layout)
    except BaseException:
        claimed.release()
        raise
    return claimed


def _output_path(path: str | Path) -> Path:
    text = os.fspath(path)
    if not text.strip():
        raise OutputError("the output path is empty; give a directory (e.g. --out DIR)")
    if "\0" in text:
        raise OutputError(f"{excerpt(text)}: a path cannot hold a NUL byte", text)
    return Path(text)


def _os_error(path: Path, doing: str, exc: OSError) -> OutputError:
    """One line naming ``path`` and the system's reason."""
    return OutputError(f"{excerpt(path)}: {doing} ({exc.strerror or type(exc).__name__})", str(path))


def _make(target: Path, kind: str) -> None:
    """Make ``target`` and its marker if it does not exist."""
    try:
        target.mkdir(parents=True)
    except FileExistsError:
        if not target.is_dir():
            raise OutputError(
                f"{excerpt(target)}: exists and is not a directory; give a directory", str(target)
            ) from None
        return
    except OSError as exc:
        raise _os_error(target, "cannot create the directory", exc) from None
    try:
        _write_marker(target, kind)
    except OSError as exc:
        raise _os_error(target / MARKER, "cannot write", exc) from None


def _write_marker(directory: Path, kind: str) -> None:
    text = (
        f"dualarm {kind}\nwritten by dualarm: it writes into this directory "
        "again only if it holds nothing else than what dualarm writes there.\n"
    )
    marker = directory / MARKER
    if not marker.is_file() or _marker_kind(directory) != kind:
        write_whole(marker, text)


def _marker_kind(directory: Path) -> str | None:
    """The kind the marker of ``directory`` names ("" for an unreadable marker), or None without one."""
    for name, legacy in ((MARKER, None), *LEGACY_MARKERS.items()):
        marker = directory / name
        if marker.is_file() and not marker.is_symlink():
            if legacy is not None:
                return legacy
            try:
                words = marker.read_text(errors="replace").split("\n", 1)[0].split()
            except OSError:
                return ""
            return words[1] if len(words) == 2 and words[0] == "dualarm" else ""
    return None


def _check(target: Path, kind: str, layout: Layout) -> None:
    """Refuse ``target`` unless dualarm may write there as ``kind`` (see :func:`claim_output_dir`)."""
    try:
        marked = _marker_kind(target)
        entries = sorted(os.listdir(target))
        if marked is None and not entries:
            _write_marker(target, kind)
            return
        if marked is None and not layout.add_only:
            raise OutputError(
                f"{excerpt(target)}: not a {kind} directory made by dualarm (no {MARKER} marker) "
                f"and not empty: it holds '{excerpt(entries[0])}'; give an empty or new directory",
                str(target),
            )
        if marked is not None and marked != kind:
            raise OutputError(
                f"{excerpt(target)}: not a {kind} directory (its {MARKER} "
                f"marker says '{excerpt(marked)}'); give another directory",
                str(target),
            )
        foreign = _foreign(target, layout, strict=False, held=[])
    except OSError as exc:
        raise _os_error(target, "cannot read the directory", exc) from None
    if foreign is not None:
        raise _foreign_error(target, kind, foreign)


def _foreign_error(target: Path, kind: str, foreign: Path) -> OutputError:
    return OutputError(
        f"{excerpt(target)}: holds '{excerpt(foreign.relative_to(target))}', which dualarm "
        f"does not write into a {kind} directory; move it away or give another directory",
        str(target),
    )


def _match(name: str, patterns: Mapping[str, Layout | str] | tuple[str, ...]) -> Layout | str | None:
    for pattern in patterns:
        if fnmatch.fnmatchcase(name, pattern):
            return patterns[pattern] if isinstance(patterns, Mapping) else pattern
    return None


def _foreign(directory: Path, layout: Layout, *, strict: bool, held: list[int]) -> Path | None:
    """The first entry under ``directory`` that dualarm does not write there, or None.

    Sorted, depth first.

    Outside ``strict`` (reuse), an add-only directory accepts anything; in ``strict`` (before
    deleting) every entry must be dualarm's, and each marked directory inside is locked
    exclusively (its descriptor appended to ``held``).

    Raises:
        OutputError: a marked directory inside is locked by another process.
    """
    if layout.add_only and not strict:
        return None
    for entry in sorted(os.scandir(directory), key=lambda e: e.name):
        path = Path(entry.path)
        if entry.is_symlink():
            return path  # dualarm writes no links
        if entry.is_file():
            ours = (MARKER, *layout.files)
            if (
                _match(entry.name, ours) is not None
                or _match(entry.name, tuple(PARTIAL.format(p) for p in ours)) is not None
            ):
                continue
            return path
        sub = _match(entry.name, layout.dirs) if entry.is_dir() else None
        if sub is None:
            return path
        if isinstance(sub, str):
            if _marker_kind(path) != sub:
                return path
            if strict:
                _lock_inside(path, held)
            sub = KINDS[sub]
        found = _foreign(path, sub, strict=strict, held=held)
        if found is not None:
            return found
    return None


def _lock_inside(path: Path, held: list[int]) -> None:
    fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
    held.append(fd)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        raise OutputError(
            f"{excerpt(path)}: in use by another dualarm process (locked); wait for it to end", str(path)
        ) from None


def new_run_id() -> str:
    """A run id: UTC start time and 6 random hex digits, e.g. ``20261121-130501-a1b2c3``."""
    return datetime.now(UTC).strftime("%Y%m%d-%H%M%S") + "-" + secrets.token_hex(3)


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


#: A staging directory no process holds (its writer was killed: SIGKILL, a power cut) and unchanged for this long is
#: removed by the next run into the recordings directory [s]; the age covers the moment between its ``mkdir`` and
#: its writer's lock.
STALE_STAGING_S = 60.0


def _remove_stale_staging(recordings: Path) -> None:
    """Remove the staging directories in ``recordings/<task>/`` of writers gone (:data:`STALE_STAGING_S`).

    A writer holds an exclusive ``flock`` on its staging directory until it renames it into place; the system
    releases it when the process ends, however it ends. What cannot be read or removed is left as it is.
    """
    pattern = PARTIAL.format(_RUN_ID)
    with contextlib.suppress(OSError):
        for task in os.scandir(recordings):
            if not task.is_dir(follow_symlinks=False):
                continue
            with contextlib.suppress(OSError):
                for entry in os.scandir(task.path):
                    if entry.is_dir(follow_symlinks=False) and fnmatch.fnmatchcase(entry.name, pattern):
                        _remove_if_stale(Path(entry.path))


def _remove_if_stale(staging: Path) -> None:
    with contextlib.suppress(OSError):
        fd = os.open(staging, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # BlockingIOError (an OSError): its writer is running
            if time.time() - os.fstat(fd).st_mtime > STALE_STAGING_S:
                shutil.rmtree(staging)
        finally:
            os.close(fd)


@dataclass
class RunDirectory:
    """A run being written.

    Attributes:
        final: where the run will live.
        staging: the temporary directory written to until :meth:`finish`, locked (``flock``, exclusive) until then:
            the next run removes a staging directory no process holds (:func:`_remove_stale_staging`).
        manifest: the manifest being built (written by :meth:`finish`).
        output: the recordings directory, locked (shared) while this object lives.
    """

    final: Path
    staging: Path
    manifest: dict[str, object] = field(default_factory=dict)
    _started: float = field(default_factory=time.perf_counter)
    output: OutputDir | None = None
    _lock: int = -1

    @classmethod
    def create(cls, out_dir: Path, task_name: str, manifest: Mapping[str, object]) -> RunDirectory:
        """Make the staging directory for a new run of ``task_name`` under ``out_dir``.

        ``out_dir`` is claimed as a recordings directory (:func:`claim_output_dir`) and stays
        locked, shared with other runs, while the returned object lives (its ``output``). The run
        gets an id no entry of ``out_dir/<task>`` has: nothing there is replaced.

        Raises:
            InvalidArgumentError: a task name that is not one path component.
            OutputError: ``out_dir`` cannot be used, or the run directory cannot be made.
        """
        if task_name in ("", ".", "..") or "/" in task_name or os.sep in task_name or "\0" in task_name:
            raise InvalidArgumentError("task_name", f"'{excerpt(task_name)}' is not a directory name")
        output = claim_output_dir(out_dir, "recordings")
        _remove_stale_staging(output.path)
        parent = output.path / task_name
        try:
            parent.mkdir(exist_ok=True)
            while True:
                run_id = new_run_id()
                staging = parent / PARTIAL.format(run_id)
                if not (parent / run_id).exists() and not staging.exists():
                    with contextlib.suppress(FileExistsError):  # another run took this id meanwhile
                        staging.mkdir()
                        break
        except OSError as exc:
            raise _os_error(parent, "cannot create the run directory", exc) from None
        try:
            run = cls(final=parent / run_id, staging=staging, output=output)
            run._lock = os.open(staging, os.O_RDONLY | os.O_DIRECTORY)
            fcntl.flock(run._lock, fcntl.LOCK_EX)
            run.manifest = {"run_id": run_id, "status": "running", "started_at": _now(), **manifest}
        except BaseException as exc:  # interrupted: no hidden staging directory is left
            shutil.rmtree(staging, ignore_errors=True)
            if isinstance(exc, OSError):
                raise _os_error(staging, "cannot lock the run directory", exc) from None
            raise
        return run

    @property
    def run_id(self) -> str:
        """The run's id (its directory name)."""
        return self.final.name

    def conclude(self, verdict: Verdict) -> None:
        """Fix the run's verdict and end time in the manifest.

        The verdict: ``status`` (complete, violated or failed), ``error``, ``violations``, each with
        its check, stage, message and time.
        """
        self.manifest["status"] = verdict.status
        self.manifest["error"] = verdict.error
        self.manifest["violations"] = [v.as_record() for v in verdict.violations]
        self.manifest["finished_at"] = _now()
        self.manifest["wall_time_s"] = round(time.perf_counter() - self._started, 3)

    def finish(self, metrics: Mapping[str, float] | None) -> Path:
        """Write manifest.json (and metrics.json if the run finished) and move the run into place.

        The run finished: complete or violated.
        """
        if "finished_at" not in self.manifest:
            from dualarm.contracts.verdict import Verdict

            self.conclude(Verdict("complete"))
        if self.manifest["status"] in ("complete", "violated") and metrics is not None:
            clean = {k: (v if math.isfinite(v) else None) for k, v in metrics.items()}
            (self.staging / METRICS).write_text(json.dumps(clean, indent=2, sort_keys=True) + "\n")
        (self.staging / MANIFEST).write_text(json.dumps(self.manifest, indent=2) + "\n")
        self.staging.rename(self.final)
        self._unlock()
        return self.final

    def discard(self) -> None:
        """Remove the staging directory (used only when even a failed run cannot be written)."""
        shutil.rmtree(self.staging, ignore_errors=True)
        self._unlock()

    def _unlock(self) -> None:
        fd, self._lock = self._lock, -1
        if fd >= 0:
            os.close(fd)

    def __del__(self) -> None:
        self._unlock()
