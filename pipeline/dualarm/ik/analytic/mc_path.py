"""MC-Inverse along a Cartesian path: the arm angle per sample, one kept branch, checked steps.

Zou, Min, Xu's consistency argument (section III.B, V): when the arm angle psi is a function of
where the hand is on the task, and not of how it got there, and the same solution branch is kept
throughout, then every repetition of a path gives the same joints. Here psi follows the task's
``[arm_angle]`` table (``auto``, the default: the least-travel profile within the limits found
over the first repetition, see :func:`_auto`; the initial configuration's psi held; a constant; or
a schedule over the time within a repetition). :func:`arm_angle_profiles` reads back the profile
and branch a path follows (the run's manifest and metrics hold them). The branch (elbow, shoulder
and wrist root of the 8 candidates) is the one nearest the initial configuration at the first
sample (``auto`` picks it with the profile), and it is kept. A sample where that branch is
invalid, or where a joint moves more than ``max_joint_step_rad`` between samples, fails the stage
with the sample, the time and the joint named; nothing is silently swapped.

Each arm is solved in its chain base frame (the torso); a free waist is held at its initial
value, because MC-Inverse solves 7-DOF arms (see :mod:`dualarm.ik.arms`). One pose alone:
:func:`dualarm.ik.analytic.mc_inverse.mc_inverse`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from dualarm.contracts.joint_path import JointPath
from dualarm.contracts.reference import CartesianReference, first_repetition_index, time_in_repetition
from dualarm.errors import NoSolutionFound, StageError
from dualarm.ik.analytic.mc_inverse import OUTSIDE_LIMITS, REASONS, VALID, McInverse, branch_label, nearest_candidate
from dualarm.ik.arms import ArmProblem, ArmSolution, arm_problems, joint_path
from dualarm.method import Method, Recorded
from dualarm.model.robot import Robot
from dualarm.settings import with_overrides
from dualarm.tasks.schema import ArmAngle

if TYPE_CHECKING:
    from dualarm.tasks import Task


#: Offsets of the arm angles the ``auto`` mode searches, around the preferred one [rad] (1 degree).
AUTO_GRID = np.linspace(-np.pi, np.pi, 360, endpoint=False)
#: Most grid cells the ``auto`` arm angle moves between two samples.
AUTO_MAX_CELLS = 2
#: Every how many grid cells the ``auto`` mode tries a start angle.
START_STRIDE = 2
#: Weight of the start's distance from the preferred arm angle and the initial joints: a tie-break.
START_WEIGHT = 0.1
#: Most times the ``auto`` search plans again around the samples where its profile collided.
CLEARANCE_ROUNDS = 30

#: Whether configurations of one arm's joints keep it clear of the robot and the task's objects: (hand, Q (M, 7)
#: [rad], the arm's joints in chain order) -> (M,) bool. The IK stage makes one from the planners' closed-form
#: collision checker (:class:`dualarm.plan.clearance.ArmClearance`); ``auto`` keeps to the configurations it passes.
Clearance = Callable[[str, np.ndarray], np.ndarray]


def arm_clearance(clearance: Clearance | None, hand: str) -> Callable[[np.ndarray], np.ndarray] | None:
    """``clearance`` for ``hand``'s arm alone: Q (M, 7) [rad] -> (M,) bool; None for None."""
    return None if clearance is None else (lambda Q: clearance(hand, Q))


def settings_for(task: Task, **overrides: object) -> ArmAngle:
    """MC-Inverse's settings for a task: its ``[arm_angle]`` table, with ``overrides``."""
    return with_overrides(task.spec.arm_angle.settings(), overrides)


