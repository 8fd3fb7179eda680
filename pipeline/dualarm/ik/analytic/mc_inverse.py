"""MC-Inverse: closed-form inverse kinematics of an S-R-S arm at a given arm angle.

Zou, Min, Xu, *MC-Inverse: An Analytical Method for Consistent Motion of Anthropomorphic Dual-arm
Robot*, section III.B. For a hand pose (p, R) and an arm angle psi the arm has 8 joint solutions:
two elbow angles (sub-problem 1, eqs 2-4), and for each two shoulder (sub-problem 2, eqs 5-10) and
two wrist (sub-problem 3) triples.

The paper writes sub-problems 2 and 3 for its HR2 arm, whose shoulder and wrist are ZYZ Euler
joints. Here they are written for any S-R-S chain read from a URDF. The forward kinematics is a
product of exponentials: the rotation of the frame after joint i is
exp(k_1 theta_1) ... exp(k_i theta_i) R_i(0), where k_i is joint i's axis at the zero configuration
in the chain base frame. Sub-problems 2 and 3 then become "Euler angles about three arbitrary
axes":

    Q = exp(k_a theta_a) exp(k_b theta_b) exp(k_c theta_c).

The middle angle solves k_a . exp(k_b theta_b) k_c = k_a . Q k_c, which has two roots; for the
ZYZ axes these are eqs (9) and (10). The outer angles are rotations of one known vector onto
another about a known axis. Each joint's sign and offset against the canonical model are absorbed
by the zero-configuration axes k_i and the elbow's zero angle. These are derived from the chain
when it is loaded, and the solver is checked against the chain's own forward kinematics.

The solver requires consecutive shoulder axes and consecutive wrist axes to be perpendicular, as
in every S-R-S arm of the papers. A chain that is not S-R-S is refused with the axes at fault
named.

Everything is one CasADi Function, ``(T (4x4), psi) -> (Q (7x8), reason (1x8))``, compiled to
machine code (:mod:`dualarm.numerics.compiled`), which can be mapped over a whole path in one call.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache, cached_property

import casadi as cs
import numpy as np

from dualarm.arrays import RIGID_TOLERANCE, finite_array, joint_vector, rigid_transforms
from dualarm.errors import InvalidArgumentError, NoSolutionFound, NotSRSError
from dualarm.ik.analytic.subproblems import elbow, euler, into_limits, rotate, rotation, triad, zero_axes
from dualarm.model.robot import Chain, Robot
from dualarm.model.srs import SrsKinematics
from dualarm.numerics.batched import Batched, BatchedCandidates, Single
from dualarm.numerics.compiled import compiled

#: Candidate order: index = 4 * elbow + 2 * shoulder + wrist, each 0 (the first root: theta_4 =
#: beta - phi_0, or the middle Euler angle with sine >= 0 from its singular position) or 1.
CANDIDATES = 8

#: Validity codes of a candidate, in order of precedence.
VALID, OUT_OF_REACH, SINGULAR, OUTSIDE_LIMITS = 0, 1, 2, 3
#: SINGULAR: the elbow is straight, the shoulder-wrist line is vertical (no reference plane), or a
#: shoulder or wrist middle joint aligns the outer two axes; the solution is not isolated there.
REASONS = {VALID: "valid", OUT_OF_REACH: "out of reach", SINGULAR: "singular", OUTSIDE_LIMITS: "outside limits"}

#: Poses per mapped call of :meth:`McInverse.margins_on_grid` (each at every angle of the grid).
GRID_CHUNK = 64

#: Sine below which an elbow, shoulder or wrist counts as singular (the solution is not isolated).
SINGULAR_SINE = 1e-7
#: Largest cosine between two axes that count as perpendicular.
PERPENDICULAR_COSINE = 1e-9


@dataclass(frozen=True)
class McInverse:
    """MC-Inverse of one S-R-S arm chain.

    Attributes:
        kinematics: S, E, W and the arm angle psi(q) of eq (1) for the chain.
        lower, upper: joint limits [rad], (7,).
        candidates: Function ``(T (4x4) hand pose in the chain base frame [m], psi [rad]) ->
            (Q (7x8) [rad], reason (1x8))``, column j the candidate with index j (see
            :data:`CANDIDATES`), reason one of :data:`REASONS`; compiled (:mod:`dualarm.numerics.compiled`).
        checked: the same with a third output, whether the inputs pass :meth:`solve`'s checks
            (finite, a rigid transform): the one-pose call.
        with_margins: ``(T, psi) -> (Q (7x8) [rad], margin (1x8) [rad])``, margin each valid
            candidate's distance to its nearest joint limit, -inf for the others.
    """

    kinematics: SrsKinematics
    lower: np.ndarray
    upper: np.ndarray
    candidates: cs.Function
    checked: cs.Function
    with_margins: cs.Function

    @property
    def chain(self) -> Chain:
        """The arm chain."""
        return self.kinematics.geometry.chain

    @classmethod
    def of(cls, chain: Chain, vertical: tuple[float, float, float] = (0.0, 0.0, 1.0)) -> McInverse:
        """The solver for ``chain``; ``vertical`` is V of eq (1) in the chain base frame.

        Derived once per chain and vertical in a process, then kept (a study's worker derives it once, not per
        trial).

        Raises:
            NotSRSError: the chain is not S-R-S, or consecutive shoulder or wrist axes are not
                perpendicular.
        """
        return _solver(chain, (float(vertical[0]), float(vertical[1]), float(vertical[2])))

    @classmethod
    def _derive(cls, chain: Chain, vertical: tuple[float, float, float]) -> McInverse:
        """Derive the solver (see :meth:`of`)."""
        kin = SrsKinematics.of(chain, vertical)
        geo = kin.geometry
        movable = [j for j in chain.joints if j.movable]
        k, tip0 = zero_axes(chain)  # axes and tip rotation at q = 0
        for a, b in ((0, 1), (1, 2), (4, 5), (5, 6)):
            if abs(k[a] @ k[b]) > PERPENDICULAR_COSINE:
                raise NotSRSError(
                    f"chain '{chain.name}': the axes of {movable[a].name} and {movable[b].name} are not perpendicular, "
                    "which MC-Inverse needs",
                    chain=chain.name,
                )
        S, E0, W0 = (np.asarray(x).ravel() for x in kin.points(np.zeros(7)))
        lower = np.array([j.lower for j in movable])
        upper = np.array([j.upper for j in movable])

        T, psi = cs.SX.sym("T", 4, 4), cs.SX.sym("psi")
        R = T[:3, :3]
        L2, L3 = geo.upper_arm, geo.forearm
        a4 = k[3]
        W, sw, d, out_of_reach, beta, elbows = elbow(geo, S, E0, W0, a4, T)  # eqs (2)-(4)
        u = sw / d
        # the elbow circle: alpha at S between SW and SE; psi = 0 with the elbow below SW in the
        # vertical plane, psi growing for a turn about -SW (eq 5)
        cos_alpha = cs.fmin(1, cs.fmax(-1, (L2**2 + d**2 - L3**2) / (2 * L2 * d)))
        V = np.asarray(vertical, dtype=float)
        down = -(V - cs.dot(V, u) * u)
        n0 = down / cs.norm_2(down)
        n = cs.cos(psi) * n0 + cs.sin(psi) * cs.cross(-u, n0)
        E = S + L2 * (cos_alpha * u + cs.sqrt(1 - cos_alpha**2) * n)  # eq (5)
        singular_reference = cs.norm_2(cs.cross(u, V)) < SINGULAR_SINE  # SW vertical: no reference plane

        singular_elbow = cs.logic_or(cs.sin(beta) < SINGULAR_SINE, singular_reference)
        columns, reasons = [], []
        for theta4 in elbows:
            c4, s4 = cs.cos(theta4), cs.sin(theta4)
            # sub-problem 2: the shoulder rotation turns SE(0) onto SE and the forearm onto EW (eqs 6-8)
            Q = triad(E - S, W - E) @ triad(cs.SX(E0 - S), rotate(a4, c4, s4, cs.SX(W0 - E0))).T
            shoulders, s_shoulder = euler(Q, k[0], k[1], k[2])  # eqs (9)-(10)
            arm = Q @ rotation(a4, c4, s4)  # exp(k1 t1) ... exp(k4 t4): both shoulder triples reproduce Q
            wrists, s_wrist = euler(arm.T @ R @ tip0.T, k[4], k[5], k[6])  # sub-problem 3
            singular = cs.logic_or(singular_elbow, cs.fmin(s_shoulder, s_wrist) < SINGULAR_SINE)
            for t1, t2, t3 in shoulders:
                for t5, t6, t7 in wrists:
                    q = cs.vertcat(
                        *[
                            into_limits(a, lo, hi)
                            for a, lo, hi in zip((t1, t2, t3, theta4, t5, t6, t7), lower, upper, strict=True)
                        ]
                    )
                    outside = cs.logic_or(cs.mmax(q - upper) > 0, cs.mmax(lower - q) > 0)
                    reasons.append(
                        cs.if_else(
                            out_of_reach,
                            OUT_OF_REACH,
                            cs.if_else(singular, SINGULAR, cs.if_else(outside, OUTSIDE_LIMITS, VALID)),
                        )
                    )
                    columns.append(q)
        outputs = [cs.horzcat(*columns), cs.horzcat(*reasons)]
        candidates = cs.Function("mc_inverse", [T, psi], outputs, ["T", "psi"], ["Q", "reason"], {"cse": True})
        # the one-pose call's input check, in the same compiled call (rigid_transforms' tests, finite_array's for psi)
        finite = cs.logic_all(cs.fabs(cs.vertcat(cs.vec(T), psi)) < cs.inf)
        orthogonal = cs.mmax(cs.fabs(R.T @ R - np.eye(3))) <= RIGID_TOLERANCE
        row = cs.mmax(cs.fabs(T[3, :] - cs.DM([[0, 0, 0, 1]]))) <= RIGID_TOLERANCE
        accepted = cs.logic_and(cs.logic_and(finite, orthogonal), cs.logic_and(row, cs.det(R) >= 0))
        checked = cs.Function(
            "mc_inverse_checked",
            [T, psi],
            [*outputs, accepted],
            ["T", "psi"],
            ["Q", "reason", "accepted"],
            {"cse": True},
        )
        # each valid candidate's distance to its nearest joint limit, for the arm-angle search (mc_path._auto)
        margins = [
            cs.if_else(r == VALID, cs.mmin(cs.fmin(q - cs.DM(lower), cs.DM(upper) - q)), -cs.inf)
            for q, r in zip(columns, reasons, strict=True)
        ]
        with_margins = cs.Function(
            "mc_inverse_margins",
            [T, psi],
            [outputs[0], cs.horzcat(*margins)],
            ["T", "psi"],
            ["Q", "margin"],
            {"cse": True},
        )
        return cls(
            kinematics=kin,
            lower=lower,
            upper=upper,
            candidates=compiled(candidates),
            checked=compiled(checked),
            with_margins=compiled(with_margins),
        )

    def solve(self, pose: np.ndarray, psi: float) -> McSolution:
        """All 8 candidates for one hand pose (4x4, chain base frame) [m] at arm angle ``psi`` [rad].

        One compiled call that also checks the inputs; only inputs it does not accept go through
        the checks that name what is wrong. Not thread-safe (one buffer per solver).

        Raises:
            InvalidArgumentError: ``pose`` is not a 4x4 rigid transform, or ``psi`` is not finite.
        """
        T = pose if isinstance(pose, np.ndarray) and pose.shape == (4, 4) and pose.dtype.kind in "fiu" else None
        if T is None or not isinstance(psi, (int, float, np.number)):  # not the arrays this call takes as they are
            T, psi = rigid_transforms(pose, "pose"), float(finite_array(psi, "psi", ()))
        out = self._one(T, psi)  # Q (7x8, column-major: candidate by candidate), reason (8), accepted
        if not out[-1]:
            rigid_transforms(
                T, "pose"
            )  # raise, naming the fault (where numpy accepts at the tolerance's edge, the result stands)
            finite_array(psi, "psi", ())
        return McSolution(
            q=out[:-9].reshape(CANDIDATES, -1), reason=out[-9:-1].astype(int), joint_names=self.chain.joint_names
        )

    def solve_many(self, poses: np.ndarray, psi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Candidates for N poses (N, 4, 4) [m] at arm angles (N,) [rad], in mapped calls.

        Returns:
            q (N, 8, 7) [rad] and reason codes (N, 8).
        """
        return self._batched.candidates(poses, psi)

    def margins_on_grid(self, poses: np.ndarray, psi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Candidates for N poses (N, 4, 4) [m], each at every arm angle of a grid (G,) [rad].

        With each candidate's distance to its nearest joint limit, -inf where it is not valid: q (N, G, 8, 7) [rad],
        margin (N, G, 8) [rad].

        One mapped call per chunk of poses, each pose passed once for its G angles.
        """
        psi = np.asarray(psi, dtype=float).ravel()
        G = len(psi)
        if G not in self._grids:  # with_margins mapped over the grid, the pose shared (not mapped)
            self._grids[G] = Batched(
                self.with_margins.map(f"mc_inverse_margins_{G}", "serial", G, [0], []), chunk=GRID_CHUNK
            )
        q, margin = self._grids[G](np.asarray(poses, dtype=float).reshape(-1, 4, 4), psi[None])
        return q.transpose(0, 2, 1).reshape(len(q), G, CANDIDATES, -1), margin.reshape(len(q), G, CANDIDATES)

    @cached_property
    def _batched(self) -> BatchedCandidates:
        return BatchedCandidates(self.candidates)

    @cached_property
    def _grids(self) -> dict[int, Batched]:
        return {}

    @cached_property
    def _one(self) -> Single:
        return Single(self.checked)


@dataclass(frozen=True)
class McSolution:
    """The 8 candidates of one pose.

    Attributes:
        q: joint values [rad], (8, 7), row j the candidate with index j.
        reason: validity code per candidate (see :data:`REASONS`), (8,).
        joint_names: the arm's joints, the columns of ``q``.
    """

    q: np.ndarray
    reason: np.ndarray
    joint_names: tuple[str, ...] = ()

    @property
    def reasons(self) -> tuple[str, ...]:
        """Each candidate's validity in words (``valid``, ``out of reach``, ``singular``, ``outside limits``)."""
        return tuple(REASONS[int(r)] for r in self.reason)

    @property
    def valid(self) -> np.ndarray:
        """Mask of valid candidates, (8,)."""
        return self.reason == VALID

    def nearest(self, seed: np.ndarray | Mapping[str, float]) -> np.ndarray:
        """The valid candidate nearest ``seed`` (largest joint difference), (7,) [rad].

        The branch MC-Inverse keeps along a path when ``seed`` is the initial configuration.

        Args:
            seed: the arm's joints (7,) [rad], or a configuration joint name -> value holding them.

        Raises:
            InvalidArgumentError: ``seed`` is not 7 finite numbers (or lacks one of the arm's joints).
            NoSolutionFound: no candidate is valid (the reasons are in the message).
        """
        if isinstance(seed, Mapping):
            seed = joint_vector(seed, self.joint_names, "seed")
        index = nearest_candidate(self.q, self.reason, finite_array(seed, "seed", (self.q.shape[1],)))
        if index is None:
            raise NoSolutionFound(
                f"MC-Inverse: no valid candidate ({', '.join(sorted({REASONS[int(r)] for r in self.reason}))})",
                stage="ik",
            )
        return self.q[index].copy()


def nearest_candidate(q: np.ndarray, reason: np.ndarray, seed: np.ndarray) -> int | None:
    """Index of the valid candidate of ``q`` (8, 7) [rad] (``reason`` (8,)) nearest ``seed`` (7,) [rad].

    Nearest by the largest joint difference, or None if none is valid.
    """
    valid = np.flatnonzero(reason == VALID)
    if valid.size == 0:
        return None
    return int(valid[np.argmin(np.abs(q[valid] - seed).max(axis=1))])


@cache
def _solver(chain: Chain, vertical: tuple[float, float, float]) -> McInverse:
    return McInverse._derive(chain, vertical)


def mc_inverse(
    robot: Robot,
    hand: str,
    pose: np.ndarray,
    psi: float,
    q: Mapping[str, float] | str | None = None,
    vertical: tuple[float, float, float] = (0.0, 0.0, 1.0),
) -> McSolution:
    """MC-Inverse for one hand pose: the 8 candidates of ``hand``'s S-R-S arm at arm angle ``psi``.

    Args:
        robot: the robot.
        hand: ``left`` or ``right``.
        pose: the hand pose in the robot's base frame (4x4) [m], as task files give poses
            (:func:`dualarm.to_arm_frame` converts to the arm chain's frame, which
            :meth:`McInverse.solve` takes).
        psi: the arm angle of eq (1) [rad].
        q: the configuration of the joints between the base and the arm (a waist): a home pose's
            name or joint -> value [rad] (others at 0); default all 0.
        vertical: V of eq (1), in the arm chain's base frame (normalised here).

    Returns:
        The candidates, their validity and :meth:`McSolution.nearest`.

    Raises:
        InvalidArgumentError: a pose that is not a 4x4 rigid transform, a non-finite psi, a zero vertical.
        NotSRSError: the arm is not S-R-S.
    """
    from dualarm.model.kinematics import to_arm_frame

    v = finite_array(vertical, "vertical", (3,))
    if not np.linalg.norm(v) > 0:
        raise InvalidArgumentError("vertical", "must not be zero")
    chain = robot.hand_chain(hand)
    target = to_arm_frame(robot, hand, pose, q)
    unit = tuple(float(x) for x in v / np.linalg.norm(v))
    return _solver(chain, unit).solve(target, psi)


def candidate_table(
    chain: Chain,
    pose: tuple[float, ...],
    psi: float,
    vertical: tuple[float, float, float] = (0.0, 0.0, 1.0),
    frame: PoseFrame | None = None,
) -> dict:
    """The paper's Table I for one hand pose: the 8 candidates at arm angle ``psi`` [rad].

    Args:
        chain: an S-R-S arm chain.
        pose: hand pose, X Y Z [m] ROLL PITCH YAW [rad] (extrinsic x-y-z), in ``frame``.
        psi: the arm angle of eq (1) [rad].
        vertical: the reference vertical vector V of eq (1), in the chain base frame.
        frame: the frame ``pose`` is given in; default the chain base frame.

    Returns:
        A JSON-ready dict: ``chain`` (base, tip, joints), ``frame`` (``robot`` or ``chain`` and its
        link), ``pose``, ``arm_angle`` and ``candidates``, each with ``q`` [rad], ``valid``,
        ``reason``, the position and orientation errors of its forward kinematics against the pose
        [m, rad] and the arm angle of eq (1) recomputed from its joints (``arm_angle_rad``).
    """
    from dualarm.model.kinematics import ChainKinematics
    from dualarm.model.poses import pose_errors

    frame = frame or PoseFrame.chain_base(chain)
    unit = tuple(np.asarray(vertical, dtype=float) / np.linalg.norm(vertical))
    target = frame.to_chain(pose)
    solver = McInverse.of(chain, unit)
    solution = solver.solve(target, psi)
    reached = ChainKinematics.of(chain).poses(solution.q)
    position_error, orientation_error = pose_errors(reached, np.repeat(target[None], len(reached), axis=0))
    angles = solver.kinematics.arm_angles(solution.q)
    candidates = [
        {
            "q": q.tolist(),
            "valid": bool(r == VALID),
            "reason": REASONS[int(r)],
            "position_error_m": float(p),
            "orientation_error_rad": float(o),
            "arm_angle_rad": float(a),
        }
        for q, r, p, o, a in zip(solution.q, solution.reason, position_error, orientation_error, angles, strict=True)
    ]
    return {
        "chain": {"base": chain.base, "tip": chain.tip, "joints": list(chain.joint_names)},
        "frame": frame.record(),
        "pose": list(pose),
        "arm_angle": psi,
        "candidates": candidates,
    }


#: Default grid step of :func:`sweep_arm_angle` [rad] (1 degree).
SWEEP_STEP_RAD = np.pi / 180
#: Smallest and largest grid step of :func:`sweep_arm_angle` [rad] (0.01 and 30 degrees).
SWEEP_STEP_RANGE_RAD = (np.pi / 18000, np.pi / 6)


@dataclass(frozen=True)
class ArmAngleSweep:
    """Every candidate of one hand pose over a grid of arm angles.

    Which psi each branch reaches within the joint limits.

    Attributes:
        psi_rad: the grid, (G,) [rad], from -pi in steps of ``step_rad``.
        q: the candidates, (G, 8, 7) [rad].
        reason: their validity codes (see :data:`REASONS`), (G, 8).
        step_rad: the grid step [rad].
    """

    psi_rad: np.ndarray
    q: np.ndarray
    reason: np.ndarray
    step_rad: float

    def intervals(self, branch: int) -> list[tuple[float, float]]:
        """The runs of grid angles where candidate ``branch`` (0-7) is valid, as (first, last) [rad].

        A run that crosses psi = +-pi is one interval whose last angle lies above pi (first + its
        length); a branch valid on the whole grid gives (-pi, pi - step). The true ends lie within
        one step outside each run.
        """
        valid = self.reason[:, branch] == VALID
        G = len(valid)
        if valid.all():
            return [(float(self.psi_rad[0]), float(self.psi_rad[-1]))]
        runs: list[list[int]] = []
        for g in (int(i) for i in np.flatnonzero(valid)):
            if runs and runs[-1][1] == g - 1:
                runs[-1][1] = g
            else:
                runs.append([g, g])
        if len(runs) > 1 and runs[0][0] == 0 and runs[-1][1] == G - 1:  # one run across +-pi
            first = runs.pop()
            runs[0] = [first[0], runs[0][1] + G]
        return [(float(self.psi_rad[a]), float(self.psi_rad[a] + (b - a) * self.step_rad)) for a, b in runs]

    def blocking(self, branch: int) -> str:
        """The most frequent reason why ``branch`` is invalid on the grid (``valid`` when it never is)."""
        codes = self.reason[:, branch]
        codes = codes[codes != VALID]
        return REASONS[int(np.bincount(codes).argmax())] if codes.size else REASONS[VALID]

    @property
    def reachable(self) -> bool:
        """Whether any branch is valid at any grid angle."""
        return bool((self.reason == VALID).any())


def sweep_arm_angle(solver: McInverse, pose: np.ndarray, step_rad: float = SWEEP_STEP_RAD) -> ArmAngleSweep:
    """The 8 candidates of one hand pose (4x4, chain base frame) [m] at every arm angle of a grid.

    The grid runs from -pi in steps of ``step_rad`` [rad]; in one mapped call.

    Raises:
        InvalidArgumentError: ``pose`` is not a 4x4 rigid transform, or ``step_rad`` is outside
            :data:`SWEEP_STEP_RANGE_RAD`.
    """
    T = rigid_transforms(pose, "pose")
    step = float(finite_array(step_rad, "step_rad", ()))
    low, high = SWEEP_STEP_RANGE_RAD
    if not low <= step <= high:
        raise InvalidArgumentError("step_rad", f"{step:g} rad is outside [{low:g}, {high:g}] rad")
    grid = -np.pi + step * np.arange(int(np.ceil(2 * np.pi / step - 1e-9)))
    q, reason = solver.solve_many(np.repeat(T[None], len(grid), axis=0), grid)
    return ArmAngleSweep(psi_rad=grid, q=q, reason=reason, step_rad=step)


def branch_label(branch: int) -> str:
    """``branch`` (0-7) as the command line and messages name it, numbered from 1.

    For example ``3 (elbow 0, shoulder 1, wrist 0)``.
    """
    return f"{branch + 1} (elbow {branch // 4}, shoulder {branch // 2 % 2}, wrist {branch % 2})"


def sweep_table(sweep: ArmAngleSweep) -> list[dict]:
    """Per branch (numbered 1-8) its feasible arm-angle intervals [rad]; JSON-ready.

    When it has none, the most frequent reason.
    """
    rows = []
    for b in range(CANDIDATES):
        intervals = sweep.intervals(b)
        rows.append(
            {
                "branch": b + 1,
                "elbow": b // 4,
                "shoulder": b // 2 % 2,
                "wrist": b % 2,
                "intervals_rad": [list(i) for i in intervals],
                "valid_samples": int((sweep.reason[:, b] == VALID).sum()),
                "blocked_by": None if intervals else sweep.blocking(b),
            }
        )
    return rows


@dataclass(frozen=True)
class PoseFrame:
    """The frame a hand pose is given in, for ``dualarm ik srs``.

    Attributes:
        kind: ``robot`` (the robot's base frame, as task files give poses) or ``chain`` (the arm
            chain's base frame, where the solver works).
        link: the link whose frame it is.
        chain_in_frame: the chain base's pose in this frame (4x4) [m].
    """

    kind: str
    link: str
    chain_in_frame: np.ndarray

    @classmethod
    def chain_base(cls, chain: Chain) -> PoseFrame:
        """The chain's own base frame."""
        return cls("chain", chain.base, np.eye(4))

    @classmethod
    def robot_base(cls, robot: Robot, chain: Chain) -> PoseFrame:
        """The robot's base frame (its URDF's root link), the joints between it and the chain (a waist) at 0."""
        from dualarm.model.kinematics import ChainKinematics

        between = robot.chain_between(robot.urdf.root, chain.base)
        return cls("robot", robot.urdf.root, ChainKinematics.of(between).pose(np.zeros(between.dof)))

    def to_chain(self, pose: tuple[float, ...]) -> np.ndarray:
        """A pose X Y Z [m] ROLL PITCH YAW [rad] (extrinsic x-y-z) in this frame as a 4x4 transform.

        The transform is in the chain base frame [m].
        """
        from dualarm.model.poses import invert, pose_matrix

        return invert(self.chain_in_frame) @ pose_matrix(pose[:3], pose[3:])

    def record(self) -> dict:
        """JSON-ready: ``kind`` and ``link``.

        And, for the robot frame, that the joints between it and the chain are at 0.
        """
        return {"kind": self.kind, "link": self.link, **({"joints_between_at": 0.0} if self.kind == "robot" else {})}
