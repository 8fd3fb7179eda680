"""Task files: one TOML file per experiment, validated on load (see ``tasks/README.md``).

The names below load their module on first use, so that the schema (:mod:`.schema`) imports
without the kinematics that loading a task needs (:mod:`.load`).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from dualarm.tasks.load import load_task
    from dualarm.tasks.schema import TaskSpec
    from dualarm.tasks.task import Task

__all__ = ["Task", "TaskSpec", "load_task"]
_MODULE = {"Task": "dualarm.tasks.task", "load_task": "dualarm.tasks.load", "TaskSpec": "dualarm.tasks.schema"}


def __getattr__(name: str) -> object:
    if name not in _MODULE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(_MODULE[name]), name)
