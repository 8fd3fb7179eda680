"""Loading and validating a task file against its robot.

Errors name the file and key at fault (``tasks/triangle.toml:moves[2].left.to: ...``) and are
raised as :class:`~dualarm.errors.TaskFileError`; the CLI prints them as one line.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from pathlib import Path
from types import MappingProxyType
from typing import Any

from dualarm.errors import InvalidArgumentError, RobotModelError, TaskFileError, excerpt
from dualarm.files import listing
from dualarm.model.robot import Robot, load_robot
from dualarm.tasks.frames import _in_frame, _transferred
from dualarm.tasks.parse import _read, _validate
from dualarm.tasks.reach import _check_margin, _check_reach
from dualarm.tasks.schema import MAX_REPETITIONS, TaskSpec
from dualarm.tasks.task import Task

#: Most samples a task's path may have, all repetitions together: the budget that bounds every
#: stage's work. The shipped tasks use at most 3,001 (triangle: 5 repetitions of 6 s at 0.01 s);
#: at 100,000 (1,000 s of motion at 0.01 s) ``dualarm run --stages path`` took 6.3 s and wrote
#: 14 MB, at 10^6 38 s, 0.9 GB of memory and 127 MB (measured on the humanoid).
MAX_SAMPLES = 100_000


def _check_joint_names(location: str, names, robot: Robot) -> None:
    """Refuse a joint name the robot lacks, as ``location.name``."""
    for name in names:
        if name not in robot.limits:
            raise TaskFileError(f"{location}.{excerpt(name, 40)}: no such joint in robot '{excerpt(robot.name, 40)}'")


def _initial_configuration(source: str, spec: TaskSpec, robot: Robot) -> Mapping[str, float]:
    """The task's ``initial`` as every joint's value (:meth:`Robot.configuration`).

    Its errors are the task file's.
    """
    try:
        return robot.configuration(spec.initial, f"{source}:initial")
    except InvalidArgumentError as exc:
        raise TaskFileError(str(exc)) from None


def _check_structure(task: Task) -> None:
    spec, robot, where = task.spec, task.robot, task.where
    for hand in ("left", "right"):
        start = getattr(spec.start, hand)
        if start is None:
            continue
        if hand not in robot.hands:
            raise TaskFileError(
                f"{where('start.' + hand)}: robot '{excerpt(robot.name, 40)}' has no hand '{hand}' "
                f"(hands: {listing(robot.hands)})"
            )
        if start != "initial" and start not in spec.waypoints:
            raise TaskFileError(
                f"{where('start.' + hand)}: no waypoint '{excerpt(start, 40)}' "
                f'(waypoints: {listing(spec.waypoints)}; or "initial")'
            )
    started = {h for h in ("left", "right") if getattr(spec.start, h) is not None}
    per_repetition = 0
    for i, move in enumerate(spec.moves):
        steps = move.duration_s / spec.control_period_s  # at most 8.64e8 within the schema's ranges
        if steps < 1 - 1e-6:
            raise TaskFileError(
                f"{where(f'moves[{i}].duration_s')}: {move.duration_s:g} s is shorter than one control period "
                f"({spec.control_period_s:g} s)"
            )
        if abs(steps - round(steps)) > 1e-6:
            raise TaskFileError(
                f"{where(f'moves[{i}].duration_s')}: {move.duration_s:g} s is not a whole number of control periods "
                f"({spec.control_period_s:g} s)"
            )
        per_repetition += round(steps)
        for hand in ("left", "right"):
            hand_move = move.for_hand(hand)
            if hand_move is None:
                continue
            if hand not in started:
                raise TaskFileError(
                    f"{where(f'moves[{i}].{hand}')}: hand '{hand}' has no start pose (add start.{hand})"
                )
            if hand_move.to is not None and hand_move.to not in spec.waypoints:
                raise TaskFileError(
                    f"{where(f'moves[{i}].{hand}.to')}: no waypoint '{excerpt(hand_move.to, 40)}' "
                    f"(waypoints: {listing(spec.waypoints)})"
                )
    samples = 1 + spec.repetitions * per_repetition
    if samples > MAX_SAMPLES:
        raise TaskFileError(
            f"{where('moves')}: the path has {samples:,} samples ({spec.repetitions} repetitions of "
            f"{per_repetition:,} control periods of {spec.control_period_s:g} s), "
            f"more than the {MAX_SAMPLES:,} allowed; use a longer control_period_s, shorter moves or fewer repetitions"
        )
    _check_margin(task)
    if spec.gesture is not None:
        _check_joint_names(where("gesture.goal_lower"), spec.gesture.goal_lower, robot)
        _check_joint_names(where("gesture.goal_upper"), spec.gesture.goal_upper, robot)
        for key, goals in (("goal_lower", spec.gesture.goal_lower), ("goal_upper", spec.gesture.goal_upper)):
            for name, value in goals.items():
                lim = robot.limits[name]
                if not lim.lower <= value <= lim.upper:
                    raise TaskFileError(
                        f"{where(f'gesture.{key}')}.{name}: {value:g} rad is outside the joint's limits "
                        f"[{lim.lower:g}, {lim.upper:g}]"
                    )
        for name, lo in spec.gesture.goal_lower.items():
            hi = spec.gesture.goal_upper.get(name)
            if hi is not None and lo > hi:
                raise TaskFileError(f"{where('gesture.goal_lower')}.{name}: {lo:g} above goal_upper {hi:g}")
    if spec.object is not None:
        obj = spec.object
        if obj.master not in started:
            raise TaskFileError(f"{where('object.master')}: the master hand '{obj.master}' needs a start pose")
        if obj.slave in started or any(m.for_hand(obj.slave) for m in spec.moves):
            raise TaskFileError(
                f"{where('object.slave')}: the slave hand '{obj.slave}' follows the master by eq (11); "
                "give it no start or moves"
            )
    for i, wta in enumerate(spec.wta):
        if wta.hand not in robot.hands:
            raise TaskFileError(
                f"{where(f'wta[{i}].hand')}: robot '{excerpt(robot.name, 40)}' has no hand '{wta.hand}'"
            )
    names = set(robot.urdf.links) | {o.name for o in spec.environment} | ({spec.object.name} if spec.object else set())
    for i, pair in enumerate(spec.expected_contacts):
        for name in pair:
            if name not in names:
                raise TaskFileError(
                    f"{where(f'expected_contacts[{i}]')}: '{excerpt(name, 40)}' is neither a robot link "
                    "nor an object of the task"
                )


def _check_environment(task: Task) -> None:
    """Refuse a fixed object that overlaps a link of the robot's base (a link no joint moves).

    By PyBullet's closest points (imported only for tasks with objects).
    """
    if not task.spec.environment:
        return
    from dualarm.sim.world import add_environment, load_pybullet_robot, pb

    with load_pybullet_robot(task.robot.urdf.path) as sim:
        client = sim.client
        moved = {-1: False}
        for i in range(pb.getNumJoints(sim.body, physicsClientId=client)):
            info = pb.getJointInfo(sim.body, i, physicsClientId=client)
            moved[i] = moved[info[16]] or info[2] != pb.JOINT_FIXED
        base = [i for i in sim.collision_links() if not moved[i]]
        name = sim.link_name
        for index, (body, obj) in enumerate(add_environment(sim, task.spec.environment).items()):  # in the file's order
            for link in base:
                points = pb.getClosestPoints(sim.body, body, 0.0, linkIndexA=link, physicsClientId=client)
                if points:
                    depth = -min(p[8] for p in points)
                    raise TaskFileError(
                        f"{task.where(f'environment[{index}]')}: '{excerpt(obj, 40)}' overlaps the robot's base link "
                        f"'{name[link]}' ({depth * 1e3:.1f} mm deep); move it away from the robot"
                    )


def load_task(path: str | Path, repetitions: int | None = None, robot: str | Path | None = None) -> Task:
    """Read, validate and resolve a task file.

    ``repetitions`` overrides the file's, ``robot`` (a robot directory or shipped robot's name) the robot it names.

    A ``path`` that does not exist but is a bare name (``triangle``) is a shipped task, and the
    file's ``robot`` a directory relative to it or a shipped robot's name (see :mod:`dualarm.data`).

    Raises:
        TaskFileError: one line: ``file:key`` and the cause, for any malformed or impossible content
            (every number has a range, see :mod:`dualarm.tasks.schema`; the path at most
            :data:`MAX_SAMPLES` samples), or a ``repetitions`` override outside 1 to
            :data:`~dualarm.tasks.schema.MAX_REPETITIONS`; the file and the OS's reason when the
            file cannot be read (only a regular file is opened).
    """
    return _load_file(path, repetitions, robot)


def load_task_unmoved(path: str | Path, robot: str | Path | None = None) -> Task:
    """The task file at ``path`` with no moves: every hand it starts stays at the initial configuration.

    As :func:`load_task` loads it (errors name the file): ``dualarm task check`` loads it so when a waypoint is
    out of reach, to report every waypoint.
    """
    return _load_file(
        path,
        None,
        robot,
        lambda data: {**data, "start": {hand: "initial" for hand in data.get("start", {})}, "moves": []},
    )


def _load_file(
    path: str | Path,
    repetitions: int | None,
    robot: str | Path | None,
    edit: Callable[[dict], dict] = lambda data: data,
) -> Task:
    """:func:`load_task`, the file's keys passed through ``edit`` before validation."""
    from dualarm.data import find_task

    file = find_task(path)
    text, data = _read(file)
    spec = _validate(str(file), edit(data))
    if robot is not None:
        spec = spec.model_copy(update={"robot": str(robot)})
    return _resolve(spec, file, text, file.parent if robot is None else Path.cwd(), None, repetitions)


