"""MC-Inverse along a Cartesian path: the arm angle per sample, one kept branch, checked steps.

Zou, Min, Xu's consistency argument (section III.B, V): when the arm angle psi is a function of
where the hand is on the task, and not of how it got there, and the same solution branch is kept
throughout, then every repetition of a path gives the same joints. Here psi follows the task's
``[arm_angle]`` table (the initial configuration's psi held, a constant, or a schedule over the
time within a repetition). The branch (elbow, shoulder and wrist root of the 8 candidates) is
the one nearest the initial configuration at the first sample, and it is kept. A sample where
that branch is invalid, or where a joint moves more than ``max_joint_step_rad`` between samples,
fails the stage with the sample, the time and the joint named; nothing is silently swapped.

Each arm is solved in its chain base frame (the torso); a free waist is held at its initial
value, because MC-Inverse solves 7-DOF arms.
"""

from __future__ import annotations

import time

import numpy as np

from pipeline.errors import StageError
from pipeline.ik.joint_path import JointPath
from pipeline.ik.mc_inverse import REASONS, VALID, McInverse
from pipeline.model.kinematics import ChainKinematics
from pipeline.model.poses import invert
from pipeline.tasks import Task


#: Offsets of the arm angles the ``auto`` mode searches, around the current one [rad] (0.5 degree).
AUTO_GRID = np.linspace(-np.pi, np.pi, 720, endpoint=False)


def time_in_repetition(reference) -> np.ndarray:
    """Time since the repetition began, per sample (N,) [s]. Repetition r spans
    (r T, (r + 1) T] (the first also holds t = 0), so samples at the same place of every
    repetition get the same value."""
    period = reference.t[reference.rep == reference.rep[0]][-1] - reference.t[0]
    return reference.t - reference.t[0] - (reference.rep - reference.rep[0]) * period


def arm_angles(task: Task, hand: str, reference, solver: McInverse, q0: np.ndarray) -> np.ndarray:
    """psi per sample (N,) [rad] for ``hand`` by the task's ``[arm_angle]`` table; ``q0`` is the
    arm's initial configuration [rad] (``auto`` gives its psi, the preferred one; see :func:`_auto`)."""
    spec = task.spec.arm_angle
    N = len(reference)
    if spec.mode in ("initial", "auto"):
        return np.full(N, float(solver.kinematics.arm_angles(q0)[0]))
    if spec.mode == "constant":
        if hand not in spec.value_rad:
            raise StageError(f"arm_angle.value_rad has no value for the {hand} hand")
        return np.full(N, spec.value_rad[hand])
    if hand not in spec.schedule:
        raise StageError(f"arm_angle.schedule has no entry for the {hand} hand")
    times, values = np.array(spec.schedule[hand]).T
    return np.interp(time_in_repetition(reference), times, values)


def solve_mc_inverse(task: Task, reference) -> JointPath:
    """Joint path of every hand of ``task`` along ``reference`` by MC-Inverse.

    Raises:
        StageError: a sample where the kept branch is invalid (out of reach, singular, outside
            the limits) or a joint step above ``arm_angle.max_joint_step_rad``.
    """
    spec = task.spec.arm_angle
    vertical = tuple(np.asarray(spec.vertical) / np.linalg.norm(spec.vertical))
    names: list[str] = []
    columns, errors, times = [], [], np.zeros(len(reference))
    for hand in task.spec.hands:
        chain = task.robot.hand_chain(hand)
        solver = McInverse.of(chain, vertical)
        root_to_base = ChainKinematics.of(task.robot.chain_between(reference.frame, chain.base))
        base_pose = root_to_base.pose(np.array([task.initial_q[n] for n in root_to_base.chain.joint_names]))
        targets = invert(base_pose)[None] @ reference.hands[hand].poses  # poses in the arm's base frame
        q0 = np.array([task.initial_q[n] for n in chain.joint_names])
        psi = arm_angles(task, hand, reference, solver, q0)
        start = time.perf_counter()
        if spec.mode == "auto":
            psi = _auto(solver, targets, reference, psi[0], q0, spec.margin_rad)
        candidates, reasons = solver.solve_many(targets, psi)
        times += (time.perf_counter() - start) / len(reference)
        q = _kept_branch(hand, chain.joint_names, q0, reference, candidates, reasons, spec.max_joint_step_rad)
        reached = ChainKinematics.of(chain).poses(q)
        errors.append(np.linalg.norm(reached[:, :3, 3] - targets[:, :3, 3], axis=1))
        names += chain.joint_names
        columns.append(q)
    q = np.hstack(columns)
    return JointPath(
        method="mc-inverse",
        joint_names=tuple(names),
        t=reference.t,
        rep=reference.rep,
        q=q,
        qd=np.gradient(q, reference.t, axis=0),
        status=np.zeros(len(reference), int),
        solve_time_s=times,
        hand_error_m=np.stack(errors, axis=1),
        hands=tuple(task.spec.hands),
        fixed={n: v for n, v in task.initial_q.items() if n not in names},
    )


