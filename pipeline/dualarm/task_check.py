"""``dualarm task check``: a task validated without running it, and every waypoint's reach.

Every waypoint's reach within the joint limits.

The task is loaded as a run loads it (schema, robot, structure, objects; :func:`dualarm.tasks.load_task`).
Then each waypoint a hand goes to (its start and every ``to``) is tested within the joint limits,
the waist at the task's initial configuration:

- an S-R-S arm: the MC-Inverse sweep over the arm angle (:func:`dualarm.ik.analytic.mc_inverse.sweep_arm_angle`)
  gives the branches and psi intervals that reach it; where no branch does on the grid, the
  numeric reach test of :mod:`dualarm.tasks.load` (bounded IK, any chain) decides for the methods
  that do not need S-R-S;
- any other arm: that numeric reach test.

A waypoint the loader's own reach test refuses is reported like any other unreachable one. Waypoints
are the poses a run uses: the task's ``frame`` and ``scale`` applied.

When every waypoint is reached, the path is sampled as the run's path stage samples it
(:func:`dualarm.paths.build.build_reference`: every move, arcs and ``by`` moves included, both hands,
a carried object's slave hand, each repetition's closure) and its reach test run on every sample: a
task this passes never fails a run for reach, and one it refuses names the move and the time.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from dualarm.errors import NotSRSError, UnreachablePoseError, excerpt
from dualarm.ik.analytic.mc_inverse import SWEEP_STEP_RAD, McInverse, sweep_arm_angle
from dualarm.model.kinematics import to_arm_frame
from dualarm.paths.build import build_reference
from dualarm.tasks.load import load_task, load_task_unmoved
from dualarm.tasks.reach import numeric_reach
from dualarm.tasks.schema import unit_vector
from dualarm.tasks.task import Task


@dataclass(frozen=True)
class WaypointReach:
    """Whether one hand reaches one waypoint within the joint limits.

    Attributes:
        key: the waypoint's key in the task (``waypoints.A``).
        hand: the hand that goes there.
        position_m: its position in the robot base frame [m], (3,).
        rpy_rad: its orientation, roll pitch yaw [rad] (extrinsic x-y-z), (3,).
        branches: for an S-R-S arm, per branch (0-7) reaching it, its feasible psi intervals [rad]
            (see :meth:`~dualarm.ik.analytic.mc_inverse.ArmAngleSweep.intervals`); empty otherwise.
        srs: whether the arm is S-R-S (MC-Inverse's sweep was used).
        numeric: whether the numeric reach test (bounded IK) reaches it; None when not needed.
    """

    key: str
    hand: str
    position_m: tuple[float, float, float]
    rpy_rad: tuple[float, float, float]
    branches: dict[int, list[tuple[float, float]]]
    srs: bool
    numeric: bool | None

    @property
    def reachable(self) -> bool:
        """Reached by some branch of MC-Inverse or by the numeric test."""
        return bool(self.branches) or bool(self.numeric)


@dataclass(frozen=True)
class TaskCheck:
    """The result of checking a task: its name, where it was read, every waypoint's reach, and the path's.

    ``path``: None when every sample of the path is within reach (or the waypoints already are not), else
    the path stage's refusal (the move, the time and why); ``samples``: the samples checked.
    """

    name: str
    source: str
    waypoints: tuple[WaypointReach, ...]
    path: str | None = None
    samples: int = 0

    @property
    def unreachable(self) -> tuple[WaypointReach, ...]:
        """The waypoints no method the task can use reaches."""
        return tuple(w for w in self.waypoints if not w.reachable)

    @property
    def passed(self) -> bool:
        """Every waypoint and every sample of the path within reach."""
        return not self.unreachable and self.path is None


def _load(file: Path, robot: Path | None) -> tuple[Task, dict]:
    """The task (``robot`` replacing its robot) and its raw keys.

    A task whose waypoints the loader's reach test refuses is loaded again without its moves, so that every
    waypoint is reported.
    """
    try:
        task = load_task(file, robot=robot)
    except UnreachablePoseError:
        task = load_task_unmoved(file, robot)
    return task, tomllib.loads(task.text)


def _targets(task: Task, data: dict) -> list[tuple[str, str]]:
    """(hand, waypoint name) of every waypoint a hand goes to, in the file's order."""
    pairs = []
    for hand in ("left", "right"):
        start = data.get("start", {}).get(hand)
        names = [start] + [m.get(hand, {}).get("to") for m in data.get("moves", [])]
        pairs += [(hand, n) for n in names if n is not None and n != "initial"]
    return list(dict.fromkeys(pairs))


def check_task(path: str | Path, robot: str | Path | None = None, step_rad: float = SWEEP_STEP_RAD) -> TaskCheck:
    """Validate the task file ``path`` (a shipped task's name too) without running it.

    On its robot or ``robot``, and test every waypoint's reach (module docstring).

    Raises:
        TaskFileError: the task is malformed or names what its robot lacks (one line naming the key).
    """
    from scipy.spatial.transform import Rotation

    from dualarm.data import find_task

    file = find_task(path)
    task, data = _load(file, Path(robot) if robot is not None else None)
    results = []
    for hand, name in _targets(task, data):
        T = task.waypoint_pose(name)
        branches: dict[int, list[tuple[float, float]]] = {}
        srs = True
        try:
            solver = McInverse.of(task.robot.hand_chain(hand), unit_vector(task.spec.arm_angle.vertical))
        except NotSRSError:
            srs = False
        if srs:
            sweep = sweep_arm_angle(solver, to_arm_frame(task.robot, hand, T, task.initial_q), step_rad)
            branches = {b: iv for b in range(8) if (iv := sweep.intervals(b))}
        numeric = None if branches else bool(numeric_reach(task, hand).within(T[None])[0])
        x, y, z = (float(v) for v in T[:3, 3])
        roll, pitch, yaw = (float(v) for v in Rotation.from_matrix(T[:3, :3]).as_euler("xyz"))
        results.append(WaypointReach(f"waypoints.{name}", hand, (x, y, z), (roll, pitch, yaw), branches, srs, numeric))
    check = TaskCheck(name=task.name, source=excerpt(file), waypoints=tuple(results))
    if check.unreachable:
        return check
    try:
        reference = build_reference(task)
    except UnreachablePoseError as exc:
        return replace(check, path=str(exc))
    return replace(check, samples=len(reference))


def report_lines(check: TaskCheck) -> list[str]:
    """One line per waypoint: the hand, the pose, and what reaches it.

    What reaches it: branches numbered 1-8 and their psi intervals, or the numeric test.
    """
    lines = []
    for w in check.waypoints:
        pose = (
            f"position [{', '.join(f'{v:.3f}' for v in w.position_m)}] m, "
            f"rpy [{', '.join(f'{v:.3f}' for v in w.rpy_rad)}] rad"
        )
        if w.branches:
            spans = "; ".join(
                f"branch {b + 1}: "
                + ", ".join(
                    f"[{lo:.3f}, {hi:.3f}]" if hi <= np.pi else f"[{lo:.3f}, {hi - 2 * np.pi:.3f}] across ±pi"
                    for lo, hi in iv
                )
                for b, iv in w.branches.items()
            )
            how = f"reachable by MC-Inverse, psi [rad] per branch: {spans}"
        elif w.numeric:
            how = "reachable by numeric IK within the limits" + (
                " (no MC-Inverse branch on the psi grid)" if w.srs else " (arm not S-R-S: MC-Inverse cannot be used)"
            )
        else:
            how = "NOT reachable within the joint limits"
        lines.append(f"{w.key} ({w.hand} hand): {pose}: {how}")
    return lines


def unreachable_lines(check: TaskCheck) -> list[str]:
    """One line per unreachable waypoint (``x.toml:waypoints.A: ...``), and the path's refusal."""
    return [
        f"{check.source}:{w.key}: the {w.hand} hand cannot reach it within the joint limits ("
        + ("no MC-Inverse branch at any arm angle, " if w.srs else "")
        + "numeric IK did not reach it); move the waypoint or change its orientation"
        for w in check.unreachable
    ] + ([check.path] if check.path else [])