def arm_angles(spec: ArmAngle, hand: str, reference: CartesianReference, initial: float) -> np.ndarray:
    """Psi per sample (N,) [rad] for ``hand`` by the ``[arm_angle]`` settings ``spec``.

    ``initial`` is the arm's initial configuration's psi [rad] (``auto`` gives it too, the preferred
    one; see :func:`_auto`). SEW IK's angle follows the same modes (:mod:`dualarm.ik.analytic.sew_path`).
    """
    N = len(reference)
    if spec.mode in ("initial", "auto"):
        return np.full(N, initial)
    if spec.mode == "constant":
        if hand not in spec.value_rad:
            raise StageError(f"arm_angle.value_rad has no value for the {hand} hand", stage="ik")
        return np.full(N, spec.value_rad[hand])
    if hand not in spec.schedule:
        raise StageError(f"arm_angle.schedule has no entry for the {hand} hand", stage="ik")
    times, values = np.array(spec.schedule[hand]).T
    return np.interp(time_in_repetition(reference.t, reference.rep), times, values)


#: The default settings of :func:`solve_mc_inverse`: the ``[arm_angle]`` table's defaults.
DEFAULT_ARM_ANGLE = ArmAngle()


def solve_mc_inverse(
    robot: Robot,
    reference: CartesianReference,
    q0: Mapping[str, float] | str | None = None,
    settings: ArmAngle = DEFAULT_ARM_ANGLE,
    clearance: Clearance | None = None,
) -> JointPath:
    """Joint path of every hand of ``reference`` by MC-Inverse, each arm an S-R-S chain.

    Args:
        robot: the robot.
        reference: the hands' poses (position and orientation).
        q0: the initial configuration (a home pose's name or joint -> value [rad], others at 0):
            the branch kept is the one nearest it at the first sample, and the joints between the
            reference's frame and the arms (a waist) hold their values.
        settings: how the arm angle is chosen (the task file's ``[arm_angle]`` table).
        clearance: for ``auto``, which configurations of an arm keep it clear of collisions (None: any).

    Raises:
        NotSRSError: an arm is not S-R-S.
        StageError: a sample where the kept branch is invalid (out of reach, singular, outside
            the limits) or a joint step above ``max_joint_step_rad``; the error's ``sample``,
            ``t_s`` and ``joint`` say where.
    """
    spec = settings
    q0 = robot.configuration(q0, "q0")
    arms = arm_solvers(robot, reference, q0, spec)
    solutions = []
    for arm, solver, initial in arms:
        psi = arm_angles(spec, arm.hand, reference, initial)
        start = time.perf_counter()
        branch = None
        if spec.mode == "auto":
            psi, branch = _auto(
                solver, arm.targets, reference, psi[0], arm.q0, spec, arm.hand, arm_clearance(clearance, arm.hand)
            )
        candidates, reasons = solver.solve_many(arm.targets, psi)
        elapsed = time.perf_counter() - start
        q = _kept_branch(arm.hand, solver, arm.q0, reference, psi, candidates, reasons, spec.max_joint_step_rad, branch)
        solutions.append(
            ArmSolution(
                q=q, ok=np.ones(len(reference), bool), solve_time_s=np.full(len(reference), elapsed / len(reference))
            )
        )
    return joint_path("mc-inverse", reference, [arm for arm, _, _ in arms], solutions, q0)


def arm_solvers(
    robot: Robot, reference: CartesianReference, q0: Mapping[str, float], spec: ArmAngle
) -> list[tuple[ArmProblem, McInverse, float]]:
    """Each arm of ``reference``, its MC-Inverse solver and its initial configuration's arm angle [rad].

    The arms are :func:`~dualarm.ik.arms.arm_problems` at the configuration ``q0``; each solver has
    ``spec.vertical`` as the arm angle's reference direction.
    """
    vertical = tuple(np.asarray(spec.vertical) / np.linalg.norm(spec.vertical))
    arms = []
    for arm in arm_problems(robot, reference, q0):
        solver = McInverse.of(arm.chain, vertical)
        arms.append((arm, solver, float(solver.kinematics.arm_angles(arm.q0)[0])))
    return arms