def _kept_branch(hand: str, names, q0: np.ndarray, reference, candidates: np.ndarray, reasons: np.ndarray, max_step: float) -> np.ndarray:
    """The candidate branch nearest ``q0`` [rad] at sample 0, checked along the path."""
    valid0 = np.flatnonzero(reasons[0] == VALID)
    if valid0.size == 0:
        why = ", ".join(sorted({REASONS[int(r)] for r in reasons[0]}))
        raise StageError(f"MC-Inverse, {hand} arm: no valid solution at the path start ({why})")
    branch = valid0[np.argmin(np.abs(candidates[0, valid0] - q0).max(axis=1))]
    q = candidates[:, branch]
    invalid = np.flatnonzero(reasons[:, branch] != VALID)
    if invalid.size:
        k = invalid[0]
        raise StageError(
            f"MC-Inverse, {hand} arm: sample {k} (t = {reference.t[k]:.3f} s, rep {reference.rep[k]}) has no valid "
            f"solution on the kept branch {branch + 1}: {REASONS[int(reasons[k, branch])]}"
        )
    steps = np.abs(np.diff(q, axis=0))
    jumps = np.argwhere(steps > max_step)
    if jumps.size:
        k, j = jumps[0]
        raise StageError(
            f"MC-Inverse, {hand} arm: {names[j]} jumps {steps[k, j]:.3f} rad between samples {k} and {k + 1} "
            f"(t = {reference.t[k + 1]:.3f} s), above arm_angle.max_joint_step_rad = {max_step}"
        )
    return q


def _margins(solver: McInverse, targets: np.ndarray, psi: np.ndarray, candidates: np.ndarray | None = None, reasons: np.ndarray | None = None) -> np.ndarray:
    """Per pose and candidate, the distance to the nearest joint limit [rad] (-inf where invalid
    for another reason than the limits): targets (M, 4, 4), psi (M,) -> (M, 8). Pass the
    candidates and reasons of ``solver.solve_many(targets, psi)`` when already at hand."""
    if candidates is None:
        candidates, reasons = solver.solve_many(targets, psi)
    margin = np.minimum(candidates - solver.lower, solver.upper - candidates).min(axis=2)
    return np.where((reasons == VALID) | (margin < 0), margin, -np.inf)


def _auto(solver: McInverse, targets: np.ndarray, reference, preferred: float, q0: np.ndarray, margin: float) -> np.ndarray:
    """psi per sample (N,) [rad] that moves only when it must: start at ``preferred`` (or the
    nearest angle with ``margin`` to every limit on the branch nearest ``q0``), and at each sample
    keep the previous angle if the branch still has ``margin`` there, else step to the nearest grid
    angle that has. The first repetition is walked until it ends where it began (a closed path
    then repeats), and every repetition reuses that profile, so repetitions give identical joints.
    Where no angle keeps the margin, the one with the most is taken (the branch check then names
    the sample if even that is outside the limits)."""
    first_rep = np.flatnonzero(reference.rep == reference.rep[0])
    G = len(AUTO_GRID)
    grid = np.angle(np.exp(1j * (AUTO_GRID + preferred)))
    start_poses = np.repeat(targets[:1], G, axis=0)
    start, start_reasons = solver.solve_many(start_poses, grid)  # (G, 8, 7), (G, 8)
    m0 = _margins(solver, start_poses, grid, start, start_reasons)
    # the branches that can keep the margin all along (best angle per sample, every 5th sample on
    # a 2-degree grid); among them the one nearest q0 at the start
    coarse, picks = grid[::4], first_rep[::5]
    reach = _margins(solver, np.repeat(targets[picks], len(coarse), axis=0), np.tile(coarse, len(picks))).reshape(len(picks), len(coarse), 8)
    worst = reach.max(axis=1).min(axis=0)  # (8,)
    usable = worst >= margin if (worst >= margin).any() else worst == worst.max()
    cost = np.where((m0 >= margin) & usable[None], np.abs(start - q0).max(axis=2), np.inf)
    if not np.isfinite(cost).any():
        cost = np.where(usable[None], -m0, np.inf)
    g, branch = np.unravel_index(np.argmin(cost), cost.shape)
    psi0 = preferred if m0[np.argmin(np.abs(grid - preferred)), branch] >= margin else grid[g]
    for _ in range(3):  # walk the repetition until it closes on its start angle
        profile = np.empty(len(first_rep))
        current = psi0
        for i, k in enumerate(first_rep):
            if _margins(solver, targets[k : k + 1], np.array([current]))[0, branch] < margin:
                around = np.angle(np.exp(1j * (AUTO_GRID + current)))
                m = _margins(solver, np.repeat(targets[k : k + 1], G, axis=0), around)[:, branch]
                distance = np.abs(np.angle(np.exp(1j * (around - current))))
                current = around[np.argmin(np.where(m >= margin, distance, np.inf))] if (m >= margin).any() else around[np.argmax(m)]
            profile[i] = current
        if abs(np.angle(np.exp(1j * (profile[-1] - psi0)))) < 1e-12:
            break
        psi0 = profile[-1]
    # later repetitions repeat the first one's poses: the first repetition's sample at the same time
    phase = np.rint(time_in_repetition(reference) / reference.period_s).astype(int)
    return profile[np.clip(phase, 0, len(profile) - 1)]
