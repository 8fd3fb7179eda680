"""``dualarm bench ik``: position-level IK of one arm.

The analytic solver of its family against iterative solvers.

Measured in one process, on the same random reachable poses of an arm chain: each pose is the
forward kinematics of a configuration drawn uniformly within the joint limits (fixed seed), so
every pose is reachable, and its arm angle psi is that configuration's (eq 1 of MC-Inverse; on an
arm of the SEW solver's family, its stereographic SEW angle, :mod:`dualarm.ik.analytic.sew`).

On an S-R-S arm the analytic rows are MC-Inverse's and IK-Geo's (an S-R-S arm is of the SEW
solver's R-2R-R-3R family); on an arm of the SEW family they are:

- SEW called singly: :func:`dualarm.ik.analytic.sew.solve` per pose, on the first :data:`SEW_SINGLE_POSES`
  poses only (each call runs the whole search with its per-step overhead).
- SEW batched: :func:`dualarm.ik.analytic.sew.solve_many` over all poses in one call; time per pose.
- IK-Geo, the peer (the ``ik-geo`` package): with one joint fixed at the original configuration's
  (q7 on the Panda's family, q1 on the R-2R-R-3R family), the other six are IK-Geo's
  ``spherical_two_intersecting`` robot (:func:`ik_geo_problem`); one ``get_ik`` call per pose on
  inputs prepared before the timing (on the Panda's family the robot is built in the call, since it
  depends on the fixed joint; its answer turned into rows after).

Success for SEW and IK-Geo: the original configuration among the exact solutions to
:data:`SEW_MATCH_TOLERANCE_RAD` (near a double root a solution is determined only so far).

- MC-Inverse called singly: one Python call of :meth:`McInverse.solve` per pose (all 8
  candidates, its input checks included); time per call.
- MC-Inverse batched: :meth:`McInverse.solve_many` over all poses in one call, after one warm-up
  call (the first builds the mapped Function); time per pose, the call's time divided by the
  poses, over :data:`BATCH_REPEATS` calls (mapped calls spread over the machine's cores, see
  :mod:`dualarm.numerics.batched`).
- DLS-SVD (:class:`~dualarm.ik.pose_level.dls.DlsSolver`, default settings: 1e-9 m / 1e-9 rad), TRAC-IK
  (:class:`~dualarm.ik.pose_level.baselines.TracIkSolver`, defaults) and PyBullet
  (:class:`~dualarm.ik.pose_level.baselines.PyBulletIkSolver`, defaults): one call per pose, seeded from the
  original configuration plus N(0, :data:`SEED_NOISE_RAD`) noise clipped to the limits (fixed
  seed, the same seeds for the three); time per call.

Success: for MC-Inverse, the original configuration is among the valid candidates to
:data:`MATCH_TOLERANCE_RAD` in every joint; for the others, the solver's own flag (``converged``,
or ``ok``, which for the baselines is already confirmed by the project's FK).

Never used by the test suite: wall-clock numbers depend on the machine.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from dualarm.methods import not_sew, not_srs
from dualarm.model.robot import Robot
from dualarm.quiet import c_output_silenced

if TYPE_CHECKING:
    from dualarm.ik.analytic.mc_inverse import McInverse
    from dualarm.model.sew import SewChain

#: Row names, in the order of :func:`bench_ik`'s rows.
MC_SINGLE = "MC-Inverse, single"
MC_BATCHED = "MC-Inverse, batched"
DLS = "DLS-SVD"
TRAC_IK = "TRAC-IK"
PYBULLET = "PyBullet"

#: Largest joint difference between a candidate and the original configuration that counts as
#: finding it [rad].
MATCH_TOLERANCE_RAD = 1e-9
#: Standard deviation of the noise added to the original configuration to seed the iterative
#: solvers [rad].
SEED_NOISE_RAD = 0.1
#: Timed calls of the batched MC-Inverse over all poses (after the warm-up).
BATCH_REPEATS = 5
SEW_SINGLE = "SEW, single"
SEW_BATCHED = "SEW, batched"
IK_GEO = "IK-Geo (one joint fixed)"
#: Poses the single-call SEW row measures (the first ones).
SEW_SINGLE_POSES = 100
#: Largest joint difference that counts as finding the original configuration, for SEW and IK-Geo [rad].
SEW_MATCH_TOLERANCE_RAD = 1e-6
#: Targets: MC-Inverse time per pose called singly and batched [s] (issue 22), DLS-SVD success rate [1].
TARGET_SINGLE_S = 5e-6
TARGET_BATCHED_S = 1e-6
TARGET_DLS_SUCCESS = 0.999

#: ``progress(name, done, total)``: ``done`` of ``total`` poses of the solver ``name`` measured.
Progress = Callable[[str, int, int], None]


@dataclass(frozen=True)
class IkBenchRow:
    """One measured solver.

    Attributes:
        name: what was measured (one of :data:`MC_SINGLE`, :data:`MC_BATCHED`, :data:`DLS`,
            :data:`TRAC_IK`, :data:`PYBULLET`).
        poses: poses solved.
        mean_s: mean time per pose [s].
        median_s: median time per pose [s] (for the batched row: median over the repeated calls
            of the call's time divided by the poses).
        success_rate: fraction of the poses solved [1], in [0, 1].
        note: how the row was measured and what its failures were.
    """

    name: str
    poses: int
    mean_s: float
    median_s: float
    success_rate: float
    note: str = ""


def ratios(rows: Sequence[IkBenchRow], reference_name: str | None = None) -> dict[str, float]:
    """Mean time per pose of every row divided by that of the row ``reference_name``.

    Args:
        rows: rows of :func:`bench_ik`.
        reference_name: the row the others are compared with (default: the batched analytic
            row, :data:`MC_BATCHED` or :data:`SEW_BATCHED`).

    Returns:
        Row name -> mean-time ratio [1] (> 1: slower than the reference).

    Raises:
        KeyError: no row named ``reference_name``.
    """
    by_name = {r.name: r for r in rows}
    reference = by_name[reference_name or (MC_BATCHED if MC_BATCHED in by_name else SEW_BATCHED)].mean_s
    return {r.name: r.mean_s / reference for r in rows}


def reachable_poses(
    robot: Robot, arm: str, poses: int, seed: int, mc: McInverse | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random reachable hand poses of the arm chain of hand ``arm``.

    Args:
        robot: the robot.
        arm: hand of the chain, ``left`` or ``right``.
        poses: number of poses.
        seed: seed of the configurations.
        mc: the arm's :class:`~dualarm.ik.analytic.mc_inverse.McInverse` if already built (for psi).

    Returns:
        The configurations Q (N, 7) [rad] drawn uniformly within the limits, their hand poses
        (N, 4, 4) in the chain base frame [m], and their arm angles psi (N,) [rad] (their SEW
        angles on an arm that is not S-R-S but of the SEW solver's family).
    """
    from dualarm.ik.analytic.mc_inverse import McInverse
    from dualarm.model.kinematics import ChainKinematics
    from dualarm.model.robot import random_configurations

    chain = robot.hand_chain(arm)
    Q = random_configurations(robot, chain, poses, seed)
    T = ChainKinematics.of(chain).poses(Q)
    if mc is None and not_srs(robot, (arm,)) and not not_sew(robot, (arm,)):
        from dualarm.ik.analytic.sew_path import sew_angle_of
        from dualarm.model.sew import sew_chain
        from dualarm.tasks.schema import ArmAngle

        return Q, T, sew_angle_of(ArmAngle()).angle(*sew_chain(chain).points(Q))
    psi = (mc or McInverse.of(chain)).kinematics.arm_angles(Q)
    return Q, T, psi


def bench_ik(
    robot: Robot | str | Path, arm: str = "left", poses: int = 10_000, seed: int = 0, progress: Progress | None = None
) -> list[IkBenchRow]:
    """Time and success rate of the arm's analytic solver, DLS-SVD, TRAC-IK and PyBullet.

    The analytic solver: MC-Inverse on an S-R-S arm, SEW and its peer IK-Geo on an arm of the SEW
    family; single and batched. All on the same random reachable poses of one arm (see the module
    docstring).

    Args:
        robot: the robot, or its directory (as for :func:`~dualarm.model.robot.load_robot`).
        arm: hand whose arm chain is solved, ``left`` or ``right``.
        poses: number of random poses (a few tens for a quick check).
        seed: seed of the configurations; the seeds' noise uses ``seed + 1``.
        progress: called as ``progress(name, done, total)`` when a solver starts, about every 1 %
            of the poses, and when it ends.

    Returns:
        Rows in the order MC-Inverse single, MC-Inverse batched (or SEW single, SEW batched),
        IK-Geo, DLS-SVD, TRAC-IK, PyBullet.

    Raises:
        ValueError: ``poses`` below 1.
        RobotModelError: no hand ``arm``.
        NotSRSError: the arm chain is neither S-R-S nor of the SEW solver's family.
    """
    from dualarm.errors import NotSRSError
    from dualarm.ik.analytic.mc_inverse import McInverse
    from dualarm.ik.pose_level.baselines import PyBulletIkSolver, TracIkSolver
    from dualarm.ik.pose_level.dls import DlsSolver
    from dualarm.model.robot import load_robot

    if isinstance(poses, bool) or not isinstance(poses, int) or poses < 1:
        raise ValueError(f"poses: must be a positive integer, got {poses!r}")
    if not isinstance(robot, Robot):
        robot = load_robot(robot)
    chain = robot.hand_chain(arm)
    srs = not not_srs(robot, (arm,))
    if not srs and not_sew(robot, (arm,)):
        raise NotSRSError(
            f"bench ik: the {arm} arm of '{robot.name}' is neither S-R-S "
            f"nor of the SEW solver's family: {not_sew(robot, (arm,))[arm]}"
        )
    mc = McInverse.of(chain) if srs else None
    Q, T, psi = reachable_poses(robot, arm, poses, seed, mc)
    lower, upper = robot.lower_upper(chain.joint_names)
    seeds = np.clip(Q + np.random.default_rng(seed + 1).normal(0.0, SEED_NOISE_RAD, Q.shape), lower, upper)
    report = progress or (lambda name, done, total: None)

    def per_pose(name: str, solve: Callable[[int], bool]) -> IkBenchRow:
        """Time ``solve(i)`` (returning success) for every pose."""
        row, ok = _timed(name, poses, solve, report)
        return replace(row, success_rate=float(np.mean(ok)))

    rows = (
        _mc_rows(mc, T, psi, Q, per_pose, report) + _ik_geo_rows(robot, arm, T, Q, report)
        if mc is not None
        else _sew_rows(robot, arm, T, psi, Q, report)
    )

    # 3. Iterative solvers from perturbed seeds.
    dls = DlsSolver.of(robot, chain.base, [chain.tip])
    order = [dls.joint_names.index(name) for name in chain.joint_names]  # DLS q -> chain order (identity for an arm)
    dls_seeds = np.empty_like(seeds)
    dls_seeds[:, order] = seeds
    iterations = []

    def dls_solve(i: int) -> bool:
        result = dls.solve([T[i]], dls_seeds[i])
        iterations.append(result.iterations)
        return result.converged

    row = per_pose(DLS, dls_solve)
    tolerances = f"{dls.settings.position_tolerance_m:g} m, {dls.settings.orientation_tolerance_rad:g} rad"
    rows.append(
        replace(
            row,
            note=f"tolerances {tolerances}; median {np.median(iterations):.0f} iterations, at most {max(iterations)}",
        )
    )

    with c_output_silenced():  # TRAC-IK's C++ prints on construction
        trac = TracIkSolver.of(robot, chain.base, chain.tip)
    row = per_pose(TRAC_IK, lambda i: trac.solve(T[i], seeds[i]).ok)
    rows.append(
        replace(
            row,
            note=(
                f"timeout {trac.timeout_s * 1e3:g} ms, epsilon {trac.epsilon:g}, {trac.solve_type}; ok confirmed by FK"
            ),
        )
    )

    with c_output_silenced():  # PyBullet's banner
        bullet = PyBulletIkSolver.of(robot, chain.base, chain.tip)
    with bullet:
        row = per_pose(PYBULLET, lambda i: bullet.solve(T[i], seeds[i]).ok)
    rows.append(
        replace(
            row,
            note=(
                f"{bullet.max_iterations} iterations max, tolerances "
                f"{bullet.position_tolerance_m:g} m, {bullet.orientation_tolerance_rad:g} rad by FK"
            ),
        )
    )
    return rows


def _mc_rows(
    mc: McInverse,
    T: np.ndarray,
    psi: np.ndarray,
    Q: np.ndarray,
    per_pose: Callable[[str, Callable[[int], bool]], IkBenchRow],
    report: Progress,
) -> list[IkBenchRow]:
    """MC-Inverse called singly and batched (the module docstring)."""
    from dualarm.numerics.batched import THREADS, BatchedCandidates

    poses = len(Q)
    rows = []
    # 1. MC-Inverse, one call per pose; the success test is outside the timed call.
    solutions = []

    def mc_single(i: int) -> bool:
        solutions.append(mc.solve(T[i], psi[i]))
        return True

    mc.solve(T[0], psi[0])  # the Function's first call
    row = per_pose(MC_SINGLE, mc_single)
    distance = np.array([_closest(s.q, s.reason, q) for s, q in zip(solutions, Q, strict=True)])
    rows.append(replace(row, success_rate=float(np.mean(distance <= MATCH_TOLERANCE_RAD)), note=_mc_note(distance)))

    # 2. MC-Inverse, all poses in one call.
    report(MC_BATCHED, 0, poses)
    mc.solve_many(T, psi)  # warm-up: builds the mapped Function
    calls = []
    for _ in range(BATCH_REPEATS):
        start = time.perf_counter()
        q_all, reason_all = mc.solve_many(T, psi)
        calls.append((time.perf_counter() - start) / poses)
    report(MC_BATCHED, poses, poses)
    distance = np.array([_closest(c, r, q) for c, r, q in zip(q_all, reason_all, Q, strict=True)])
    note = f"{_mc_note(distance)}; best of {BATCH_REPEATS} calls {min(calls) * 1e6:.2f} µs/pose"
    note += f"; mapped calls of {BatchedCandidates.chunk} poses on {THREADS} threads"
    rows.append(
        IkBenchRow(
            MC_BATCHED,
            poses,
            float(np.mean(calls)),
            float(np.median(calls)),
            float(np.mean(distance <= MATCH_TOLERANCE_RAD)),
            note,
        )
    )
    return rows


def _sew_rows(
    robot: Robot, arm: str, T: np.ndarray, psi: np.ndarray, Q: np.ndarray, report: Progress
) -> list[IkBenchRow]:
    """SEW called singly (the first :data:`SEW_SINGLE_POSES` poses) and batched.

    And IK-Geo with one joint fixed (the module docstring).
    """
    from dualarm.ik.analytic.sew import solve, solve_many
    from dualarm.ik.analytic.sew_path import sew_angle_of
    from dualarm.model.sew import sew_chain
    from dualarm.tasks.schema import ArmAngle

    chain = robot.hand_chain(arm)
    sew_arm, sew = sew_chain(chain), sew_angle_of(ArmAngle())
    poses = len(Q)

    rows = []
    single = min(poses, SEW_SINGLE_POSES)
    row, answers = _timed(SEW_SINGLE, single, lambda i: solve(sew_arm, T[i], float(psi[i]), sew).q, report)
    success = float(np.mean([_found(a, q) for a, q in zip(answers, Q, strict=False)]))
    rows.append(
        replace(
            row,
            success_rate=success,
            note=f"the first {single} poses; original q among the solutions to {SEW_MATCH_TOLERANCE_RAD:g} rad",
        )
    )

    report(SEW_BATCHED, 0, poses)
    start = time.perf_counter()
    batched = solve_many(sew_arm, T, psi, sew)
    elapsed = (time.perf_counter() - start) / poses
    report(SEW_BATCHED, poses, poses)
    counts = np.array([len(b.q) for b in batched])
    success = float(np.mean([_found(b.q, q) for b, q in zip(batched, Q, strict=True)]))
    rows.append(
        IkBenchRow(
            SEW_BATCHED,
            poses,
            elapsed,
            elapsed,
            success,
            f"one call; {counts.min()}-{counts.max()} solutions per pose (median {np.median(counts):.0f})",
        )
    )

    return rows + _ik_geo_rows(robot, arm, T, Q, report)


def _ik_geo_rows(robot: Robot, arm: str, T: np.ndarray, Q: np.ndarray, report: Progress) -> list[IkBenchRow]:
    """IK-Geo with one joint fixed at the original configuration's, one call per pose.

    See the module docstring: the analytic peer, on an S-R-S arm (an R-2R-R-3R arm whose first three
    axes meet) as on the SEW family.
    """
    import ik_geo

    from dualarm.model.sew import UPPER_ARM_FAMILY, sew_chain

    sew_arm = sew_chain(robot.hand_chain(arm))
    problems = [
        ik_geo_problem(sew_arm, T[i], Q[i]) for i in range(len(Q))
    ]  # made before the timing, as the other rows' poses
    if sew_arm.family == UPPER_ARM_FAMILY:  # the robot depends on the fixed joint: built in each call
        row, answers = _timed(
            IK_GEO,
            len(Q),
            lambda i: ik_geo.Robot.spherical_two_intersecting(*problems[i][:2]).get_ik(*problems[i][2:]),
            report,
        )
    else:
        robot_6r = ik_geo.Robot.spherical_two_intersecting(*problems[0][:2])
        row, answers = _timed(IK_GEO, len(Q), lambda i: robot_6r.get_ik(*problems[i][2:]), report)
    success = float(
        np.mean(
            [_found(np.array(ik_geo_rows(sew_arm, a, q)).reshape(-1, 7), q) for a, q in zip(answers, Q, strict=True)]
        )
    )
    fixed = "q7, joints 6..1" if sew_arm.family == UPPER_ARM_FAMILY else "q1, joints 2..7"
    note = (
        f"ik-geo's spherical_two_intersecting with {fixed} fixed at the original's; "
        f"original q among its exact solutions to {SEW_MATCH_TOLERANCE_RAD:g} rad"
    )
    return [replace(row, success_rate=success, note=note)]


def _found(q_all: np.ndarray, q: np.ndarray) -> bool:
    """Whether ``q`` (7,) [rad] is among the rows of ``q_all`` to :data:`SEW_MATCH_TOLERANCE_RAD`.

    Angles compared modulo 2 pi.
    """
    return (
        bool(len(q_all))
        and float(np.abs(np.angle(np.exp(1j * (np.asarray(q_all) - q)))).max(axis=1).min()) <= SEW_MATCH_TOLERANCE_RAD
    )


def ik_geo_solutions(arm: SewChain, T: np.ndarray, q: np.ndarray) -> list[np.ndarray]:
    """IK-Geo's exact solutions (each (7,) [rad]) of the pose T (4, 4, chain base frame).

    With the joint its 6R leaves out held at ``q``'s (7,): :func:`ik_geo_call`'s answer as rows of
    the 7 joints.
    """
    return ik_geo_rows(arm, ik_geo_call(arm, T, q), q)


def ik_geo_call(arm: SewChain, T: np.ndarray, q: np.ndarray) -> list:
    """IK-Geo's answer for the pose T (4, 4, chain base frame).

    Its list of (6 joints, least-squares flag), with the joint its 6R leaves out held at ``q``'s
    (7,): :func:`ik_geo_problem`'s robot built and solved.
    """
    import ik_geo

    axes, offsets, R, p = ik_geo_problem(arm, T, q)
    return ik_geo.Robot.spherical_two_intersecting(axes, offsets).get_ik(R, p)


def ik_geo_problem(arm: SewChain, T: np.ndarray, q: np.ndarray) -> tuple[list, list, list, list]:
    """IK-Geo's 6R robot (its axes and offsets) and the rotation and position it solves.

    For the pose T (4, 4, chain base frame) with the joint its 6R leaves out held at ``q``'s (7,).

    Both SEW families are IK-Geo's ``spherical_two_intersecting`` 6R (the ``ik-geo`` package: axes
    1 and 2 meet, axes 4-6 meet) once one joint is fixed: 3R-R-2R-R with q7 fixed, joints 6..1
    reversed (joints 6, 5 meet; 3, 2, 1 meet at the shoulder), the pose inverted, the robot
    depending on q7; R-2R-R-3R (an S-R-S arm among them) with q1 fixed, joints 2..7 (2, 3 meet; 5,
    6, 7 meet), joint 1's turn about its axis through S undone, the robot the same for every q1.
    ik-geo reads a rotation's rows as its columns.
    """
    from dualarm.model.sew import UPPER_ARM_FAMILY

    S, E, C, W = arm.shoulder, arm.elbow, arm.crossing, arm.wrist
    if arm.family == UPPER_ARM_FAMILY:
        R67 = _rotation(arm.axes[6], float(q[6]))
        P = [
            C - (W + R67 @ arm.tool),
            np.zeros(3),
            E - C,
            S - E,
            np.zeros(3),
            np.zeros(3),
            -S,
        ]  # from the 6R's tip at q = 0
        R06 = T[:3, :3] @ arm.tool_rotation.T @ R67.T
        return (-arm.axes[:6][::-1]).tolist(), np.array(P).tolist(), R06.tolist(), (-R06.T @ T[:3, 3]).tolist()
    R1 = _rotation(arm.axes[0], float(q[0]))
    P = [C, np.zeros(3), E - C, W - E, np.zeros(3), np.zeros(3), arm.tool]
    R = R1.T @ T[:3, :3] @ arm.tool_rotation.T  # the 6R's rotation, without the tip's at q = 0
    return arm.axes[1:].tolist(), np.array(P).tolist(), R.T.tolist(), (R1.T @ (T[:3, 3] - S) + S).tolist()


def _rotation(k: np.ndarray, angle: float) -> np.ndarray:
    """exp([k] angle) for one unit axis k (3,) (Rodrigues, in numpy).

    In numpy: a CasADi call costs more than the product on one angle.
    """
    from dualarm.model.rodrigues import hat

    K = hat(k)
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)