def _kept_branch(
    hand: str,
    solver: McInverse,
    q0: np.ndarray,
    reference: CartesianReference,
    psi: np.ndarray,
    candidates: np.ndarray,
    reasons: np.ndarray,
    max_step: float,
    branch: int | None = None,
) -> np.ndarray:
    """The candidate ``branch``, checked along the path.

    ``branch`` is by default the one nearest ``q0`` [rad] at sample 0; ``psi`` (N,) [rad] the arm
    angle per sample.
    """
    names = solver.chain.joint_names
    if branch is None:
        branch = nearest_candidate(candidates[0], reasons[0], q0)
        if branch is None:
            why = ", ".join(sorted({REASONS[int(r)] for r in reasons[0]}))
            nearest = int(np.argmin(np.abs(candidates[0] - q0).max(axis=1)))
            outside = reasons[0, nearest] == OUTSIDE_LIMITS
            detail = _limit_detail(solver, candidates[0, nearest]) if outside else ""
            raise NoSolutionFound(
                f"MC-Inverse, {hand} arm: no valid solution at the path start ({why}){detail} "
                f"at psi = {psi[0]:.4f} rad; {LIMIT_HINT}",
                stage="ik",
                sample=0,
                t_s=float(reference.t[0]),
                joint=names[_worst_joint(solver, candidates[0, nearest])] if outside else None,
            )
    q = candidates[:, branch]
    invalid = np.flatnonzero(reasons[:, branch] != VALID)
    if invalid.size:
        k = invalid[0]
        outside = reasons[k, branch] == OUTSIDE_LIMITS
        joint = names[_worst_joint(solver, q[k])] if outside else None
        raise StageError(
            f"MC-Inverse, {hand} arm: sample {k} (t = {reference.t[k]:.3f} s, rep {reference.rep[k]}) "
            f"has no valid solution on the kept branch {branch + 1}: "
            f"{REASONS[int(reasons[k, branch])]}{_limit_detail(solver, q[k]) if outside else ''} "
            f"at psi = {psi[k]:.4f} rad; {LIMIT_HINT}",
            stage="ik",
            sample=int(k),
            t_s=float(reference.t[k]),
            joint=joint,
        )
    steps = np.abs(np.diff(q, axis=0))
    jumps = np.argwhere(steps > max_step)
    if jumps.size:
        k, j = jumps[0]
        raise StageError(
            f"MC-Inverse, {hand} arm: {names[j]} jumps {steps[k, j]:.3f} rad between samples {k} and {k + 1} "
            f"(t = {reference.t[k + 1]:.3f} s), above arm_angle.max_joint_step_rad = {max_step}",
            stage="ik",
            sample=int(k + 1),
            t_s=float(reference.t[k + 1]),
            joint=names[j],
        )
    return q


#: What a user can do when a branch leaves the joint limits.
LIMIT_HINT = (
    'set [arm_angle] mode = "auto" in the task (or a range_rad the arm angle may use; '
    "dualarm task check and dualarm ik srs --sweep show the feasible psi)"
)


def _worst_joint(solver: McInverse, q: np.ndarray) -> int:
    """The joint of ``q`` (7,) [rad] farthest outside its limits."""
    return int(np.argmax(np.maximum(q - solver.upper, solver.lower - q)))


def _limit_detail(solver: McInverse, q: np.ndarray) -> str:
    """The detail of a message on a candidate ``q`` (7,) [rad] outside the limits: its worst joint.

    Such as ``: left_elbow at 2.1000 rad is 0.1000 rad (5.7 deg) above its upper limit 2.0000 rad``.
    """
    j = _worst_joint(solver, q)
    above = q[j] > solver.upper[j]
    excess = q[j] - solver.upper[j] if above else solver.lower[j] - q[j]
    side, limit = ("above its upper", solver.upper[j]) if above else ("below its lower", solver.lower[j])
    return (
        f": {solver.chain.joint_names[j]} at {q[j]:.4f} rad is {excess:.4f} rad "
        f"({np.degrees(excess):.1f} deg) {side} limit {limit:.4f} rad"
    )


def _wrap(angle):
    return np.angle(np.exp(1j * np.asarray(angle)))


