"""Task files: one TOML file per experiment, validated on load (see ``tasks/README.md``)."""

from dualarm.tasks.load import Task, load_task
from dualarm.tasks.schema import TaskSpec

__all__ = ["Task", "TaskSpec", "load_task"]
