"""Loading and validating a task file against its robot.

Errors name the file and key at fault (``tasks/triangle.toml:moves[2].left.to: ...``) and are
raised as :class:`~dualarm.errors.TaskFileError`; the CLI prints them as one line.
"""

from __future__ import annotations

import hashlib
import json
import tomllib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np
from pydantic import ValidationError
from pydantic_core import ErrorDetails

from dualarm.errors import InvalidArgumentError, NotSRSError, RobotModelError, TaskFileError, UnreachablePoseError, excerpt
from dualarm.files import listing, read_text
from dualarm.model.kinematics import ChainKinematics, hand_pose, origin_matrix
from dualarm.model.poses import pose_matrix
from dualarm.model.robot import Chain, Robot, load_robot
from dualarm.model.srs import SrsGeometry, srs_geometry
from dualarm.tasks.schema import FRAME_ROLES, MAX_REPETITIONS, REFERENCE_ARM_M, Pose, TaskSpec

#: Margin kept from the fully stretched or fully folded arm when checking reach [m].
REACH_MARGIN_M = 1e-3
#: Most samples a task's path may have, all repetitions together: the budget that bounds every
#: stage's work. The shipped tasks use at most 3,001 (triangle: 5 repetitions of 6 s at 0.01 s);
#: at 100,000 (1,000 s of motion at 0.01 s) ``dualarm run --stages path`` took 6.3 s and wrote
#: 14 MB, at 10^6 38 s, 0.9 GB of memory and 127 MB (measured on the humanoid).
MAX_SAMPLES = 100_000


@dataclass(frozen=True)
class Task:
    """A validated task.

    Attributes:
        spec: the parsed file (or dict).
        file: where it was read from; None for a task made from a dict.
        text: the source's exact text (TOML for a file, JSON for a dict; recorded as an attachment).
        robot: the robot it names, with the task's ``[limits]`` applied.
        initial_q: the initial configuration, every movable joint of the robot [rad].
    """

    spec: TaskSpec
    file: Path | None
    text: str
    robot: Robot
    initial_q: Mapping[str, float]

    @property
    def name(self) -> str:
        """The task's name (also its recordings directory)."""
        return self.spec.name

    @property
    def sha256(self) -> str:
        """SHA-256 of the source's text."""
        return hashlib.sha256(self.text.encode()).hexdigest()

    @property
    def source_name(self) -> str:
        """The file name of the task's source (``<name>.json`` for a task made from a dict)."""
        return self.file.name if self.file is not None else f"{self.name}.json"

    def where(self, key: str) -> str:
        """``file:key`` for error messages (``<dict>:key`` for a task made from a dict)."""
        return f"{excerpt(self.file) if self.file is not None else '<dict>'}:{key}"

    def hand_chain_from_root(self, hand: str) -> Chain:
        """The chain from the robot's root link to ``hand``'s tip (waist included)."""
        return self.robot.chain_between(self.robot.urdf.root, self.robot.hand_chain(hand).tip)

    def initial_hand_pose(self, hand: str) -> np.ndarray:
        """The pose of ``hand`` at the initial configuration, in the robot base frame (4x4) [m]."""
        return hand_pose(self.robot, hand, self.initial_q)

    def hand_poses(self, joint_names: tuple[str, ...], q: np.ndarray, fixed: Mapping[str, float]) -> dict[str, np.ndarray]:
        """Each driven hand's pose (N, 4, 4) [m] at configurations ``q`` (N, n) [rad] of ``joint_names``, the other joints at ``fixed`` or else at their initial values."""
        return hand_poses(self.robot, self.spec.hands, joint_names, q, {**self.initial_q, **fixed})

    def waypoint_pose(self, name: str) -> np.ndarray:
        """The 4x4 pose of waypoint ``name`` [m]."""
        wp = self.spec.waypoints[name]
        return pose_matrix(wp.position, wp.rpy)

    def start_pose(self, hand: str) -> np.ndarray:
        """The start pose of a driven hand (``initial`` or a waypoint) [m]."""
        start = getattr(self.spec.start, hand)
        return self.initial_hand_pose(hand) if start == "initial" else self.waypoint_pose(start)


