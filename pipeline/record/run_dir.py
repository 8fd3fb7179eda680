"""Run directories: ``<out>/<task>/<run-id>/{run.mcap, run.rrd, manifest.json, metrics.json}``.

A run is written into a hidden temporary directory beside its final place and renamed into place
once finished, so a directory named by a run id is never half-written. A failed run is renamed
too, with ``status: failed`` and the error in its manifest and no ``metrics.json``.
"""

from __future__ import annotations

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
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path

from dualarm.errors import RecordingError

MANIFEST = "manifest.json"
METRICS = "metrics.json"
PACKAGES = ("dualarm", "casadi", "numpy", "scipy", "pybullet", "mcap", "foxglove-sdk", "rerun-sdk", "pandas", "pydantic", "toppra", "ruckig")


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


def write_whole(path: Path, text: str) -> Path:
    """Write ``text`` beside ``path``, then rename it into place: a file that exists is complete. Creates ``path``'s directory; returns ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(f".{path.name}.partial")
    partial.write_text(text)
    os.replace(partial, path)
    return path


def new_run_id() -> str:
    """A run id: UTC start time and 6 random hex digits, e.g. ``20261121-130501-a1b2c3``."""
    return datetime.now(timezone.utc).strftime("%Y%m%d-%H%M%S") + "-" + secrets.token_hex(3)


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


@dataclass
class RunDirectory:
    """A run being written.

    Attributes:
        final: where the run will live.
        staging: the temporary directory written to until :meth:`finish`.
        manifest: the manifest being built (written by :meth:`finish`).
    """

    final: Path
    staging: Path
    manifest: dict[str, object] = field(default_factory=dict)
    _started: float = field(default_factory=time.perf_counter)

    @classmethod
    def create(cls, out_dir: Path, task_name: str, manifest: Mapping[str, object]) -> "RunDirectory":
        """Make the staging directory for a new run of ``task_name`` under ``out_dir``."""
        run_id = new_run_id()
        parent = Path(out_dir) / task_name
        try:
            parent.mkdir(parents=True, exist_ok=True)
            staging = parent / f".{run_id}.partial"
            staging.mkdir()
        except OSError as exc:
            raise RecordingError(f"{parent}: cannot create the run directory ({exc.strerror})") from None
        run = cls(final=parent / run_id, staging=staging)
        run.manifest = {"run_id": run_id, "status": "running", "started_at": _now(), **manifest}
        return run

    @property
    def run_id(self) -> str:
        """The run's id (its directory name)."""
        return self.final.name

    def conclude(self, error: str | None) -> None:
        """Fix the run's status (``complete`` or ``failed`` with ``error``) and end time in the manifest."""
        self.manifest["status"] = "failed" if error else "complete"
        self.manifest["error"] = error
        self.manifest["finished_at"] = _now()
        self.manifest["wall_time_s"] = round(time.perf_counter() - self._started, 3)

    def finish(self, metrics: Mapping[str, float] | None) -> Path:
        """Write manifest.json (and metrics.json if the run is complete) and move the run into place."""
        if "finished_at" not in self.manifest:
            self.conclude(None)
        if self.manifest["status"] == "complete" and metrics is not None:
            clean = {k: (v if math.isfinite(v) else None) for k, v in metrics.items()}
            (self.staging / METRICS).write_text(json.dumps(clean, indent=2, sort_keys=True) + "\n")
        (self.staging / MANIFEST).write_text(json.dumps(self.manifest, indent=2) + "\n")
        self.staging.rename(self.final)
        return self.final

    def discard(self) -> None:
        """Remove the staging directory (used only when even a failed run cannot be written)."""
        shutil.rmtree(self.staging, ignore_errors=True)
