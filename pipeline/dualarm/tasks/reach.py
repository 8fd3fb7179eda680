"""Whether each hand's poses are within its arm's reach.

The analytic S-R-S bound, else a numeric IK check.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dualarm.errors import NotSRSError, TaskFileError, UnreachablePoseError, excerpt
from dualarm.model.kinematics import ChainKinematics, origin_matrix
from dualarm.model.robot import Chain
from dualarm.model.srs import SrsGeometry, srs_geometry
from dualarm.tasks.frames import shoulder_position
from dualarm.tasks.task import Task

#: Margin kept from the fully stretched or fully folded arm when checking reach [m].
REACH_MARGIN_M = 1e-3


def _check_margin(task: Task) -> None:
    """Refuse an ``arm_angle.margin_rad`` too large for a driven arm's joints.

    Half the narrowest position range of a driven arm's joints or more: no configuration keeps it from both limits
    of that joint.
    """
    robot, margin = task.robot, task.spec.arm_angle.margin_rad
    ranges = {
        name: robot.limits[name].upper - robot.limits[name].lower
        for hand in task.spec.hands
        if hand in robot.hands
        for name in robot.hand_chain(hand).joint_names
    }
    if not ranges:
        return
    joint = min(ranges, key=lambda n: ranges[n])
    half = ranges[joint] / 2
    if not margin < half:
        raise TaskFileError(
            f"{task.where('arm_angle.margin_rad')}: {margin:g} rad is outside the allowed range [0, {half:.4g}) rad "
            f"(below half the range of joint '{excerpt(joint, 40)}', the narrowest of the driven arms)"
        )


@dataclass(frozen=True)
class ArmReach:
    """The workspace test of one hand of an S-R-S arm, in closed form.

    The wrist centre W of a hand pose must lie within [|L2 - L3|, L2 + L3] of the shoulder S (less
    :data:`REACH_MARGIN_M`).

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
        return (
            f"the {self.hand} hand cannot reach [{p}] with this orientation: its wrist centre is {d:.3f} m "
            f"from {origin}, the arm spans {self.geometry.min_reach:.3f}-{self.geometry.reach:.3f} m"
        )


@dataclass(frozen=True)
class NumericReach:
    """The workspace test of one hand of any arm.

    A pose is within reach when a numeric IK solve inside the joint limits reaches it.

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
        """One bounded solve for pose T (4, 4) from ``start`` (k,).

        Returns (free joints [rad], position error [m], orientation error [rad]).
        """
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
        result = least_squares(
            residual, x0, jac=jacobian, bounds=(self.lower, self.upper), method="dogbox", max_nfev=50
        )
        r = residual(result.x)
        return result.x, float(np.linalg.norm(r[:3])), float(np.linalg.norm(r[3:]))

    def solve(self, T: np.ndarray, warm: np.ndarray | None = None) -> tuple[np.ndarray | None, float, float]:
        """The free joints [rad] reaching pose T (4, 4) within the limits, or None.

        From ``warm`` then every seed; with the smallest position [m] and orientation [rad] errors met.
        """
        best = (np.inf, np.inf)
        for start in ([warm] if warm is not None else []) + list(self.seeds):
            x, position, orientation = self._solve(T, start)
            if position <= REACH_POSITION_TOLERANCE_M and orientation <= REACH_ORIENTATION_TOLERANCE_RAD:
                return x, position, orientation
            best = min(best, (position, orientation))
        return None, *best

    def within(self, T: np.ndarray) -> np.ndarray:
        """Which of the hand poses T (N, 4, 4) pass; (N,) bool.

        Poses equal to 1e-9 (a repeated path's) are solved once, in order, each from the previous one's solution.
        """
        T = np.asarray(T, dtype=float)
        _, first, inverse = np.unique(
            np.round(T.reshape(len(T), 16), 9), axis=0, return_index=True, return_inverse=True
        )
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
            f"the {self.hand} hand cannot reach [{p}] with this orientation within the joint limits: "
            f"numeric IK from {len(self.seeds)} starts "
            f"came no closer than {position:.3g} m and {orientation:.3g} rad "
            "(this arm is not S-R-S, so reach is decided by IK)"
        )


#: Numeric reach (:class:`NumericReach`): random starts besides the initial configuration, their seed, and
#: the errors that count as reached [m], [rad].
REACH_SEEDS = 8
REACH_SEED = 0
REACH_POSITION_TOLERANCE_M = 1e-4
REACH_ORIENTATION_TOLERANCE_RAD = 1e-3


def numeric_reach(task: Task, hand: str) -> NumericReach:
    """The numeric reach test of ``hand`` for ``task``.

    The arm's joints free (and the waist's when the task frees it), the rest at the initial configuration.
    """
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


def arm_reach(task: Task, hand: str) -> ArmReach | NumericReach:
    """The reach test of ``hand`` for ``task`` (waist at its initial configuration, or free).

    :class:`ArmReach` in closed form for an S-R-S arm, else :class:`NumericReach`.
    """
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
    return ArmReach(
        hand=hand, geometry=geometry, shoulder=shoulder_position(robot, hand, task.initial_q), waist_centre=centre
    )


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