def ik_geo_rows(arm: SewChain, answer: list, q: np.ndarray) -> list[np.ndarray]:
    """The exact solutions of :func:`ik_geo_call`'s ``answer`` as rows of the 7 joints [rad].

    The fixed one at ``q``'s.
    """
    from dualarm.model.sew import UPPER_ARM_FAMILY

    if arm.family == UPPER_ARM_FAMILY:
        return [np.append(np.array(s)[::-1], q[6]) for s, least_squares in answer if not least_squares]
    return [np.insert(np.array(s), 0, q[0]) for s, least_squares in answer if not least_squares]


def _timed(name: str, count: int, call: Callable[[int], Any], report: Progress) -> tuple[IkBenchRow, list]:
    """Time ``call(i)`` for the first ``count`` poses, one perf_counter pair per call.

    Reports about every 1 %. Returns the row (success rate 0 until the caller scores the results)
    and the results.
    """
    times, results = np.empty(count), []
    every = max(1, count // 100)
    report(name, 0, count)
    for i in range(count):
        start = time.perf_counter()
        results.append(call(i))
        times[i] = time.perf_counter() - start
        if (i + 1) % every == 0 or i + 1 == count:
            report(name, i + 1, count)
    return IkBenchRow(name, count, float(times.mean()), float(np.median(times)), 0.0), results


def _closest(candidates: np.ndarray, reason: np.ndarray, q: np.ndarray) -> float:
    """Largest joint difference [rad] between ``q`` (7,) and the closest valid row of ``candidates``.

    ``candidates`` is (8, 7); inf when no candidate is valid.
    """
    from dualarm.ik.analytic.mc_inverse import VALID

    valid = candidates[reason == VALID]
    return float(np.abs(valid - q).max(axis=1).min()) if valid.size else float("inf")


def _mc_note(distance: np.ndarray) -> str:
    """How MC-Inverse was scored and what its misses were, from the distances of :func:`_closest`."""
    text = f"8 candidates; original q among the valid to {MATCH_TOLERANCE_RAD:g} rad"
    missed = distance > MATCH_TOLERANCE_RAD
    if missed.any():
        none_valid = int(np.isinf(distance).sum())
        off = distance[missed & np.isfinite(distance)]
        text += f"; {int(missed.sum())} missed: {none_valid} with no valid candidate"
        if off.size:
            text += f", {off.size} off by up to {off.max():.2g} rad"
    finite = distance[np.isfinite(distance)]
    if finite.size:
        text += f"; closest valid candidate at most {finite.max():.2g} rad off"
    return text