def task_from_dict(
    data: Mapping[str, Any] | None = None,
    /,
    *,
    robot: Robot | str | Path | None = None,
    base_dir: str | Path = ".",
    **keys: Any,
) -> Task:
    """A task from a plain dict and/or keyword arguments, with the keys and checks of a task file.

    See ``tasks/README.md``: ``task_from_dict(name="circle", control_period_s=0.01, ...)``.

    Args:
        data: the task's keys, as a TOML file would give them (optional).
        robot: a :class:`~dualarm.model.robot.Robot`, or a robot directory or shipped robot's name;
            default the ``robot`` key.
        base_dir: the directory a relative ``robot`` key is resolved against.
        **keys: more keys (they win over ``data``'s).

    Raises:
        TaskFileError: ``<dict>:key`` and the cause, as for a file.
    """
    merged = {**(data or {}), **keys}
    given = robot if isinstance(robot, Robot) else None
    if given is not None:
        merged["robot"] = given.name
    elif robot is not None:
        merged["robot"] = str(robot)
    text = json.dumps(merged, indent=2, sort_keys=True, default=str)
    return _resolve(_validate("<dict>", merged), None, text, Path(base_dir), given, None)


def _resolved(path: Path) -> Path:
    """``path`` made absolute with symbolic links resolved, or as given when the OS cannot.

    Loading it then says why.
    """
    try:
        return path.resolve()
    except (OSError, ValueError, RuntimeError):  # RuntimeError: a symlink loop, before Python 3.13
        return path