def _auto(
    solver: McInverse,
    targets: np.ndarray,
    reference: CartesianReference,
    preferred: float,
    q0: np.ndarray,
    spec: ArmAngle,
    hand: str,
    clear: Callable[[np.ndarray], np.ndarray] | None = None,
) -> tuple[np.ndarray, int]:
    """The arm angle per sample (N,) [rad] and the branch (0-7) for the ``auto`` mode.

    A shortest path over the grid of (sample, arm angle) of the first repetition, per branch:
    a node is allowed where the branch is valid within the limits and psi within
    the open interval ``spec.range_rad``, a step where psi moves at most :data:`AUTO_MAX_CELLS` grid
    cells and no joint more than ``spec.max_joint_step_rad``. The cost is the path's travel, sum over steps of
    |change of psi| + the largest joint change [rad], plus per sample how far the branch comes
    closer than ``spec.margin_rad`` to a limit [rad], plus, weighted by
    :data:`START_WEIGHT`, the start's distance from ``preferred`` and its largest joint distance
    from ``q0`` [rad]. On a closed path the profile must end on the angle it began with, so that
    every repetition repeats it and gives the same joints. The least-cost branch is kept.

    With ``clear`` (which arm configurations are free of collisions), the search is lazy: the cheapest profile's
    configurations are checked, and where one collides every cell and branch of that sample is checked and those
    that collide are taken out of the graph; then it plans again, up to :data:`CLEARANCE_ROUNDS` times. A profile
    clear of collisions from the start costs one check of its samples.

    Raises:
        StageError: no branch has such a path; names the sample where the longest one ends (and whether
            collisions ended it).
    """
    first = np.flatnonzero(reference.rep == reference.rep[0])
    n = len(first)
    grid = _wrap(preferred + AUTO_GRID)
    candidates, margins = solver.margins_on_grid(targets[first], grid)  # (n, G, 8, 7), (n, G, 8)
    in_range = (grid > spec.range_rad[0]) & (grid < spec.range_rad[1])
    nodes = np.where(
        (margins >= 0) & in_range[None, :, None], np.maximum(0.0, spec.margin_rad - margins), np.inf
    )  # (n, G, 8)
    with np.errstate(invalid="ignore"):
        starts = nodes[0] + START_WEIGHT * (
            np.abs(_wrap(grid - preferred))[:, None] + np.abs(candidates[0] - q0).max(axis=-1)
        )  # (G, 8)
    closed = bool(np.abs(targets[first[0]] - targets[first[-1]]).max() < 1e-9)
    steps: dict[tuple[int, int], np.ndarray] = {}  # (branch, samples) -> step costs, kept between rounds
    collided = 0
    for _ in range(CLEARANCE_ROUNDS + 1):
        best, reached = None, 0
        for branch in range(8):
            node = nodes[:, :, branch]
            dead = np.flatnonzero(~np.isfinite(node).any(axis=1))  # no profile gets past a sample without a node
            alive = int(dead[0]) + 1 if dead.size else n
            if (branch, alive) not in steps:
                steps[branch, alive] = _step_costs(candidates[:alive, :, branch], spec.max_joint_step_rad)
            plan = _cheapest_profile(node[:alive], steps[branch, alive], starts[:, branch], closed, n)
            if isinstance(plan, int):
                reached = max(reached, plan)
            elif best is None or plan[0] < best[0]:
                best = (plan[0], plan[1], branch)
        if best is None or clear is None:
            break
        _, cells, branch = best
        hit = np.flatnonzero(~clear(candidates[np.arange(n), cells, branch]))
        if not hit.size:
            break
        collided += hit.size
        Q = candidates[hit]  # (h, G, 8, 7): every cell and branch of the samples that collided
        checkable = np.isfinite(nodes[hit])
        free = np.zeros(checkable.shape, bool)
        free[checkable] = clear(Q[checkable])
        nodes[hit] = np.where(free, nodes[hit], np.inf)
        starts = np.where(np.isfinite(nodes[0]), starts, np.inf)
    else:
        best = None
    if best is None:
        k = first[reached]
        raise StageError(
            f"MC-Inverse, {hand} arm: no arm angle in arm_angle.range_rad keeps any branch inside the joint limits "
            f"with joint steps within arm_angle.max_joint_step_rad = {spec.max_joint_step_rad} "
            + ("and the arm clear of collisions " if collided else "")
            + f"beyond sample {k} (t = {reference.t[k]:.3f} s)"
        )
    _, cells, branch = best
    profile = grid[cells]
    # later repetitions repeat the first one's poses: the first repetition's sample at the same time
    return profile[first_repetition_index(reference.t, reference.rep, reference.period_s)], branch