def hand_poses(robot: Robot, hands: Sequence[str], joint_names: Sequence[str], q: np.ndarray, others: Mapping[str, float]) -> dict[str, np.ndarray]:
    """Each of ``hands``' pose (N, 4, 4) [m] in the robot base frame at configurations ``q`` (N, n) [rad] of ``joint_names``, every other joint at its value in ``others`` [rad]."""
    q = np.asarray(q, dtype=float).reshape(-1, len(joint_names))
    columns = {n: q[:, i] for i, n in enumerate(joint_names)}
    poses = {}
    for hand in hands:
        chain = robot.chain_between(robot.urdf.root, robot.hand_chain(hand).tip)
        Q = np.stack([columns[n] if n in columns else np.full(len(q), others[n]) for n in chain.joint_names], axis=1)
        poses[hand] = ChainKinematics.of(chain).poses(Q)
    return poses


def _key_path(error: ErrorDetails, data: object) -> str:
    """The task-file key of a pydantic error.

    Location parts that are not keys of the input (the names pydantic gives union members, such as
    ``str`` or ``constrained-float``) are dropped by walking the input alongside; a missing key is
    the one part kept that the input lacks.
    """
    out: str = ""
    node = data
    loc = error["loc"]
    for i, part in enumerate(loc):
        if isinstance(node, list) and isinstance(part, int) and part < len(node):
            out, node = f"{out}[{part}]", node[part]
        elif isinstance(node, dict) and part in node:
            out, node = (f"{out}.{part}" if out else str(part)), node[part]
        elif error["type"] == "missing" and i == len(loc) - 1:
            out = f"{out}[{part}]" if isinstance(part, int) else f"{out}.{part}" if out else str(part)
    return excerpt(out) if out else "(top level)"


def _quoted(value: object) -> str:
    """``repr(value)``, quoted with :func:`~dualarm.errors.excerpt` (a value nested too deeply for repr is described)."""
    try:
        return excerpt(repr(value))
    except RecursionError:
        return f"a {type(value).__name__} nested too deeply"


def _validation_message(file: object, exc: ValidationError, data: object) -> str:
    errors = [(_key_path(e, data), e) for e in exc.errors()]
    key, first = max(errors, key=lambda ke: ke[0].count(".") + ke[0].count("["))  # the most specific
    alternatives = [e for k, e in errors if k == key]
    fitting = [e for e in alternatives if not e["type"].endswith("_type")]  # those whose type the value has
    if first["type"] == "extra_forbidden":
        message = "unknown key"
    elif first["type"] == "missing":
        message = "missing"
    elif len(alternatives) > 1 and len(fitting) == 1:  # a union, and the value has the type of one member
        message = fitting[0]["msg"].removeprefix("Value error, ")
    elif len(alternatives) > 1:  # a union: say what each alternative wanted
        message = f"wrong type or value {_quoted(first['input'])} ({'; or '.join(e['msg'].removeprefix('Value error, ') for e in alternatives)})"
    else:
        message = first["msg"].removeprefix("Value error, ")
    others = len({k for k, _ in errors}) - 1
    return f"{excerpt(file)}:{key}: {message}" + (f" (and {others} more problem{'s' if others > 1 else ''})" if others else "")


def _read(file: Path) -> tuple[str, dict]:
    """The text of a task file and its TOML; one-line TaskFileError naming the file and the cause otherwise (see :func:`dualarm.files.read_text`)."""
    text = read_text(file, "task file", TaskFileError)
    try:
        return text, tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise TaskFileError(f"{excerpt(file)}: not valid TOML: {exc}") from None
    except (RecursionError, ValueError) as exc:  # nesting beyond Python's stack, an integer beyond int()'s digits
        raise TaskFileError(f"{excerpt(file)}: not valid TOML: {excerpt(exc) if isinstance(exc, ValueError) else 'tables or arrays nested too deeply'}") from None


def _validate(where: str, data: object) -> TaskSpec:
    try:
        return TaskSpec.model_validate(data)
    except ValidationError as exc:
        raise TaskFileError(_validation_message(where, exc, data)) from None
    except RecursionError:
        raise TaskFileError(f"{excerpt(where)}: values nested too deeply") from None


def _check_joint_names(location: str, names, robot: Robot) -> None:
    """Refuse a joint name the robot lacks, as ``location.name``."""
    for name in names:
        if name not in robot.limits:
            raise TaskFileError(f"{location}.{excerpt(name, 40)}: no such joint in robot '{excerpt(robot.name, 40)}'")


