"""SEW IK along a Cartesian path (``--ik sew``).

The SEW angle per sample, every solution there, one kept, checked steps.

MC-Inverse's consistency argument (:mod:`dualarm.ik.analytic.mc_path`) for 7R arms that are not
S-R-S: when the SEW angle is a function of where the hand is on the task and the same solution is
followed, every repetition of a path gives the same joints. At each sample every solution at the
SEW angle is enumerated (:func:`dualarm.ik.analytic.sew.solve_many`, all samples at once); the one
kept is the one inside the joint limits nearest the initial configuration at the first sample,
then at each sample the one inside the limits nearest the previous sample's (a SEW solution has no
fixed branch label: the roots of the 1-D search appear and merge along a path, so the branch is
followed by continuity).
A sample without such a solution, or a joint step above ``max_joint_step_rad``, fails the stage
naming the sample, the time and the joint; nothing is swapped silently.

The SEW angle is Elias and Wen's stereographic one with e_r the task's ``[arm_angle] vertical`` and
the singular half-line from the shoulder along -e_r (into the base, out of reach). ``[arm_angle]``
modes: ``initial`` (the initial configuration's SEW angle, held), ``constant`` and ``schedule``, as
for MC-Inverse; ``auto`` plans a profile of least travel as MC-Inverse's does (:func:`_auto`), on a
coarser grid (each (sample, angle) costs a 1-D search) whose nodes are solutions, not fixed
branches; ``range_rad``, an interval of MC-Inverse's arm angle (another angle), is not used.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping

import numpy as np

from dualarm.contracts.joint_path import JointPath
from dualarm.contracts.reference import CartesianReference, first_repetition_index
from dualarm.errors import NoSolutionFound, StageError
from dualarm.ik.analytic import mc_path
from dualarm.ik.analytic.mc_path import START_WEIGHT, settings_for
from dualarm.ik.analytic.sew import SewAngle, SewSolutions, into_limits, solve_many
from dualarm.ik.arms import ArmProblem, ArmSolution, arm_problems, joint_path
from dualarm.method import Method
from dualarm.model.robot import Robot
from dualarm.model.sew import SewChain, sew_chain
from dualarm.tasks.schema import ArmAngle

__all__ = ["settings_for", "sew_angle_of", "solve_sew"]

#: ``auto``: SEW angles of the grid the profile moves on, evenly over the circle from the initial configuration's
#: (10 degrees apart).
AUTO_ANGLES = 36
#: ``auto``: samples of the first repetition the profile is planned on (evenly spaced; the angle is interpolated
#: between them).
AUTO_SAMPLES = 64
#: ``auto``: most grid cells the angle moves from one planned sample to the next.
AUTO_MAX_CELLS = 3
#: ``auto``: most times the profile is planned again with more samples where the last one failed.
AUTO_ROUNDS = 24
#: ``auto``: the path followed and the planned solution at a planned sample differ by more than this when the
#: path left it [rad].
SAME_SOLUTION_RAD = 1e-6


def sew_angle_of(spec: ArmAngle) -> SewAngle:
    """The stereographic SEW angle of the ``[arm_angle]`` settings.

    e_r is their vertical, the singular half-line along -e_r.
    """
    return SewAngle.stereographic(spec.vertical)


#: The default settings of :func:`solve_sew`: the initial configuration's SEW angle, held.
DEFAULT_ARM_ANGLE = ArmAngle(mode="initial")


def solve_sew(
    robot: Robot,
    reference: CartesianReference,
    q0: Mapping[str, float] | str | None = None,
    settings: ArmAngle = DEFAULT_ARM_ANGLE,
    clearance: mc_path.Clearance | None = None,
) -> JointPath:
    """Joint path of every hand of ``reference`` by SEW IK (module docstring).

    Each arm is a 7R chain of a family :mod:`dualarm.ik.analytic.sew` solves. ``clearance``: for ``auto``, which
    configurations of an arm keep it clear of collisions (None: any; see :func:`_auto`).

    Raises:
        NotSewError: an arm is of no such family (one line).
        StageError: a sample without a solution inside the limits, or a joint step above
            ``max_joint_step_rad`` (the error's ``sample``, ``t_s`` and ``joint`` say where); for
            ``auto``, no profile (:func:`_auto`).
    """
    spec = settings
    q0 = robot.configuration(q0, "q0")
    sew = sew_angle_of(spec)
    problems = arm_problems(robot, reference, q0)
    solutions = []
    for problem in problems:
        arm = sew_chain(problem.chain)
        lower, upper = robot.lower_upper(problem.chain.joint_names)
        initial = float(sew.angle(*(x[0] for x in arm.points(problem.q0[None]))))
        start = time.perf_counter()
        limits = (lower, upper, robot.limit_array("velocity", problem.chain.joint_names))
        found: dict[int, SewSolutions] = {}
        if spec.mode == "auto":
            clear = mc_path.arm_clearance(clearance, problem.hand)
            try:
                psi, found = _auto(arm, sew, problem, reference, initial, limits, spec, clear)
            except StageError as exc:
                if clear is None:
                    raise
                raise type(exc)(
                    f"{exc}, with the arm kept clear of collisions", stage="ik", sample=exc.sample, t_s=exc.t_s
                ) from None
        else:
            psi = mc_path.arm_angles(spec, problem.hand, reference, initial)
        rest = [k for k in range(len(reference)) if k not in found]
        found.update(zip(rest, solve_many(arm, problem.targets[rest], psi[rest], sew), strict=True))
        q = _followed(
            problem.hand,
            problem.chain.joint_names,
            [found[k] for k in range(len(reference))],
            problem.q0,
            lower,
            upper,
            reference,
            psi,
            spec.max_joint_step_rad,
        )
        elapsed = time.perf_counter() - start
        solutions.append(
            ArmSolution(
                q=q, ok=np.ones(len(reference), bool), solve_time_s=np.full(len(reference), elapsed / len(reference))
            )
        )
    return joint_path("sew", reference, problems, solutions, q0)


def _auto(
    arm: SewChain,
    sew: SewAngle,
    problem: ArmProblem,
    reference: CartesianReference,
    initial: float,
    limits: tuple[np.ndarray, np.ndarray, np.ndarray],
    spec: ArmAngle,
    clear: Callable[[np.ndarray], np.ndarray] | None = None,
) -> tuple[np.ndarray, dict[int, SewSolutions]]:
    """``auto``: the SEW angle per sample (N,) [rad] and the solutions there of the first repetition.

    The solutions are those of the first repetition's samples (by sample); the angles are a profile
    of least travel that keeps a solution inside the limits (MC-Inverse's ``auto`` for an arm without
    fixed branches).

    The profile is planned (:func:`_plan`) on some samples of the first repetition, at first
    :data:`AUTO_SAMPLES` evenly spaced; between them the angle is interpolated linearly. The first
    repetition is then solved and followed at that profile (:func:`_follow`). Where the path
    leaves the planned solution between two planned samples, the sample midway is planned on too;
    where it fails (no solution inside the limits, a joint step above ``max_joint_step_rad``, or
    one faster than the joint's velocity limit), that sample, the one before it and the midpoints
    to the planned samples around it; and the profile is planned again, up to
    :data:`AUTO_ROUNDS` times. Later repetitions repeat the first one's profile.

    ``limits``: the arm's lower and upper position limits [rad] and its velocity limits [rad/s]. With ``clear``
    (which arm configurations are free of collisions), a planned sample's solutions that collide are dropped,
    and a followed sample that collides fails as one without a solution would.

    Raises:
        StageError: no profile, or the last round's failure.
    """
    lower, upper, speed = limits
    first = np.flatnonzero(reference.rep == reference.rep[0])
    angles = initial + np.arange(AUTO_ANGLES) * (2 * np.pi / AUTO_ANGLES)
    planned = set(first[np.unique(np.linspace(0, len(first) - 1, AUTO_SAMPLES).round().astype(int))].tolist())
    closed = bool(np.abs(problem.targets[first[0]] - problem.targets[first[-1]]).max() < 1e-9)
    solutions: dict[int, np.ndarray] = {}  # sample -> its solutions inside the limits, (angles, M, 7), NaN-padded
    for _ in range(AUTO_ROUNDS):
        new = sorted(planned - solutions.keys())
        if new:
            found = solve_many(
                arm,
                np.repeat(problem.targets[new], AUTO_ANGLES, axis=0),
                np.tile(np.angle(np.exp(1j * angles)), len(new)),
                sew,
            )
            for i, k in enumerate(new):
                solutions[k] = _inside(found[i * AUTO_ANGLES : (i + 1) * AUTO_ANGLES], lower, upper, clear)
        picked = np.array(sorted(planned))
        cells, nodes = _plan(solutions, picked, angles, problem, initial, limits, closed, reference, spec)
        profile = np.interp(first, picked, np.unwrap(angles[cells]))
        found = solve_many(arm, problem.targets[first], profile, sew)
        q, failure = _follow(
            problem.hand,
            problem.chain.joint_names,
            found,
            problem.q0,
            lower,
            upper,
            reference,
            profile,
            spec.max_joint_step_rad,
            speed,
        )
        if clear is not None:
            failure = _collision(problem.hand, q, clear, reference, failure)
        end = len(first) if failure is None else _where(failure)
        with np.errstate(invalid="ignore"):
            apart = np.abs(np.angle(np.exp(1j * (q[picked] - nodes)))).max(axis=1) > SAME_SOLUTION_RAD
        apart &= picked < end
        if apart.any():  # the path left the planned solutions between two planned samples: plan between them too
            i = int(np.argmax(apart))
            if not i or picked[i] - picked[i - 1] <= 1:
                raise failure or _no_profile(problem.hand, reference, int(picked[i]), spec.max_joint_step_rad)
            planned.add(int(picked[i - 1] + picked[i]) // 2)
        elif failure is not None:  # the planned solution ends between planned samples: plan around the failure
            k = _where(failure)
            before, after = (
                int(picked[int(np.searchsorted(picked, k)) - 1]),
                int(picked[min(int(np.searchsorted(picked, k, "right")), len(picked) - 1)]),
            )
            more = {k, max(k - 1, 0), (before + k) // 2, (k + after) // 2} - planned
            if not more:
                raise failure
            planned |= more
        else:
            return profile[first_repetition_index(reference.t, reference.rep, reference.period_s)], dict(
                zip(first.tolist(), found, strict=True)
            )
    raise failure or _no_profile(problem.hand, reference, int(first[-1]), spec.max_joint_step_rad)


def _where(failure: StageError) -> int:
    """The sample a :func:`_follow` failure names (it always names one)."""
    assert failure.sample is not None
    return int(failure.sample)


def _inside(
    found: list, lower: np.ndarray, upper: np.ndarray, clear: Callable[[np.ndarray], np.ndarray] | None = None
) -> np.ndarray:
    """The solutions of one sample at each angle moved into the limits where they can be, those inside.

    And clear of collisions, given ``clear``. ``found`` holds one :class:`SewSolutions` per angle; the result is
    (angles, M, 7) [rad] padded with NaN.
    """
    rows = [into_limits(f.q, lower, upper) for f in found]
    rows = [q[np.all((q >= lower) & (q <= upper), axis=1)] for q in rows]
    Q = np.full((len(rows), max(1, max(len(q) for q in rows)), 7), np.nan)
    for g, q in enumerate(rows):
        Q[g, : len(q)] = q
    if clear is not None:
        solved = np.isfinite(Q).all(axis=-1)
        blocked = np.zeros(solved.shape, bool)
        blocked[solved] = ~clear(Q[solved])
        Q[blocked] = np.nan
    return Q


def _collision(
    hand: str,
    q: np.ndarray,
    clear: Callable[[np.ndarray], np.ndarray],
    reference: CartesianReference,
    failure: StageError | None,
) -> StageError | None:
    """``failure``, or an earlier one: the first followed sample of ``q`` (N, 7) [rad] that collides."""
    end = len(q) if failure is None else _where(failure)
    hit = np.flatnonzero(~clear(q[:end]))
    if not hit.size:
        return failure
    k = int(hit[0])
    return NoSolutionFound(
        f"sew, {hand} arm: sample {k} (t = {reference.t[k]:.3f} s, rep {reference.rep[k]}) collides "
        "(the arm within the clearance margin of the robot or an object)",
        stage="ik",
        sample=k,
        t_s=float(reference.t[k]),
    )


def _plan(
    solutions: dict[int, np.ndarray],
    picked: np.ndarray,
    angles: np.ndarray,
    problem: ArmProblem,
    initial: float,
    limits: tuple[np.ndarray, np.ndarray, np.ndarray],
    closed: bool,
    reference: CartesianReference,
    spec: ArmAngle,
) -> tuple[np.ndarray, np.ndarray]:
    """The grid cell of the angle (K,) and the solution (K, 7) [rad] at each planned sample ``picked``.

    ``picked`` is (K,). By dynamic programming over (planned sample, angle, solution) nodes.

    A step from one planned sample to the next moves the angle at most :data:`AUTO_MAX_CELLS`
    cells, goes on to the solution nearest (as :func:`_follow` chooses), and moves no joint more
    than ``max_joint_step_rad`` per sample between them nor faster on average than its velocity
    limit (the IK stage checks the path's velocities at the task's timing). The cost is, as
    MC-Inverse's, the sum over steps of |change of the angle| + the largest joint change [rad],
    plus per node how far it comes closer than ``margin_rad`` to a limit, plus, weighted by
    ``START_WEIGHT``, the start's distance from ``initial`` and its largest joint distance from the
    initial configuration. A start is, at an angle, the solution nearest the initial configuration
    (the one the path takes); a profile is searched from every angle's start at once. On a
    ``closed`` path the profile ends on the solution it began with, so that every repetition
    repeats it.

    Raises:
        StageError: no profile; names the planned sample where the longest one ends.
    """
    lower, upper, speed = limits
    G = len(angles)
    M = max(solutions[k].shape[1] for k in picked)
    Q = np.stack(
        [np.pad(solutions[k], ((0, 0), (0, M - solutions[k].shape[1]), (0, 0)), constant_values=np.nan) for k in picked]
    )  # (K, G, M, 7)
    with np.errstate(invalid="ignore"):
        node = np.where(
            np.isnan(Q[..., 0]),
            np.inf,
            np.maximum(0.0, spec.margin_rad - np.minimum(Q - lower, upper - Q).min(axis=-1)),
        )
    with np.errstate(invalid="ignore"):
        away = np.nan_to_num(np.abs(np.angle(np.exp(1j * (Q[0] - problem.q0)))).max(axis=-1), nan=np.inf)  # (G, M)
    m_start = away.argmin(axis=1)  # at each angle, the solution the path takes from the initial configuration
    start = node[0, np.arange(G), m_start] + START_WEIGHT * (
        np.abs(np.angle(np.exp(1j * (angles - initial)))) + away[np.arange(G), m_start]
    )
    g0 = np.argsort(start)  # cheapest first: a tie goes to the cheaper start
    g0 = g0[np.isfinite(start[g0])]
    if not g0.size:
        raise _no_profile(problem.hand, reference, int(picked[0]), spec.max_joint_step_rad)
    m0 = m_start[g0]
    shifts = np.arange(-AUTO_MAX_CELLS, AUTO_MAX_CELLS + 1)
    cost = np.full((g0.size, G, M), np.inf)
    cost[np.arange(g0.size), g0, m0] = start[g0]
    back = np.zeros((len(picked), g0.size, G, M, 2), int)  # (shift index, solution) each node is reached from
    for k in range(1, len(picked)):
        limit = np.minimum(
            spec.max_joint_step_rad * (picked[k] - picked[k - 1]),
            speed * (reference.t[picked[k]] - reference.t[picked[k - 1]]),
        )
        best = np.full(cost.shape, np.inf)
        for j, d in enumerate(shifts):
            with np.errstate(invalid="ignore"):
                change = np.abs(
                    np.angle(np.exp(1j * (Q[k][:, :, None] - np.roll(Q[k - 1], d, axis=0)[:, None])))
                )  # (G, M now, M before, 7): from cell g - d
            largest = np.nan_to_num(change.max(axis=-1), nan=np.inf)
            nearest = largest.argmin(axis=1)  # (G, M before): the solution the path goes on to, as _follow chooses it
            step = np.take_along_axis(largest, nearest[:, None], 1)[:, 0]
            within = np.all(np.take_along_axis(change, nearest[:, None, :, None], 1)[:, 0] <= limit, axis=-1)
            option = (
                np.roll(cost, d, axis=1) + np.where(within, step, np.inf)[None] + abs(d) * 2 * np.pi / G
            )  # (starts, G, M before)
            for before in range(M):
                to = nearest[:, before]
                better = option[:, np.arange(G), before] < best[:, np.arange(G), to]
                s_, g_ = np.nonzero(better)
                best[s_, g_, to[g_]] = option[s_, g_, before]
                back[k][s_, g_, to[g_]] = np.stack([np.full(len(g_), j), np.full(len(g_), before)], -1)
        cost = best + node[k][None]
        if not np.isfinite(cost).any():
            raise _no_profile(problem.hand, reference, int(picked[k]), spec.max_joint_step_rad)
    if closed:  # end on the start's solution (the last planned sample is the first's pose again)
        with np.errstate(invalid="ignore"):
            gap = np.nan_to_num(np.abs(Q[-1, g0] - Q[0, g0, m0][:, None]).max(axis=-1), nan=np.inf)  # (starts, M)
        m_end = gap.argmin(axis=1)
        total = np.where(gap[np.arange(g0.size), m_end] < 1e-6, cost[np.arange(g0.size), g0, m_end], np.inf)
        ends = np.stack([g0, m_end], -1)
    else:
        flat = cost.reshape(g0.size, -1).argmin(axis=1)
        total, ends = cost.reshape(g0.size, -1)[np.arange(g0.size), flat], np.stack(np.unravel_index(flat, (G, M)), -1)
    s = int(np.argmin(total))
    if not np.isfinite(total[s]):
        raise _no_profile(problem.hand, reference, int(picked[-1]), spec.max_joint_step_rad)
    cells, nodes = np.empty(len(picked), int), np.empty((len(picked), 7))
    g, m = ends[s]
    for k in range(len(picked) - 1, -1, -1):
        cells[k], nodes[k] = g, Q[k, g, m]
        if k:
            j, m = back[k, s, g, m]
            g = (g - shifts[j]) % G
    return cells, nodes


def _no_profile(hand: str, reference: CartesianReference, k: int, max_step: float) -> StageError:
    """The stage error of `auto` when no profile gets past planned sample ``k``."""
    return StageError(
        f"sew, {hand} arm: no SEW angle profile keeps a solution inside the joint limits, "
        f"with joint steps within arm_angle.max_joint_step_rad = {max_step} "
        f"and the velocity limits, beyond sample {k} (t = {reference.t[k]:.3f} s)",
        stage="ik",
        sample=int(k),
        t_s=float(reference.t[k]),
    )


def _nearest_turns(Q: np.ndarray, previous: np.ndarray) -> np.ndarray:
    """Each joint of the solutions Q (M, 7) moved by whole turns to the value nearest ``previous`` (7,)."""
    return Q + 2 * np.pi * np.round((previous - Q) / (2 * np.pi))


def _followed(hand, names, found, q0, lower, upper, reference, psi, max_step) -> np.ndarray:
    """The solution inside [lower, upper] at every sample (N, 7) [rad].

    The one nearest ``q0`` at sample 0, then the one nearest the previous one.

    Raises:
        StageError: :func:`_follow`'s failure.
    """
    q, failure = _follow(hand, names, found, q0, lower, upper, reference, psi, max_step)
    if failure is not None:
        raise failure
    return q


def _follow(
    hand, names, found, q0, lower, upper, reference, psi, max_step, speed=None
) -> tuple[np.ndarray, StageError | None]:
    """:func:`_followed`'s path (N, 7) [rad], filled up to the sample where it fails, and the failure.

    The failure is None when it does not fail: a sample without a solution inside the limits, a
    joint step above ``max_step``, or, given velocity limits ``speed`` (7,) [rad/s], a step faster
    (the error's ``sample``, ``t_s`` and ``joint`` say where).
    """
    q = np.full((len(found), 7), np.nan)
    previous = q0
    for k, solutions in enumerate(found):
        where = f"sample {k} (t = {reference.t[k]:.3f} s, rep {reference.rep[k]})"
        if not len(solutions.q):
            return q, NoSolutionFound(
                f"sew, {hand} arm: {where} has no solution at SEW angle {psi[k]:.4f} rad",
                stage="ik",
                sample=k,
                t_s=float(reference.t[k]),
            )
        near = _nearest_turns(solutions.q, previous)
        inside = np.all((near >= lower) & (near <= upper), axis=1)
        if not inside.any():
            worst = int(np.argmax(np.maximum(lower - near, near - upper).max(axis=0)))
            return q, NoSolutionFound(
                f"sew, {hand} arm: {where}: none of its {len(near)} solutions at SEW angle {psi[k]:.4f} rad "
                f"is inside the joint limits ({names[worst]} the worst)",
                stage="ik",
                sample=k,
                t_s=float(reference.t[k]),
                joint=names[worst],
            )
        steps = np.where(inside[:, None], np.abs(near - previous), np.inf)
        best = int(np.argmin(steps.max(axis=1)))
        if k and steps[best].max() > max_step:
            j = int(np.argmax(steps[best]))
            return q, StageError(
                f"sew, {hand} arm: {names[j]} jumps {steps[best, j]:.3f} rad at {where}, "
                f"above arm_angle.max_joint_step_rad = {max_step}: the solution followed ends there",
                stage="ik",
                sample=k,
                t_s=float(reference.t[k]),
                joint=names[j],
            )
        if k and speed is not None and np.any(steps[best] > speed * (reference.t[k] - reference.t[k - 1])):
            j = int(np.argmax(steps[best] / speed))
            return q, StageError(
                f"sew, {hand} arm: {names[j]} moves faster than its velocity limit at {where}",
                stage="ik",
                sample=k,
                t_s=float(reference.t[k]),
                joint=names[j],
            )
        q[k] = previous = near[best]
    return q, None


#: SEW IK in the registry (:data:`dualarm.methods.METHODS`).
METHODS: Mapping[str, Method[ArmAngle]] = {
    "sew": Method(
        "sew",
        "ik",
        "SEW angle (Elias, Wen): every solution at the SEW angle by a 1-D search, the one continuing the path kept; "
        "7R arms with a spherical wrist and two meeting shoulder axes (S-R-S, offset humanoid shoulders) "
        "or a spherical shoulder and two meeting wrist axes (the Panda)",
        solve_sew,
        ArmAngle,
        settings_for,
        arm="sew",
        clearance=True,
    )
}