#: The arm-angle moves of one step, in grid cells (-W..W).
SHIFTS = np.arange(-AUTO_MAX_CELLS, AUTO_MAX_CELLS + 1)


#: Samples whose step costs :func:`_step_costs` computes at once (their arrays stay in the CPU's cache).
STEP_CHUNK = 32


def _step_costs(q: np.ndarray, max_step: float) -> np.ndarray:
    """The cost of the step into grid cell g at sample k from cell g - d at k - 1, d = -W..W.

    |change of psi| + the largest joint change [rad], inf where a joint moves more than ``max_step``:
    q (n, G, 7) [rad] -> (n - 1, G, 2 W + 1).
    """
    W, G = AUTO_MAX_CELLS, q.shape[1]
    joints = np.ascontiguousarray(
        np.moveaxis(q, -1, 0)
    )  # (7, n, G): the largest change is a maximum over 7 arrays, not a reduction over a short axis
    costs = np.empty((len(SHIFTS), len(q) - 1, G))
    with np.errstate(invalid="ignore"):
        for a in range(0, len(q) - 1, STEP_CHUNK):
            b = min(a + STEP_CHUNK, len(q) - 1)
            previous = np.concatenate(
                [joints[:, a:b, G - W :], joints[:, a:b], joints[:, a:b, :W]], axis=-1
            )  # wrapped around the grid
            change, joint = costs[:, a:b], np.empty((b - a, G))
            for j, d in enumerate(SHIFTS):
                np.abs(
                    np.subtract(joints[0, a + 1 : b + 1], previous[0, :, W - d : W - d + G], out=change[j]),
                    out=change[j],
                )
                for i in range(1, len(joints)):
                    np.maximum(
                        change[j],
                        np.abs(
                            np.subtract(joints[i, a + 1 : b + 1], previous[i, :, W - d : W - d + G], out=joint),
                            out=joint,
                        ),
                        out=change[j],
                    )
            change[~(change <= max_step)] = np.inf
    return np.moveaxis(costs, 0, -1) + np.abs(SHIFTS) * (2 * np.pi / G)


#: Start cells whose profiles one pass of :func:`_cheapest_profile` follows at once.
START_BATCH = 8