def _initial_configuration(source: str, spec: TaskSpec, robot: Robot) -> Mapping[str, float]:
    """The task's ``initial`` as every joint's value (:meth:`Robot.configuration`), its errors as the task file's."""
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
            raise TaskFileError(f"{where('start.' + hand)}: robot '{excerpt(robot.name, 40)}' has no hand '{hand}' (hands: {listing(robot.hands)})")
        if start != "initial" and start not in spec.waypoints:
            raise TaskFileError(f"{where('start.' + hand)}: no waypoint '{excerpt(start, 40)}' (waypoints: {listing(spec.waypoints)}; or \"initial\")")
    started = {h for h in ("left", "right") if getattr(spec.start, h) is not None}
    per_repetition = 0
    for i, move in enumerate(spec.moves):
        steps = move.duration_s / spec.control_period_s  # at most 8.64e8 within the schema's ranges
        if steps < 1 - 1e-6:
            raise TaskFileError(f"{where(f'moves[{i}].duration_s')}: {move.duration_s:g} s is shorter than one control period ({spec.control_period_s:g} s)")
        if abs(steps - round(steps)) > 1e-6:
            raise TaskFileError(f"{where(f'moves[{i}].duration_s')}: {move.duration_s:g} s is not a whole number of control periods ({spec.control_period_s:g} s)")
        per_repetition += round(steps)
        for hand in ("left", "right"):
            hand_move = move.for_hand(hand)
            if hand_move is None:
                continue
            if hand not in started:
                raise TaskFileError(f"{where(f'moves[{i}].{hand}')}: hand '{hand}' has no start pose (add start.{hand})")
            if hand_move.to is not None and hand_move.to not in spec.waypoints:
                raise TaskFileError(f"{where(f'moves[{i}].{hand}.to')}: no waypoint '{excerpt(hand_move.to, 40)}' (waypoints: {listing(spec.waypoints)})")
    samples = 1 + spec.repetitions * per_repetition
    if samples > MAX_SAMPLES:
        raise TaskFileError(
            f"{where('moves')}: the path has {samples:,} samples ({spec.repetitions} repetitions of {per_repetition:,} control periods of {spec.control_period_s:g} s), "
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
                    raise TaskFileError(f"{where(f'gesture.{key}')}.{name}: {value:g} rad is outside the joint's limits [{lim.lower:g}, {lim.upper:g}]")
        for name, lo in spec.gesture.goal_lower.items():
            hi = spec.gesture.goal_upper.get(name)
            if hi is not None and lo > hi:
                raise TaskFileError(f"{where('gesture.goal_lower')}.{name}: {lo:g} above goal_upper {hi:g}")
    if spec.object is not None:
        obj = spec.object
        if obj.master not in started:
            raise TaskFileError(f"{where('object.master')}: the master hand '{obj.master}' needs a start pose")
        if obj.slave in started or any(m.for_hand(obj.slave) for m in spec.moves):
            raise TaskFileError(f"{where('object.slave')}: the slave hand '{obj.slave}' follows the master by eq (11); give it no start or moves")
    for i, wta in enumerate(spec.wta):
        if wta.hand not in robot.hands:
            raise TaskFileError(f"{where(f'wta[{i}].hand')}: robot '{excerpt(robot.name, 40)}' has no hand '{wta.hand}'")
    names = set(robot.urdf.links) | {o.name for o in spec.environment} | ({spec.object.name} if spec.object else set())
    for i, pair in enumerate(spec.expected_contacts):
        for name in pair:
            if name not in names:
                raise TaskFileError(f"{where(f'expected_contacts[{i}]')}: '{excerpt(name, 40)}' is neither a robot link nor an object of the task")


def _check_margin(task: Task) -> None:
    """Refuse an ``arm_angle.margin_rad`` of half the narrowest position range of a driven arm's joints or more: no configuration keeps it from both limits of that joint."""
    robot, margin = task.robot, task.spec.arm_angle.margin_rad
    ranges = {name: robot.limits[name].upper - robot.limits[name].lower for hand in task.spec.hands if hand in robot.hands for name in robot.hand_chain(hand).joint_names}
    if not ranges:
        return
    joint = min(ranges, key=lambda n: ranges[n])
    half = ranges[joint] / 2
    if not margin < half:
        raise TaskFileError(
            f"{task.where('arm_angle.margin_rad')}: {margin:g} rad is outside the allowed range [0, {half:.4g}) rad (below half the range of joint '{excerpt(joint, 40)}', the narrowest of the driven arms)"
        )


@dataclass(frozen=True)
class ArmReach:
    """The workspace test of one hand of an S-R-S arm, in closed form: the wrist centre W of a hand pose must lie within [|L2 - L3|, L2 + L3] of the shoulder S (less :data:`REACH_MARGIN_M`).

    With the waist free, S may move on a sphere about the waist centre, and the test becomes the
    necessary condition | |W - centre| - |S - centre| | <= L2 + L3.

    Attributes:
        hand: the hand.
        geometry: its arm's S-R-S geometry.
        shoulder: S in the robot base frame at the initial configuration [m].
        waist_centre: the waist's centre of rotation [m] when the waist is free, else None.
    """

    hand: str
    geometry: SrsGeometry
    shoulder: np.ndarray
    waist_centre: np.ndarray | None

    def distances(self, T: np.ndarray) -> np.ndarray:
        """The distance the test bounds, for hand poses T (N, 4, 4) [m]; (N,)."""
        wrist = self.geometry.wrist_centre(T[:, :3, 3], T[:, :3, :3])
        if self.waist_centre is None:
            return np.linalg.norm(wrist - self.shoulder, axis=1)
        radius = np.linalg.norm(self.shoulder - self.waist_centre)
        return np.abs(np.linalg.norm(wrist - self.waist_centre, axis=1) - radius)

    def within(self, T: np.ndarray) -> np.ndarray:
        """Which of the hand poses T (N, 4, 4) pass; (N,) bool."""
        d = self.distances(T)
        low = -np.inf if self.waist_centre is not None else self.geometry.min_reach + REACH_MARGIN_M
        return (d >= low) & (d <= self.geometry.reach - REACH_MARGIN_M)

    def explain(self, T: np.ndarray) -> str:
        """Why one pose T (4, 4) fails, for an error message."""
        d = float(self.distances(T[None])[0])
        p = ", ".join(f"{v:.3f}" for v in T[:3, 3])
        origin = "the waist's reach" if self.waist_centre is not None else "the shoulder"
        return f"the {self.hand} hand cannot reach [{p}] with this orientation: its wrist centre is {d:.3f} m from {origin}, the arm spans {self.geometry.min_reach:.3f}-{self.geometry.reach:.3f} m"


@dataclass(frozen=True)
class NumericReach:
    """The workspace test of one hand of any arm: a pose is within reach when a numeric IK solve inside the joint limits reaches it.

    Why numeric IK, not a sampled workspace: a hand pose has six dimensions, which no affordable
    sampling of a 7-DOF arm's configurations covers densely enough to decide one given pose (a
    sampled cloud decides positions only, and blurs the boundary by its resolution); a solve
    decides the very pose asked, joint limits included, and a solution found is a proof of reach.
    The solver is SciPy's bounded least squares (``dogbox``, the limits as bounds) on the hand's
    position error and rotation vector, with the chain's geometric Jacobian; it starts from the
    previous pose's solution (along a path), the task's initial configuration, then
    :data:`REACH_SEEDS` configurations drawn uniformly within the limits (fixed seed
    :data:`REACH_SEED`), and stops at the first that reaches the pose within
    :data:`REACH_POSITION_TOLERANCE_M` and :data:`REACH_ORIENTATION_TOLERANCE_RAD`. A pose that
    no start reaches is refused: deterministic, but a pose reachable only from a start none of
    these finds would be refused too (not seen on the shipped robots).

    Attributes:
        hand: the hand.
        chain: the chain from the robot's root link to the hand (a waist included).
        free: indices into ``chain.joint_names`` of the joints the solve moves (the arm's, and the
            waist's when it is free).
        q_initial: the chain's joints at the task's initial configuration [rad], (n,).
        lower: lowest positions of the free joints [rad], (k,).
        upper: highest positions of the free joints [rad], (k,).
        seeds: start configurations of the free joints [rad], (S, k), the initial one first.
    """

    hand: str
    chain: Chain
    free: tuple[int, ...]
    q_initial: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    seeds: np.ndarray

    def _solve(self, T: np.ndarray, start: np.ndarray) -> tuple[np.ndarray, float, float]:
        """One bounded solve for pose T (4, 4) from ``start`` (k,): (free joints [rad], position error [m], orientation error [rad])."""
        from scipy.optimize import least_squares
        from scipy.spatial.transform import Rotation

        kinematics = ChainKinematics.of(self.chain)
        free = list(self.free)
        q = self.q_initial.copy()

        def pose(x: np.ndarray) -> np.ndarray:
            q[free] = x
            return kinematics.pose(q)

        def residual(x: np.ndarray) -> np.ndarray:
            P = pose(x)
            return np.concatenate([P[:3, 3] - T[:3, 3], Rotation.from_matrix(P[:3, :3] @ T[:3, :3].T).as_rotvec()])

        def jacobian(x: np.ndarray) -> np.ndarray:
            q[free] = x
            return kinematics.jacobians(q)[0][:, free]

        x0 = np.clip(start, self.lower, self.upper)
        result = least_squares(residual, x0, jac=jacobian, bounds=(self.lower, self.upper), method="dogbox", max_nfev=50)
        r = residual(result.x)
        return result.x, float(np.linalg.norm(r[:3])), float(np.linalg.norm(r[3:]))

    def solve(self, T: np.ndarray, warm: np.ndarray | None = None) -> tuple[np.ndarray | None, float, float]:
        """The free joints [rad] reaching pose T (4, 4) within the limits, from ``warm`` then every seed, or None; with the smallest position [m] and orientation [rad] errors met."""
        best = (np.inf, np.inf)
        for start in ([warm] if warm is not None else []) + list(self.seeds):
            x, position, orientation = self._solve(T, start)
            if position <= REACH_POSITION_TOLERANCE_M and orientation <= REACH_ORIENTATION_TOLERANCE_RAD:
                return x, position, orientation
            best = min(best, (position, orientation))
        return None, *best

    def within(self, T: np.ndarray) -> np.ndarray:
        """Which of the hand poses T (N, 4, 4) pass; (N,) bool. Poses equal to 1e-9 (a repeated path's) are solved once, in order, each from the previous one's solution."""
        T = np.asarray(T, dtype=float)
        _, first, inverse = np.unique(np.round(T.reshape(len(T), 16), 9), axis=0, return_index=True, return_inverse=True)
        ok = np.zeros(len(first), bool)
        warm = None
        for u in np.argsort(first):  # in path order, so each solve starts from its neighbour's
            x, _, _ = self.solve(T[first[u]], warm)
            ok[u] = x is not None
            warm = x if x is not None else warm
        return ok[np.asarray(inverse).ravel()]

    def explain(self, T: np.ndarray) -> str:
        """Why one pose T (4, 4) fails, for an error message."""
        _, position, orientation = self.solve(T)
        p = ", ".join(f"{v:.3f}" for v in T[:3, 3])
        return (
            f"the {self.hand} hand cannot reach [{p}] with this orientation within the joint limits: numeric IK from {len(self.seeds)} starts "
            f"came no closer than {position:.3g} m and {orientation:.3g} rad (this arm is not S-R-S, so reach is decided by IK)"
        )


#: Numeric reach (:class:`NumericReach`): random starts besides the initial configuration, their seed, and the errors that count as reached [m], [rad].
REACH_SEEDS = 8
REACH_SEED = 0
REACH_POSITION_TOLERANCE_M = 1e-4
REACH_ORIENTATION_TOLERANCE_RAD = 1e-3


def numeric_reach(task: Task, hand: str) -> NumericReach:
    """The numeric reach test of ``hand`` for ``task``: the arm's joints free (and the waist's when the task frees it), the rest at the initial configuration."""
    robot = task.robot
    chain = task.hand_chain_from_root(hand)
    arm = set(robot.hand_chain(hand).joint_names)
    names = chain.joint_names
    free = tuple(i for i, n in enumerate(names) if n in arm or task.spec.waist == "free")
    lower, upper = robot.lower_upper(tuple(names[i] for i in free))
    initial = np.array([task.initial_q[n] for n in names])
    rng = np.random.default_rng(REACH_SEED)
    low, high = np.clip(lower, -np.pi, np.pi), np.clip(upper, -np.pi, np.pi)  # continuous joints: one turn
    seeds = np.vstack([initial[list(free)], rng.uniform(low, high, (REACH_SEEDS, len(free)))])
    return NumericReach(hand=hand, chain=chain, free=free, q_initial=initial, lower=lower, upper=upper, seeds=seeds)


def arm_reach(task: Task, hand: str) -> "ArmReach | NumericReach":
    """The reach test of ``hand`` for ``task`` (waist at its initial configuration, or free): :class:`ArmReach` in closed form for an S-R-S arm, else :class:`NumericReach`."""
    robot = task.robot
    arm = robot.hand_chain(hand)
    try:
        geometry = srs_geometry(arm)
    except NotSRSError:
        return numeric_reach(task, hand)
    to_arm = robot.chain_between(robot.urdf.root, arm.base)
    centre = None
    if task.spec.waist == "free" and to_arm.dof:
        frame = np.eye(4)  # the first waist joint's frame, which no waist motion moves
        for joint in to_arm.joints:
            frame = frame @ origin_matrix(joint)
            if joint.movable:
                break
        centre = frame[:3, 3]
    return ArmReach(hand=hand, geometry=geometry, shoulder=shoulder_position(robot, hand, task.initial_q), waist_centre=centre)


def _check_reach(task: Task) -> None:
    spec = task.spec
    for hand in spec.hands:
        names = [getattr(spec.start, hand)] + [move.to for m in spec.moves if (move := m.for_hand(hand)) is not None]
        names = [n for n in names if n is not None and n != "initial"]
        if not names:
            continue
        reach = arm_reach(task, hand)
        for name in dict.fromkeys(names):
            T = task.waypoint_pose(name)
            if not reach.within(T[None])[0]:
                raise UnreachablePoseError(f"{task.where(f'waypoints.{name}')}: {reach.explain(T)}")


def frame_pose(robot: Robot, name: str, q: Mapping[str, float]) -> np.ndarray:
    """The pose (4, 4) [m] of frame ``name`` in the robot base frame at configuration ``q`` [rad]: a role of :data:`~dualarm.tasks.schema.FRAME_ROLES` (checked first) or a URDF link.

    ``left.shoulder`` / ``right.shoulder``: that hand's shoulder centre S (:func:`shoulder_position`); ``shoulders``: the
    midpoint of the two; both with the robot base frame's axes (so a role only moves the origin).
    A link: its frame, the joints between the root and it at ``q``.

    Raises:
        NotSRSError: an arm without a shoulder centre for a shoulder role; KeyError: an unknown name.
    """
    if name in FRAME_ROLES:
        hands = ("left", "right") if name == "shoulders" else (name.split(".")[0],)
        T = np.eye(4)
        T[:3, 3] = np.mean([shoulder_position(robot, hand, q) for hand in hands], axis=0)
        return T
    if name not in robot.urdf.links:
        raise KeyError(name)
    chain = robot.chain_between(robot.urdf.root, name)
    return ChainKinematics.of(chain).pose(np.array([q[n] for n in chain.joint_names]))


def shoulder_position(robot: Robot, hand: str, q: Mapping[str, float]) -> np.ndarray:
    """The shoulder centre S of ``hand``'s arm in the robot base frame at configuration ``q`` [m], (3,): where an S-R-S arm's joints 1-3 meet, else the SEW angle's S on joint 1's axis (:mod:`dualarm.ik.sew`: where joints 1-3 meet, or the point of joint 1's axis nearest where joints 2 and 3 meet).

    Raises:
        NotSRSError: the arm is neither S-R-S nor of a SEW family (the SEW solver's one line).
    """
    arm = robot.hand_chain(hand)
    to_arm = robot.chain_between(robot.urdf.root, arm.base)
    T = ChainKinematics.of(to_arm).pose(np.array([q[n] for n in to_arm.joint_names]))
    return T[:3, :3] @ _shoulder_and_length(arm)[0] + T[:3, 3]


def arm_scale(robot: Robot, hands: Sequence[str]) -> float:
    """``scale = "arm"``'s factor: the mean arm length of ``hands``' arms (S-R-S: upper arm + forearm, L2 + L3; else |SE| + |EW| at q = 0 of the SEW angle's points) over :data:`~dualarm.tasks.schema.REFERENCE_ARM_M` (the humanoid's)."""
    return float(np.mean([_shoulder_and_length(robot.hand_chain(hand))[1] for hand in hands])) / REFERENCE_ARM_M


def _shoulder_and_length(arm: Chain) -> tuple[np.ndarray, float]:
    """The shoulder centre S [m] (3,) in the arm's base frame and the arm's length [m]: an S-R-S arm's S and L2 + L3; else those of the SEW angle's points at q = 0 (S, and |SE| + |EW|), which on an S-R-S arm are the same.

    Raises:
        NotSRSError: the arm is neither S-R-S nor of a SEW family (the SEW solver's one line).
    """
    from dualarm.ik.sew import sew_chain

    try:
        geometry = srs_geometry(arm)
        return geometry.shoulder, geometry.reach
    except NotSRSError:
        sew = sew_chain(arm)
        return sew.shoulder, float(np.linalg.norm(sew.elbow - sew.shoulder) + np.linalg.norm(sew.wrist - sew.elbow))


def _in_frame(spec: TaskSpec, robot: Robot, q: Mapping[str, float], source: str) -> TaskSpec:
    """``spec`` with its waypoints, ``by`` displacements and arcs taken from its ``frame`` (and ``scale``) into the robot base frame, at configuration ``q``; ``frame`` and ``scale`` then None.

    A pose (p, R) in the frame F becomes F (s p, R): the position scaled by s, then both moved by F.
    A role frame has the base frame's axes, so a waypoint's rpy is kept as written (bit for bit).
    """
    if spec.frame is None and spec.scale is None:
        return spec
    from scipy.spatial.transform import Rotation

    hands = tuple(h for h in spec.hands if h in robot.hands) or tuple(robot.hands)  # no hand driven: every arm
    try:
        F = np.eye(4) if spec.frame is None else frame_pose(robot, spec.frame, q)
        s = arm_scale(robot, hands) if spec.scale == "arm" else 1.0
    except KeyError:
        ends = dict.fromkeys(link for chain in robot.chains.values() for link in (chain.base, chain.tip))
        raise TaskFileError(
            f"{source}:frame: robot '{excerpt(robot.name, 40)}' has no frame '{excerpt(spec.frame, 40)}' "
            f"(roles: {listing(FRAME_ROLES)}; or a link: the chains' {listing(ends, 6)}, or another of its {len(robot.urdf.links)} links)"
        ) from None
    except (NotSRSError, RobotModelError) as exc:
        key = "scale" if spec.frame is None or spec.frame not in FRAME_ROLES else "frame"
        raise TaskFileError(f"{source}:{key}: needs the shoulder centre of every driven arm: {exc}") from None
    R, o = F[:3, :3], F[:3, 3]
    rotated = not np.array_equal(R, np.eye(3))

    def point(p: tuple[float, float, float]) -> tuple[float, float, float]:
        return tuple(float(v) for v in R @ (s * np.asarray(p)) + o)  # type: ignore[return-value]

    def vector(v: tuple[float, float, float], length: float) -> tuple[float, float, float]:
        return tuple(float(x) for x in R @ (length * np.asarray(v)))  # type: ignore[return-value]

    waypoints = {}
    for name, wp in spec.waypoints.items():
        rpy = tuple(float(a) for a in Rotation.from_matrix(R @ pose_matrix(wp.position, wp.rpy)[:3, :3]).as_euler("xyz")) if rotated else wp.rpy
        try:
            waypoints[name] = Pose(position=point(wp.position), rpy=rpy)  # type: ignore[arg-type]
        except ValidationError:
            raise TaskFileError(f"{source}:waypoints.{excerpt(name, 40)}: in the robot base frame its position {point(wp.position)} m is outside [-100, 100] m") from None
    moves = []
    for move in spec.moves:
        update = {}
        for hand in ("left", "right"):
            m = move.for_hand(hand)
            if m is not None and m.by is not None:
                update[hand] = m.model_copy(update={"by": vector(m.by, s)})
            elif m is not None and m.arc_center is not None and m.arc_axis is not None:
                update[hand] = m.model_copy(update={"arc_center": point(m.arc_center), "arc_axis": vector(m.arc_axis, 1.0)})
        moves.append(move.model_copy(update=update))
    return spec.model_copy(update={"waypoints": waypoints, "moves": tuple(moves), "frame": None, "scale": None})


def _transferred(spec: TaskSpec, robot: Robot) -> TaskSpec:
    """``spec`` with ``transfer.initial``, ``transfer.gesture`` and ``transfer.limits`` in place of ``initial``, ``gesture`` and ``limits``, and its moves' durations times ``transfer.duration_scale``, when ``robot`` is not the one ``transfer.written_for`` names (by robot.toml's ``name``)."""
    if spec.transfer is None or robot.name == spec.transfer.written_for:
        return spec
    k, period = spec.transfer.duration_scale, spec.control_period_s
    moves = tuple(m.model_copy(update={"duration_s": round(m.duration_s * k / period) * period}) for m in spec.moves) if k != 1.0 else spec.moves
    return spec.model_copy(update={"initial": spec.transfer.initial, "gesture": spec.transfer.gesture, "limits": spec.transfer.limits, "moves": moves})


def _check_environment(task: Task) -> None:
    """Refuse a fixed object that overlaps a link of the robot's base (a link no joint moves), by PyBullet's closest points (imported only for tasks with objects)."""
    if not task.spec.environment:
        return
    from dualarm.execute.world import add_environment, load_pybullet_robot, pb

    with load_pybullet_robot(task.robot.urdf.path) as sim:
        client = sim.client
        moved = {-1: False}
        for i in range(pb.getNumJoints(sim.body, physicsClientId=client)):
            info = pb.getJointInfo(sim.body, i, physicsClientId=client)
            moved[i] = moved[info[16]] or info[2] != pb.JOINT_FIXED
        base = [i for i in sim.collision_links() if not moved[i]]
        name = {i: n for n, i in sim.link_index.items()}
        for index, (body, obj) in enumerate(add_environment(sim, task.spec.environment).items()):  # in the file's order
            for link in base:
                points = pb.getClosestPoints(sim.body, body, 0.0, linkIndexA=link, physicsClientId=client)
                if points:
                    depth = -min(p[8] for p in points)
                    raise TaskFileError(
                        f"{task.where(f'environment[{index}]')}: '{excerpt(obj, 40)}' overlaps the robot's base link '{name[link]}' ({depth * 1e3:.1f} mm deep); move it away from the robot"
                    )


def load_task(path: str | Path, repetitions: int | None = None, robot: str | Path | None = None) -> Task:
    """Read, validate and resolve a task file; ``repetitions`` overrides the file's, ``robot`` (a robot directory or shipped robot's name) the robot it names.

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
    """The task file at ``path`` with every hand it starts staying at the initial configuration and no moves, as :func:`load_task` loads it (errors name the file): ``dualarm task check`` loads it so when a waypoint is out of reach, to report every waypoint."""
    return _load_file(path, None, robot, lambda data: {**data, "start": {hand: "initial" for hand in data.get("start", {})}, "moves": []})


def _load_file(path: str | Path, repetitions: int | None, robot: str | Path | None, edit: Callable[[dict], dict] = lambda data: data) -> Task:
    """:func:`load_task`, the file's keys passed through ``edit`` before validation."""
    from dualarm.data import find_task

    file = find_task(path)
    text, data = _read(file)
    spec = _validate(str(file), edit(data))
    if robot is not None:
        spec = spec.model_copy(update={"robot": str(robot)})
    return _resolve(spec, file, text, file.parent if robot is None else Path.cwd(), None, repetitions)


def task_from_dict(data: Mapping[str, Any] | None = None, /, *, robot: Robot | str | Path | None = None, base_dir: str | Path = ".", **keys: Any) -> Task:
    """A task from a plain dict and/or keyword arguments, with the keys and checks of a task file (see ``tasks/README.md``): ``task_from_dict(name="circle", control_period_s=0.01, ...)``.

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
    """``path`` made absolute with symbolic links resolved, or as given when the OS cannot (loading it then says why)."""
    try:
        return path.resolve()
    except (OSError, ValueError, RuntimeError):  # RuntimeError: a symlink loop, before Python 3.13
        return path


def _resolve(spec: TaskSpec, file: Path | None, text: str, base: Path, robot: Robot | None, repetitions: int | None) -> Task:
    """The validated task: the robot loaded (unless given) with the task's limits, the initial configuration resolved, and every check run."""
    source = excerpt(file) if file is not None else "<dict>"
    if repetitions is not None:
        if isinstance(repetitions, bool) or not isinstance(repetitions, int) or not 1 <= repetitions <= MAX_REPETITIONS:
            raise TaskFileError(f"{source}:repetitions: the override must be an integer in [1, {MAX_REPETITIONS}], not {excerpt(repr(repetitions), 24)}")
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
