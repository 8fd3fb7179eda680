"""The robots and paper tasks shipped with dualarm, and how a bare name finds them.

In an installed wheel they are the copies inside the package (``dualarm/data/robots``,
``dualarm/data/tasks``); in a checkout (an editable install) the repository's top-level ``robots/``
and ``tasks/`` folders, beside the source root ``pipeline/``. Either way they are found from this
package's own location, never from the working directory.

The rule for names, used by :func:`dualarm.load_task`, :func:`dualarm.load_robot` and the CLI:

- a task given as a path that exists is that file; otherwise a bare name (``triangle`` or
  ``triangle.toml``, no directory part) is the shipped task of that name;
- a task's ``robot`` key is a directory relative to the task file; if there is none and the value is
  a bare name (``humanoid``), it is the shipped robot of that name. The same holds for
  :func:`dualarm.load_robot`, relative to the working directory.
"""

from __future__ import annotations

from importlib.resources import as_file, files
from pathlib import Path

from dualarm.files import DIRECTORY, REGULAR_FILE, kind


def _folder(name: str) -> Path:
    with as_file(files(__name__)) as here:  # a real directory for a checkout and for a wheel
        inside = Path(here) / name
        # In a checkout this file is pipeline/dualarm/data/__init__.py and the data is at the top.
        return inside if inside.is_dir() else Path(here).parents[2] / name


def robots_dir() -> Path:
    """The folder of the shipped robots (one sub-folder per robot)."""
    return _folder("robots")


def tasks_dir() -> Path:
    """The folder of the shipped task files."""
    return _folder("tasks")


def shipped_tasks() -> tuple[str, ...]:
    """Names of the shipped tasks, sorted (``ball_game``, ``bowl_grasp``, ...)."""
    return tuple(sorted(p.stem for p in tasks_dir().glob("*.toml")))


def shipped_robots() -> tuple[str, ...]:
    """Names of the shipped robots, sorted."""
    return tuple(sorted(p.name for p in robots_dir().iterdir() if (p / "robot.toml").is_file()))


def _bare(name: str) -> bool:
    return bool(name) and Path(name).name == name and name not in (".", "..")


def find_task(path: str | Path) -> Path:
    """``path`` if it exists, else the shipped task a bare name names, else ``path`` unchanged.

    A bare name: ``triangle``, ``triangle.toml``. ``path`` unchanged so that loading it reports why
    it cannot be read.

    Never raises: a path the OS refuses to look at (a NUL byte, a name too long, a symlink loop)
    counts as not existing.
    """
    given = Path(path)
    if kind(given) is not None or not _bare(str(path)):
        return given
    shipped = tasks_dir() / (given.name if given.suffix == ".toml" else f"{given.name}.toml")
    return shipped if kind(shipped) == REGULAR_FILE else given


def find_robot(path: str | Path, relative_to: Path | None = None) -> Path:
    """The robot directory ``path`` if it exists, else the shipped robot a bare name names.

    ``path`` is relative to ``relative_to`` if given; else the directory as given.

    Never raises, as :func:`find_task`.
    """
    given = Path(path) if relative_to is None else (Path(relative_to) / path)
    if kind(given) == DIRECTORY or not _bare(str(path)):
        return given
    shipped = robots_dir() / str(path)
    return shipped if kind(shipped) == DIRECTORY else given
