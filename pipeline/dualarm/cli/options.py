"""Checks of the command line's arguments before any work, and the helpers several commands share."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer

from dualarm.errors import DualarmError, excerpt

#: Largest planning timeout [s].
MAX_TIMEOUT_S = 86_400.0
#: Largest hand position coordinate of ``ik srs --pose`` [m] and largest angle [rad].
MAX_POSITION_M, MAX_ANGLE_RAD = 1e3, 1e3
#: Largest counts: planning trials, benchmark poses, robot check samples, benchmark repeats.
MAX_TRIALS, MAX_POSES, MAX_SAMPLES, MAX_REPEATS = 100_000, 1_000_000, 1_000_000, 1_000


def _out_path(text: str, option: str) -> Path:
    """``text``, given as ``option``, as an output path; an empty one is refused.

    ``Path`` would read an empty one as the working directory.
    """
    if not text.strip():
        raise DualarmError(f"{option} '{excerpt(text)}': an empty path; give a directory or file name")
    if "\0" in text:
        raise DualarmError(f"{option} '{excerpt(text)}': a path cannot hold a NUL byte")
    return Path(text)


def _seed(seed: int, option: str = "--seed") -> int:
    """``seed`` if it is an integer >= 0 (of any size: numpy's Generator takes them all)."""
    if seed < 0:
        raise DualarmError(f"{option} {excerpt(seed)}: a seed is an integer >= 0 (of any size)")
    return seed


def _within(value: float, option: str, low: float, high: float = math.inf, *, above_low: bool = False) -> float:
    """``value``, given as ``option``, if it is finite and in [low, high] ((low, high] with ``above_low``).

    A DualarmError with the range otherwise.
    """
    if math.isfinite(value) and (value > low if above_low else value >= low) and value <= high:
        return value
    bounds = (
        f"{'>' if above_low else '>='} {low:g}"
        if high == math.inf
        else f"in {'(' if above_low else '['}{low:g}, {high:g}]"
    )
    raise DualarmError(f"{option} {excerpt(value)}: give a finite number {bounds}")


def _stages(stages: str | None) -> list[str] | None:
    """The stages of ``--stages`` (None when not given); a value naming none is refused."""
    if stages is None:
        return None
    from dualarm.contracts.run import ALL_STAGES

    chosen = [s.strip() for s in stages.split(",") if s.strip()]
    if not chosen:
        raise DualarmError(f"--stages '{excerpt(stages)}': names no stage (stages: {', '.join(ALL_STAGES)})")
    return chosen


def _record(level: str) -> str:
    """The recording level of ``--record``; another value is refused, naming the levels."""
    from dualarm.record.sink import RECORD_LEVELS

    if level not in RECORD_LEVELS:
        raise DualarmError(f"--record '{excerpt(level)}': unknown recording level (levels: {', '.join(RECORD_LEVELS)})")
    return level


#: Help of ``--record``, with the sizes measured on ``dualarm run triangle --ik mc-inverse --reps 5``.
RECORD_HELP = (
    "How much to record: full (run.mcap and run.rrd hold every stage; 74 MB), "
    "ik (they hold the path and ik/plan stages only; 4.9 MB) "
    "or metrics (no run.mcap, no run.rrd: manifest.json and metrics.json only; 9 kB). "
    "Every stage runs and is judged whatever the level "
    "(sizes of dualarm run triangle --ik mc-inverse --reps 5)."
)


def _method(name: str, kind=None, option: str = "method"):
    """The registered method ``name`` (of ``kind``).

    A DualarmError naming ``option`` and listing the methods otherwise.
    """
    from dualarm.methods import method

    return method(name, kind, option)


def _execution(gui: bool, execute_anyway: bool = False):
    from dualarm.execute.simulate import ExecutionSettings

    return ExecutionSettings(gui=gui, execute_anyway=execute_anyway)


def _robot(robot_dir: Path | None, urdf: Path | None, base: str | None, tip: str | None):
    """The robot of ``ROBOT_DIR`` or of ``--urdf PATH --base LINK --tip LINK`` (one chain named ``chain``)."""
    from dualarm.model.robot import load_robot, robot_from_urdf

    if robot_dir is not None and urdf is None:
        return load_robot(robot_dir)
    if robot_dir is not None or urdf is None:  # both given, or neither
        raise DualarmError("give either ROBOT_DIR or --urdf PATH --base LINK --tip LINK")
    if not base or not tip:
        raise DualarmError("--urdf needs --base LINK and --tip LINK")
    return robot_from_urdf(urdf, base, tip)


UrdfOption = Annotated[Path | None, typer.Option(help="A bare URDF instead (needs --base and --tip).")]
BaseLinkOption = Annotated[str | None, typer.Option(help="Base link of the arm chain (with --urdf).")]
TipLinkOption = Annotated[str | None, typer.Option(help="Tip link of the arm chain (with --urdf).")]
