"""A study's trials: each one a repeated-motion task drawn from the spec's distributions.

The same on any machine.

Trial ``i`` of a spec is drawn by its own generator, ``numpy.random.default_rng(SeedSequence([seed,
i, draw]))`` (PCG64, whose streams numpy keeps identical across platforms and versions), so it does
not depend on which trials ran before it, on which worker, or in which order: a study can be split,
resumed and spread over machines and still draw the same trials. With ``[centre] reachable`` (the
default), :func:`reachable_trial` draws again (``draw`` 1, 2, ...) until the shape is within the
arm's reach (:func:`within_reach`), up to :data:`MAX_DRAWS` times.

A trial's task (a dict with a task file's keys, :func:`dualarm.tasks.load.task_from_dict` loads
it) has one hand draw a closed shape ``repetitions`` times, starting at the robot's ``ready`` pose:

- ``polygon``: N vertices on a circle of the shape's size, a random phase; straight edges, each
  taking 1/N of the period; with ``changing`` orientation each vertex's is the base turned by up
  to ``change_rad`` about each axis.
- ``circle``: one arc of 2 pi about the centre.
- ``figure-eight``: from the centre, one circle of half the size on each side, the second the
  other way round.

With ``hands`` drawn ``both``, the left (master) hand draws the shape at the left hand's centre,
from ``[carry] rpy``, and the task's ``[object]`` has the right (slave) hand hold a box with it
(MC-Inverse eq (11); :class:`~dualarm.study.spec.Carry`).

The right hand's centre and orientations are the left's mirrored through the x-z plane. The shape's
plane is the y-z plane (the hand's shoulder frame, facing forward) with its normal
turned from x by a random angle up to ``tilt_rad`` towards a random direction. Every move's
duration is a whole number of control periods.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.spatial.transform import Rotation

from dualarm.study.spec import StudySpec

if TYPE_CHECKING:
    from dualarm.model.robot import Robot
    from dualarm.tasks.task import Task


@dataclass(frozen=True)
class Trial:
    """One trial: its index, the task it runs (a task file's keys) and its features.

    The features are what the study report bins by.

    Attributes:
        index: its number in the study, from 0.
        task: the task's keys (``task_from_dict``; written as the trial's task file).
        features: the drawn parameters: ``hand``, ``kind``, ``vertices`` (0 but for a polygon),
            ``size_m``, ``centre_x_m``/``_y_m``/``_z_m`` (the shoulder frame, arm-scaled),
            ``tilt_rad``, ``orientation`` (held or changing), ``repetitions``, ``period_s``,
            ``draw`` (see :func:`reachable_trial`, which adds ``reachable``).
    """

    index: int
    task: dict[str, Any]
    features: dict[str, Any]


#: The arms a trial of each ``hands`` draw drives; a carry's master (the hand that draws) first.
ARMS = {"left": ("left",), "right": ("right",), "both": ("left", "right")}


def trial(spec: StudySpec, index: int, draw: int = 0) -> Trial:
    """Draw ``draw`` of trial ``index`` of ``spec`` (module docstring).

    The same for the same spec, seed, index and draw.
    """
    rng = np.random.default_rng(np.random.SeedSequence([spec.seed, index, draw]))
    hand = str(rng.choice(spec.hands))
    drawing = ARMS[hand][0]  # a carry's master hand draws
    kind = str(rng.choice(spec.shape.kinds))
    vertices = int(rng.integers(spec.shape.vertices[0], spec.shape.vertices[1] + 1)) if kind == "polygon" else 0
    size = float(rng.uniform(*spec.shape.size_m))
    mirror = 1.0 if drawing == "left" else -1.0
    centre = np.array([rng.uniform(*spec.centre.x), mirror * rng.uniform(*spec.centre.y), rng.uniform(*spec.centre.z)])
    tilt, towards = float(rng.uniform(0.0, spec.shape.tilt_rad)), float(rng.uniform(0.0, 2 * math.pi))
    orientation = str(rng.choice(spec.orientation.change))
    repetitions = int(rng.integers(spec.repetitions[0], spec.repetitions[1] + 1))
    period = float(rng.uniform(*spec.period_s))
    normal = _turned_x(tilt, towards)
    up = np.array([0.0, 0.0, 1.0]) - normal[2] * normal
    u = up / np.linalg.norm(up)
    v = np.cross(normal, u)
    base = (
        np.array(spec.carry.rpy)
        if hand == "both"
        else np.array(spec.orientation.rpy)
        if hand == "left"
        else _mirrored(spec.orientation.rpy)
    )
    cp = spec.control_period_s

    def steps(duration: float) -> float:  # a whole number of control periods, at least one
        return max(1, round(duration / cp)) * cp

    def point(p: np.ndarray) -> list[float]:
        return [round(float(x), 12) for x in p]

    waypoints: dict[str, Any]
    moves: list[dict[str, Any]]
    if kind == "polygon":
        phase = float(rng.uniform(0.0, 2 * math.pi))
        corners = [
            centre
            + size
            * (math.cos(phase + 2 * math.pi * k / vertices) * u + math.sin(phase + 2 * math.pi * k / vertices) * v)
            for k in range(vertices)
        ]
        turns = (
            rng.uniform(-spec.orientation.change_rad, spec.orientation.change_rad, (vertices, 3))
            if orientation == "changing"
            else np.zeros((vertices, 3))
        )
        waypoints = {f"V{k}": {"position": point(c), "rpy": point(base + turns[k])} for k, c in enumerate(corners)}
        moves = [
            {"duration_s": steps(period / vertices), drawing: {"to": f"V{(k + 1) % vertices}"}} for k in range(vertices)
        ]
        start = "V0"
    elif kind == "circle":
        waypoints = {"P0": {"position": point(centre + size * u), "rpy": point(base)}}
        moves = [
            {
                "duration_s": steps(period),
                drawing: {"arc_center": point(centre), "arc_axis": point(normal), "arc_angle_rad": 2 * math.pi},
            }
        ]
        start = "P0"
    else:  # figure-eight: two circles of half the size through the centre, the second the other way round
        waypoints = {"C": {"position": point(centre), "rpy": point(base)}}
        moves = [
            {
                "duration_s": steps(period / 2),
                drawing: {
                    "arc_center": point(centre + size / 2 * u),
                    "arc_axis": point(normal),
                    "arc_angle_rad": 2 * math.pi,
                },
            },
            {
                "duration_s": steps(period / 2),
                drawing: {
                    "arc_center": point(centre - size / 2 * u),
                    "arc_axis": point(-normal),
                    "arc_angle_rad": 2 * math.pi,
                },
            },
        ]
        start = "C"
    task = {
        "name": f"{spec.name}-{index:06d}",
        "title": f"{spec.name}, trial {index}: "
        + ("the left hand carries a box with the right along" if hand == "both" else f"the {hand} hand draws")
        + f" a {kind} {repetitions} times",
        "source": f"dualarm study {spec.name} (seed {spec.seed}), trial {index}",
        "robot": spec.robot,
        "control_period_s": cp,
        "repetitions": repetitions,
        "initial": "ready",
        "frame": f"{drawing}.shoulder",
        "scale": "arm",
        "waypoints": waypoints,
        "start": {drawing: start},
        "moves": moves,
    }
    if hand == "both":  # eq (11): the right hand follows the left's pose through the box
        carry = spec.carry
        task["object"] = {
            "name": "box",
            "size_m": list(carry.size_m),
            "master": ARMS[hand][0],
            "slave": ARMS[hand][1],
            "master_to_object": carry.master_to_object.model_dump(),
            "slave_to_object": carry.slave_to_object.model_dump(),
        }
    features = {
        "hand": hand,
        "kind": kind,
        "vertices": vertices,
        "size_m": size,
        "centre_x_m": float(centre[0]),
        "centre_y_m": float(centre[1]),
        "centre_z_m": float(centre[2]),
        "tilt_rad": tilt,
        "orientation": orientation,
        "repetitions": repetitions,
        "period_s": sum(move["duration_s"] for move in moves),
        "draw": draw,
    }
    return Trial(index, task, features)


#: Most draws of one trial with ``[centre] reachable``.
MAX_DRAWS = 50
#: The arm-angle grid step of :func:`within_reach` [rad] (5 degrees).
REACH_STEP_RAD = np.pi / 36
#: Most poses of a repetition :func:`within_reach` checks (evenly spaced).
REACH_POSES = 64


def reachable_trial(spec: StudySpec, index: int, base_dir: str | Path = ".") -> tuple[Trial, Task]:
    """Trial ``index`` of ``spec`` and its task.

    The first draw within reach (:func:`within_reach`) with ``[centre] reachable``, else draw 0.

    Its feature ``reachable`` says whether the trial kept is within reach: false after
    :data:`MAX_DRAWS` draws none of which was (the last is kept), or without the check.

    Raises:
        UnreachablePoseError: the draw kept has a waypoint beyond the arm's span (the task
            loader's check), so it has no task.
        NotSRSError: ``[centre] reachable`` on a robot whose drawing arm is not S-R-S.
    """
    from dualarm.errors import UnreachablePoseError
    from dualarm.tasks.load import task_from_dict

    robot = study_robot(spec.robot, str(base_dir))
    draws = MAX_DRAWS if spec.centre.reachable else 1
    for draw in range(draws):
        drawn = trial(spec, index, draw)
        drawn.features["reachable"] = False
        try:
            task = task_from_dict(drawn.task, robot=robot)
        except UnreachablePoseError:  # a waypoint out of the arm's span (the task file's own check)
            if draw == draws - 1:
                raise
            continue
        if spec.centre.reachable and within_reach(task):
            drawn.features["reachable"] = True
            break
    return drawn, task


@cache
def study_robot(robot: str, base_dir: str) -> Robot:
    """A spec's ``robot``, loaded once per process.

    A directory relative to ``base_dir``, or a shipped robot's name. A study's worker parses its
    URDF once, not once per trial.

    Raises:
        RobotModelError: no such robot, or its description is unusable.
    """
    from dualarm.data import find_robot
    from dualarm.model.robot import load_robot

    return load_robot(find_robot(robot, Path(base_dir)).resolve())


def within_reach(task: Task) -> bool:
    """Whether every hand pose of the task's first repetition has an analytic S-R-S solution.

    At most :data:`REACH_POSES` of them, evenly spaced, with its first and last; a solution inside
    the joint limits, for some branch at some arm angle of a :data:`REACH_STEP_RAD` grid.

    Raises:
        NotSRSError: an arm of the task is not S-R-S.
    """
    from dualarm.errors import UnreachablePoseError
    from dualarm.ik.analytic.mc_inverse import VALID, McInverse
    from dualarm.ik.arms import arm_problems
    from dualarm.paths.build import build_reference

    try:
        reference = build_reference(task)
    except UnreachablePoseError:  # a sample beyond the arm's span (the path builder's own check)
        return False
    first = np.flatnonzero(reference.rep == 0)
    picked = first[np.unique(np.linspace(0, len(first) - 1, min(len(first), REACH_POSES)).round().astype(int))]
    grid = -np.pi + REACH_STEP_RAD * np.arange(round(2 * np.pi / REACH_STEP_RAD))
    for arm in arm_problems(task.robot, reference, task.initial_q):
        solver = McInverse.of(arm.chain)  # the arm angle's vertical does not matter: the grid covers every angle
        _, reason = solver.solve_many(np.repeat(arm.targets[picked], len(grid), axis=0), np.tile(grid, len(picked)))
        if not (reason == VALID).reshape(len(picked), -1).any(axis=1).all():
            return False
    return True


def _mirrored(rpy: tuple[float, float, float]) -> np.ndarray:
    """The orientation (extrinsic x-y-z Euler angles [rad]) mirrored through the x-z plane.

    M R M with M = diag(1, -1, 1): the right hand's of the left's.
    """
    mirror = np.diag([1.0, -1.0, 1.0])
    return np.asarray(
        Rotation.from_matrix(mirror @ Rotation.from_euler("xyz", rpy).as_matrix() @ mirror).as_euler("xyz")
    )


def _turned_x(angle: float, towards: float) -> np.ndarray:
    """The x axis turned by ``angle`` [rad] about an axis of the y-z plane (Rodrigues).

    The axis (0, cos(towards), sin(towards)).
    """
    axis = np.array([0.0, math.cos(towards), math.sin(towards)])
    x = np.array([1.0, 0.0, 0.0])
    return x * math.cos(angle) + np.cross(axis, x) * math.sin(angle) + axis * (axis @ x) * (1 - math.cos(angle))