def _resolve(
    spec: TaskSpec, file: Path | None, text: str, base: Path, robot: Robot | None, repetitions: int | None
) -> Task:
    """The validated task.

    The robot loaded (unless given) with the task's limits, the initial configuration resolved, and every check
    run.
    """
    source = excerpt(file) if file is not None else "<dict>"
    if repetitions is not None:
        if isinstance(repetitions, bool) or not isinstance(repetitions, int) or not 1 <= repetitions <= MAX_REPETITIONS:
            raise TaskFileError(
                f"{source}:repetitions: the override must be an integer in [1, {MAX_REPETITIONS}], "
                f"not {excerpt(repr(repetitions), 24)}"
            )
        spec = spec.model_copy(update={"repetitions": repetitions})
    if robot is None:
        from dualarm.data import find_robot

        try:
            robot = load_robot(_resolved(find_robot(spec.robot, base)))
        except RobotModelError as exc:
            raise TaskFileError(f"{source}:robot: {exc}") from None
    spec = _transferred(spec, robot)
    for kind in ("velocity", "acceleration"):
        value = getattr(spec.limits, kind)
        if isinstance(value, dict):
            _check_joint_names(f"{source}:limits.{kind}", value, robot)
    robot = robot.with_limits(velocity=spec.limits.velocity, acceleration=spec.limits.acceleration)
    initial = _initial_configuration(source, spec, robot)
    spec = _in_frame(spec, robot, initial, source)
    task = Task(spec=spec, file=file, text=text, robot=robot, initial_q=MappingProxyType(dict(initial)))
    _check_structure(task)
    _check_reach(task)
    _check_environment(task)
    return task
