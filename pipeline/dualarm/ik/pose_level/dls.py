"""DLS-SVD inverse kinematics, eqs (12)-(20) of Li & Liang.

Li & Liang, *Study on Humanoid Robot's Dual-arm Collision Avoidance Motion Planning Algorithm*, eqs (12)-(20).

One or several tips (hands) are driven to full 6-D poses given in a common base link's frame. The
joints are the union of the base -> tip chains, shared joints (the waist of the 17-DOF model,
eq 2) once, so a shared joint has rows in every hand's Jacobian block. Each iteration solves the
damped least-squares problem

    min |J dtheta - dx|^2 + lambda^2 |dtheta|^2                                   (12)-(15)

through the SVD J = U D V^T (17):

    dtheta = sum_i  s_i / (s_i^2 + lambda^2)  v_i u_i^T dx                        (18)-(20)

(eq 12 as the squared norms of eq 13; eq 16 as J^T (J J^T + lambda^2 I)^-1, the form eq 17 then
decomposes). ``dx`` stacks, per hand, the position error p* - p [m] and the rotation vector
log(R* R^T) [rad], both in the base frame, which is the frame of the geometric Jacobian's
[v; w] rows.

Damping rule. The paper only says lambda should be "smaller than sqrt(det(J J^T)) near a singular
configuration and greater far from it"; that inverts the purpose of damping (sqrt(det(J J^T)), the
manipulability, goes to zero at a singularity, so the rule would switch damping off exactly where
it is needed) and gives no number, so it is not used. Instead, the singular-region rule of
Nakamura & Hanafusa (1986) in the form of Maciejewski & Klein (1988) / Chiaverini (1997), on the
smallest singular value s_min that eq (17) already provides:

    lambda^2 = lambda_max^2 (1 - (s_min / eps)^2)   if s_min < eps,   else 0.

Far from singularities lambda = 0 and the step is the pseudoinverse (Gauss-Newton) step, so the
last iterations converge quadratically to the 1e-9 tolerances; inside the singular region of
width ``eps`` the damping rises smoothly to ``lambda_max`` at s_min = 0, bounding |dtheta| by
|dx| / (2 lambda). Singular values and lambda carry J's mixed units (m/rad in position rows, 1
in orientation rows). With several hands the SVD is of the stacked Jacobian and one lambda serves
all its rows: the paper writes (12)-(20) per arm k with its own lambda_k, but a shared waist
couples the arms' steps, so they are solved as one system.

Fixed damping alone does not reach 1e-9 when the solution itself lies in the singular region (a
nearly straight elbow, ~1 in 10 random arm poses): along the weak direction the error shrinks
only by lambda^2 / (s^2 + lambda^2) per step, 0.99 at s = 0.005. The rule's lambda is therefore
scaled by a Levenberg-Marquardt factor mu in [0, 1] (Marquardt 1963): mu starts at 1 (the rule as
published), is halved after every step that lowers |dx|^2, and a step that does not is retried
from the same configuration with mu four times larger; a step at mu = 1 is always taken, as the
plain method would. So damping is at its full rule value wherever the linearisation misleads the
step, and fades once the steps converge.

Step and joint limits. Each step is scaled down, direction kept, so that no joint moves more than
``max_step_rad`` (the linearisation is trusted only that far), then the new configuration is
clamped to the joint position limits. A joint already at a limit whose step would push it further
out is left out of the Jacobian (its column zeroed) and the step recomputed, repeatedly until no
such joint remains (the "joint clamping" of Baerlocher & Boulic 2004), so the other joints take up
its share of the motion instead of the solve stalling against the limit. The solve stops with
``converged=False`` and a reason when the pose error has not reached the tolerances after
``max_iterations`` steps (tried steps, retried ones included), or earlier when a step no longer
changes the configuration (a local minimum of the error, e.g. against a limit).

Evaluation. The pose errors and the stacked Jacobian are one CasADi Function of the packed vector
[theta; targets], called once per iteration through a FunctionBuffer; the SVD and the step are
numpy.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import casadi as cs
import numpy as np

from dualarm.arrays import frozen
from dualarm.errors import StageError
from dualarm.model.kinematics import chain_frames, geometric_jacobian
from dualarm.model.robot import Robot
from dualarm.numerics.compiled import compiled
from dualarm.settings import check_positive

#: Singular values below this fraction of the largest count as zero when there is no damping.
RANK_TOLERANCE = 1e-12
#: Levenberg-Marquardt factor mu: multiplied by this after a step that lowered |dx|^2 ...
MU_DECREASE = 0.5
#: ... and by this (up to 1) when a step did not, the step being retried.
MU_INCREASE = 4.0


@dataclass(frozen=True)
class DlsSettings:
    """Settings of the DLS-SVD solver.

    Attributes:
        position_tolerance_m: largest accepted hand position error [m] (every hand).
        orientation_tolerance_rad: largest accepted hand rotation error angle [rad] (every hand).
        max_iterations: steps tried (retried ones included) before the solve gives up.
        singular_region: eps of the damping rule: damping is on while the smallest singular value
            of the stacked Jacobian is below it [m/rad, mixed units of J].
        max_damping: lambda_max of the damping rule, the damping at s_min = 0 [same units].
        max_step_rad: largest change of any joint in one step [rad].
        stall_step_rad: the solve stops as stalled when no joint moved more than this in a step [rad].
    """

    position_tolerance_m: float = 1e-9
    orientation_tolerance_rad: float = 1e-9
    max_iterations: int = 200
    singular_region: float = 0.05
    max_damping: float = 0.05
    max_step_rad: float = 0.5
    stall_step_rad: float = 1e-15

    def __post_init__(self) -> None:
        check_positive(
            self, "position_tolerance_m", "orientation_tolerance_rad", "singular_region", "max_damping", "max_step_rad"
        )
        check_positive(self, "stall_step_rad", zero=True)
        check_positive(self, "max_iterations", integer=True)


@dataclass(frozen=True)
class DlsResult:
    """Outcome of one DLS-SVD solve.

    Attributes:
        q: final configuration of :attr:`DlsSolver.joint_names` [rad], (n,), within the limits.
        converged: every hand within both tolerances at ``q``.
        iterations: steps tried, retried ones included.
        position_error_m: largest hand position error at ``q`` [m].
        orientation_error_rad: largest hand rotation error angle at ``q`` [rad].
        reason: why the solve stopped unconverged (empty when converged).
    """

    q: np.ndarray
    converged: bool
    iterations: int
    position_error_m: float
    orientation_error_rad: float
    reason: str = ""


def damping(smallest_singular_value: float, settings: DlsSettings) -> float:
    """Damping factor lambda of eqs (12)-(20) by the Nakamura-Maciejewski singular-region rule.

    lambda^2 = lambda_max^2 (1 - (s_min / eps)^2) for s_min < eps, else 0.

    Args:
        smallest_singular_value: s_min of the stacked Jacobian [mixed units of J].
        settings: ``singular_region`` (eps) and ``max_damping`` (lambda_max).

    Returns:
        lambda [same units], in [0, lambda_max].
    """
    ratio = smallest_singular_value / settings.singular_region
    if ratio >= 1.0:
        return 0.0
    return settings.max_damping * float(np.sqrt(1.0 - ratio * ratio))


def dls_step(J: np.ndarray, dx: np.ndarray, settings: DlsSettings, scale: float = 1.0) -> tuple[np.ndarray, float]:
    """One damped least-squares step through the SVD, eqs (17)-(20).

    Args:
        J: stacked geometric Jacobian, (m, n).
        dx: stacked pose error [m and rad], (m,).
        settings: the damping rule's constants.
        scale: the Levenberg-Marquardt factor mu in [0, 1] applied to the rule's lambda.

    Returns:
        The joint step dtheta [rad], (n,), and the damping lambda = mu * lambda_rule used.
    """
    U, s, Vt = np.linalg.svd(J, full_matrices=False)  # eq (17)
    lam = scale * damping(float(s[-1]), settings)
    denominator = s * s + lam * lam
    # eq (19); directions with no singular value (rank loss) and no damping contribute nothing, as in a pseudoinverse
    e = np.divide(s, denominator, out=np.zeros_like(s), where=s > RANK_TOLERANCE * s[0])
    return Vt.T @ (e * (U.T @ dx)), lam  # eq (20)


def _rotation_error(R: cs.SX) -> tuple[cs.SX, cs.SX]:
    """Rotation vector log(R) (3,) [rad] and its angle [rad], valid over the whole of SO(3).

    For angles up to pi/2 the vector is v * theta / sin(theta) with v = vee(R - R^T) / 2; beyond,
    where that ratio loses precision, the axis comes from the symmetric part (R + R^T) / 2 - cos I
    = (1 - cos) a a^T, its sign from v.
    """
    c = (R[0, 0] + R[1, 1] + R[2, 2] - 1) / 2
    v = cs.vertcat(R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]) / 2
    s = cs.norm_2(v)
    angle = cs.atan2(s, c)
    ratio = cs.if_else(s < 1e-6, 1 + s * s / 6, angle / s)
    B = (R + R.T) / 2 - c * cs.SX.eye(3)
    first = cs.logic_and(B[0, 0] >= B[1, 1], B[0, 0] >= B[2, 2])
    column = cs.if_else(first, B[:, 0], cs.if_else(B[1, 1] >= B[2, 2], B[:, 1], B[:, 2]))
    diagonal = cs.if_else(first, B[0, 0], cs.if_else(B[1, 1] >= B[2, 2], B[1, 1], B[2, 2]))
    axis = column / cs.sqrt(diagonal * (1 - c))
    axis = cs.if_else(cs.dot(axis, v) >= 0, axis, -axis)
    return cs.if_else(c > 0, v * ratio, angle * axis), angle


@dataclass(frozen=True)
class DlsSolver:
    """DLS-SVD IK of one or several tips sharing a base link.

    Attributes:
        base: base link; targets are tip poses in its frame.
        tips: the tip links, the order of the targets and of the stacked rows.
        joint_names: union of the base -> tip chains' movable joints, shared ones once, URDF order;
            the order of ``q``.
        lower: lower position limits [rad], (n,).
        upper: upper position limits [rad], (n,).
        settings: solver settings.
        evaluate: CasADi Function ``x (n + 16 h) -> (dx (6 h), errors (2 h), J (6 h, n))``, where
            x = [theta; each target's 4x4 column-major], dx stacks [p* - p; log(R* R^T)] per tip
            [m, rad], errors holds the tips' position errors |p* - p| [m] then their rotation
            angles [rad], and J is the stacked geometric Jacobian [v; w] in the base frame.
    """

    base: str
    tips: tuple[str, ...]
    joint_names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    settings: DlsSettings
    evaluate: cs.Function

    @classmethod
    def of(cls, robot: Robot, base: str, tips: Sequence[str], settings: DlsSettings = DlsSettings()) -> DlsSolver:
        """The solver for ``tips`` of ``robot`` in the frame of link ``base``.

        Built once per robot, base, tips and settings in a process, then kept (a study's worker builds it once, not
        per trial).

        Args:
            robot: the robot.
            base: base link name.
            tips: tip link names (one per hand), distinct.
            settings: solver settings.

        Raises:
            StageError: no tips, repeated tips, or a tip whose chain from ``base`` has no movable joint.
            RobotModelError: a link name the URDF does not have or no chain between ``base`` and a tip.
        """
        return _solver(robot, base, tuple(tips), settings)

    @classmethod
    def _build(cls, robot: Robot, base: str, tips: tuple[str, ...], settings: DlsSettings) -> DlsSolver:
        """Build the solver (see :meth:`of`)."""
        if not tips:
            raise StageError("DLS solver: no tips given (give at least one tip link, e.g. 'left_hand')")
        if len(set(tips)) != len(tips):
            raise StageError(f"DLS solver: tips repeated in {', '.join(tips)}")
        chains = [robot.chain_between(base, tip) for tip in tips]
        for chain in chains:
            if chain.dof == 0:
                raise StageError(f"DLS solver: the chain {base} -> {chain.tip} has no movable joint")
        used = {name for chain in chains for name in chain.joint_names}
        names = tuple(name for name in robot.joint_names if name in used)
        index = {name: i for i, name in enumerate(names)}
        n, h = len(names), len(tips)

        x = cs.SX.sym("x", n + 16 * h)
        theta = x[:n]
        dx, position_errors, angles, blocks = [], [], [], []
        for k, chain in enumerate(chains):
            frames = chain_frames(chain)
            columns = [index[name] for name in chain.joint_names]
            q = theta[columns]
            T = cs.substitute(frames.tip, frames.q, q)
            Jc = cs.substitute(geometric_jacobian(frames, chain), frames.q, q)
            target = cs.reshape(x[n + 16 * k : n + 16 * (k + 1)], 4, 4)
            dp = target[:3, 3] - T[:3, 3]
            rotvec, angle = _rotation_error(target[:3, :3] @ T[:3, :3].T)
            dx += [dp, rotvec]
            position_errors.append(cs.norm_2(dp))
            angles.append(angle)
            J = cs.SX.zeros(6, n)
            J[:, columns] = Jc
            blocks.append(J)
        # J^T column-major is J row-major: the buffer fills a C-ordered (6 h, n) array.
        evaluate = compiled(
            cs.Function(
                f"dls_{base}_{'_'.join(tips)}",
                [x],
                [cs.vertcat(*dx), cs.vertcat(*position_errors, *angles), cs.densify(cs.vertcat(*blocks).T)],
                ["x"],
                ["dx", "errors", "JT"],
            )
        )
        lower, upper = robot.lower_upper(names)
        return cls(
            base=base,
            tips=tips,
            joint_names=names,
            lower=frozen(lower, (n,), "lower"),
            upper=frozen(upper, (n,), "upper"),
            settings=settings,
            evaluate=evaluate,
        )

    @property
    def n(self) -> int:
        """Number of joints."""
        return len(self.joint_names)

    def _pack_targets(self, targets: Sequence[np.ndarray]) -> np.ndarray:
        if len(targets) != len(self.tips):
            raise StageError(
                f"DLS solver: {len(targets)} target poses for {len(self.tips)} tips ({', '.join(self.tips)})"
            )
        packed = []
        for tip, T in zip(self.tips, targets, strict=True):
            T = np.asarray(T, dtype=float)
            if T.shape != (4, 4) or not np.all(np.isfinite(T)):
                raise StageError(f"DLS solver: the target of '{tip}' must be a finite 4x4 pose, got shape {T.shape}")
            packed.append(T.ravel(order="F"))
        return np.concatenate(packed)

    def _seed(self, seed: np.ndarray) -> np.ndarray:
        seed = np.asarray(seed, dtype=float)
        if seed.shape != (self.n,) or not np.all(np.isfinite(seed)):
            raise StageError(
                f"DLS solver: the seed must be {self.n} finite joint values ({', '.join(self.joint_names)}), "
                f"got shape {seed.shape}"
            )
        return np.clip(seed, self.lower, self.upper)

    def _evaluator(self, targets: Sequence[np.ndarray]):
        """A callable ``theta -> (dx, errors, J)`` evaluating :attr:`evaluate` through a FunctionBuffer.

        On numpy arrays (returned arrays are overwritten by the next call).
        """
        h = len(self.tips)
        x = np.concatenate([np.zeros(self.n), self._pack_targets(targets)])
        dx, errors, J = np.zeros(6 * h), np.zeros(2 * h), np.zeros((6 * h, self.n))
        buffer, run = self.evaluate.buffer()
        buffer.set_arg(0, x.data)
        buffer.set_res(0, dx.data)
        buffer.set_res(1, errors.data)
        buffer.set_res(2, J.data)

        def evaluate(theta: np.ndarray, _keep=buffer):
            x[: self.n] = theta
            run()
            return dx, errors, J

        return evaluate

    def damping_at(self, q: np.ndarray) -> float:
        """The rule's damping lambda at configuration ``q`` [rad], (n,), clamped to the limits.

        See :func:`damping`: the lambda of the first step from ``q``, before any Levenberg-Marquardt scaling.
        """
        J = self._evaluator([np.eye(4)] * len(self.tips))(self._seed(q))[2]
        return damping(float(np.linalg.svd(J, compute_uv=False)[-1]), self.settings)

    def _step(self, q: np.ndarray, J: np.ndarray, dx: np.ndarray, scale: float) -> np.ndarray:
        """The DLS step at ``q`` [rad] with joint clamping and the step cap (module docstring)."""
        at_lower, at_upper = q <= self.lower, q >= self.upper
        free = np.ones(self.n, dtype=bool)
        while True:
            step, _ = dls_step(J * free, dx, self.settings, scale)  # eqs (17)-(20) on the free joints
            step[~free] = 0.0
            largest = np.abs(step).max()
            if largest > self.settings.max_step_rad:
                step *= self.settings.max_step_rad / largest
            outward = free & ((at_lower & (step < 0)) | (at_upper & (step > 0)))
            if not outward.any():
                return step
            free &= ~outward

    def solve(self, targets: Sequence[np.ndarray], seed: np.ndarray) -> DlsResult:
        """Drive every tip to its target pose from ``seed``.

        Args:
            targets: one 4x4 pose [m] per tip, in the base frame, in the order of :attr:`tips`.
            seed: starting configuration [rad], (n,), clamped to the limits first.

        Returns:
            The result; ``converged=False`` with a reason when the tolerances were not reached.

        Raises:
            StageError: a target or the seed of the wrong shape or not finite.
        """
        settings = self.settings
        h = len(self.tips)
        evaluate = self._evaluator(targets)
        q = self._seed(seed)
        dx, errors, J = (a.copy() for a in evaluate(q))
        cost = dx @ dx
        mu = 1.0
        reason = ""
        iterations = 0
        while True:
            if (
                errors[:h].max() <= settings.position_tolerance_m
                and errors[h:].max() <= settings.orientation_tolerance_rad
            ):
                break
            if iterations == settings.max_iterations:
                reason = f"no convergence in {iterations} iterations"
                break
            new = np.clip(q + self._step(q, J, dx, mu), self.lower, self.upper)
            iterations += 1
            if np.abs(new - q).max() <= settings.stall_step_rad:
                reason = f"stalled after {iterations} iterations"
                break
            new_dx, new_errors, new_J = evaluate(new)
            new_cost = new_dx @ new_dx
            if new_cost < cost or mu == 1.0:  # a full-damping step is always taken, as in the paper
                if new_cost < cost:
                    mu *= MU_DECREASE
                q, cost = new, new_cost
                dx, errors, J = new_dx.copy(), new_errors.copy(), new_J.copy()
            else:  # retry from q with more damping
                mu = min(1.0, mu * MU_INCREASE)
        converged = not reason
        if not converged:
            reason += f" (position error {errors[:h].max():.3g} m, orientation error {errors[h:].max():.3g} rad)"
        return DlsResult(
            q=frozen(q, (self.n,), "q"),
            converged=converged,
            iterations=iterations,
            position_error_m=float(errors[:h].max()),
            orientation_error_rad=float(errors[h:].max()),
            reason=reason,
        )


#: Most DLS solvers a process keeps (:meth:`DlsSolver.of`).
KEPT_SOLVERS = 32


@functools.lru_cache(maxsize=KEPT_SOLVERS)
def _solver(robot: Robot, base: str, tips: tuple[str, ...], settings: DlsSettings) -> DlsSolver:
    return DlsSolver._build(robot, base, tips, settings)