def _cheapest_profile(node: np.ndarray, step_cost: np.ndarray, start: np.ndarray, closed: bool, n: int):
    """Dynamic programming over the (sample, grid cell) graph of :func:`_auto`.

    Node costs (m, G), step costs (m - 1, G, 2 W + 1) (see :func:`_step_costs`), start costs (G,),
    for the first m of the path's n samples (m < n: no node is allowed at sample m - 1).

    Every :data:`START_STRIDE`-th start cell is tried. One pass from all of them at once finds
    where profiles end, and one pass backwards the least cost from each cell to the path's end;
    with the start's cost, a lower bound of each start's profile. Starts are then followed in
    order of their bound, :data:`START_BATCH` at a time, until the next bound exceeds the least
    cost found: the result is that of following every start (the least cost, ties to the lowest
    start cell), at a fraction of the work.

    Returns (cost, cells (n,)) of the cheapest profile (ending on its start cell when ``closed``),
    or, when there is none, the first sample that no profile reaches.
    """
    m, G = node.shape
    W = AUTO_MAX_CELLS

    def forward(cost: np.ndarray, back: np.ndarray | None = None) -> np.ndarray | int:
        """Least costs (..., G) at the last sample from ``cost`` (..., G) at the first.

        Or the first sample none reaches; ``back`` (m, G) receives each cell's chosen shift.
        """
        best, option = np.empty(cost.shape), np.empty(cost.shape)
        for k in range(1, m):
            # cell g reached from cell g - d: the cost wrapped around the grid, shifted by d
            wrapped = np.concatenate([cost[..., G - W :], cost, cost[..., :W]], axis=-1)
            best.fill(np.inf)
            for j, d in enumerate(SHIFTS):
                np.add(wrapped[..., W - d : W - d + G], step_cost[k - 1, :, j], out=option)
                if back is not None:
                    back[k][option < best] = j
                np.minimum(best, option, out=best)
            cost = best + node[k]
            if not np.isfinite(cost).any():
                return k
        return cost

    starts = np.flatnonzero(np.isfinite(start))[::START_STRIDE]
    if starts.size == 0:
        return 0
    initial = np.full(G, np.inf)
    initial[starts] = start[starts]
    end = forward(initial)  # where the profiles of all the starts together end
    if isinstance(end, int):
        return end
    to_end = np.zeros(G)  # least cost from each cell of sample k to the last sample
    for k in range(m - 1, 0, -1):
        into = step_cost[k - 1] + (node[k] + to_end)[:, None]  # (G, 2W+1): into cell g by shift d
        wrapped = np.concatenate([into[G - W :], into, into[:W]])
        to_end = np.min(
            [wrapped[W + d : W + d + G, j] for j, d in enumerate(SHIFTS)], axis=0
        )  # from cell g by shift d into g + d
    bound = start[starts] + to_end[starts]
    totals = np.full(starts.size, np.inf)
    for batch in np.array_split(np.argsort(bound, kind="stable"), max(1, -(-starts.size // START_BATCH))):
        least = totals.min()
        batch = (
            batch[bound[batch] <= least + 1e-9 * max(1.0, abs(least))]
            if np.isfinite(least)
            else batch[np.isfinite(bound[batch])]
        )
        if batch.size == 0:
            break
        initial = np.full((batch.size, G), np.inf)
        initial[np.arange(batch.size), starts[batch]] = start[starts[batch]]
        end = forward(initial)
        if not isinstance(end, int):
            totals[batch] = end[np.arange(batch.size), starts[batch]] if closed else end.min(axis=1)
    if not np.isfinite(totals).any():
        return n - 1
    i = int(np.argmin(totals))
    back = np.zeros((m, G), np.int8)
    end = forward(np.where(np.arange(G) == starts[i], start, np.inf), back)
    assert not isinstance(end, int)  # the same start reaches the end again, now keeping the choices
    cells = np.empty(n, int)
    cells[-1] = starts[i] if closed else int(np.argmin(end))
    for k in range(n - 1, 0, -1):
        cells[k - 1] = (cells[k] - SHIFTS[back[k, cells[k]]]) % G
    return float(totals[i]), cells


@dataclass(frozen=True)
class ArmAngleProfile:
    """The arm-angle profile one arm of an MC-Inverse joint path follows, read from its joints.

    Attributes:
        hand: ``left`` or ``right``.
        mode: the ``[arm_angle]`` mode that chose it.
        branch: the kept branch, 0-7 (see :data:`~dualarm.ik.analytic.mc_inverse.CANDIDATES`; printed from 1).
        psi_min_rad, psi_max_rad: the smallest and largest arm angle along the path [rad]
            (unwrapped: a profile across +-pi may end beyond pi); equal for a held angle.
    """

    hand: str
    mode: str
    branch: int
    psi_min_rad: float
    psi_max_rad: float

    @property
    def constant(self) -> bool:
        """Whether the arm angle is held (it moves less than :data:`CONSTANT_TOLERANCE_RAD`)."""
        return self.psi_max_rad - self.psi_min_rad <= CONSTANT_TOLERANCE_RAD

    def record(self) -> dict:
        """JSON-ready: ``mode``, ``branch`` (1-8), ``value_rad`` for a held angle or ``range_rad``."""
        psi = {"value_rad": self.psi_min_rad} if self.constant else {"range_rad": [self.psi_min_rad, self.psi_max_rad]}
        return {"mode": self.mode, "branch": self.branch + 1, **psi}

    def metrics(self) -> dict[str, float]:
        """The arm angle's metrics of the hand: its branch and its range.

        ``ik.arm_angle_branch.<hand>`` (1-8), ``ik.arm_angle_min_rad.<hand>`` and
        ``ik.arm_angle_max_rad.<hand>``.
        """
        return {
            f"ik.arm_angle_branch.{self.hand}": float(self.branch + 1),
            f"ik.arm_angle_min_rad.{self.hand}": self.psi_min_rad,
            f"ik.arm_angle_max_rad.{self.hand}": self.psi_max_rad,
        }

    def line(self) -> str:
        """One line for the command line.

        Such as ``MC-Inverse, left arm: psi auto in [-1.2000, -0.8000] rad, branch 3 (elbow 0, shoulder 1, wrist 0)``.
        """
        psi = (
            f"held at {self.psi_min_rad:.4f} rad"
            if self.constant
            else f"in [{self.psi_min_rad:.4f}, {self.psi_max_rad:.4f}] rad"
        )
        return f"MC-Inverse, {self.hand} arm: psi {self.mode} {psi}, branch {branch_label(self.branch)}"


#: Largest spread of the arm angle along a path [rad] that counts as held.
CONSTANT_TOLERANCE_RAD = 1e-9


def arm_angle_profiles(path: JointPath, robot: Robot, settings: ArmAngle) -> tuple[ArmAngleProfile, ...]:
    """The arm-angle profile of each arm of an MC-Inverse joint path.

    Psi of eq (1) from its joints, and the branch, the candidate of MC-Inverse at the first sample's
    pose and psi equal to its joints.

    Raises:
        NotSRSError: an arm is not S-R-S.
    """
    from dualarm.model.kinematics import ChainKinematics

    vertical = tuple(np.asarray(settings.vertical) / np.linalg.norm(settings.vertical))
    profiles = []
    for hand in path.hands:
        chain = robot.hand_chain(hand)
        q = path.q[:, [path.joint_names.index(n) for n in chain.joint_names]]
        solver = McInverse.of(chain, vertical)
        psi = np.unwrap(solver.kinematics.arm_angles(q))
        candidates = solver.solve(ChainKinematics.of(chain).pose(q[0]), float(psi[0])).q
        branch = int(np.argmin(np.abs(candidates - q[0]).max(axis=1)))
        profiles.append(
            ArmAngleProfile(
                hand=hand, mode=settings.mode, branch=branch, psi_min_rad=float(psi.min()), psi_max_rad=float(psi.max())
            )
        )
    return tuple(profiles)


def recorded(path: JointPath, robot: Robot, settings: ArmAngle) -> Recorded:
    """MC-Inverse's arm-angle profile of each arm.

    Recorded as ``arm_angle_profile``, its metrics, a line per hand.
    """
    profiles = arm_angle_profiles(path, robot, settings)
    return Recorded(
        settings={"arm_angle_profile": {p.hand: p.record() for p in profiles}},
        metrics={k: v for p in profiles for k, v in p.metrics().items()},
        lines=tuple(p.line() for p in profiles),
    )


#: MC-Inverse in the registry (:data:`dualarm.methods.METHODS`).
METHODS: Mapping[str, Method[ArmAngle]] = {
    "mc-inverse": Method(
        "mc-inverse",
        "ik",
        "MC-Inverse: closed-form S-R-S IK at a chosen arm angle, one branch kept (Zou, Min, Xu)",
        solve_mc_inverse,
        ArmAngle,
        settings_for,
        arm="srs",
        recorded=recorded,
        clearance=True,
    )
}
