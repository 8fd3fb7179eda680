"""TV-GDD: velocity-level QP redundancy resolution with time-varying gesture bounds.

Zhang, Kong, Niu, *A Time-Varying-Constrained Motion Generation Scheme for Humanoid Robot Arms*.
At every control step the joint velocity is the solution of

    minimize    thetadot^T M thetadot / 2 + b^T thetadot                      (23)
    subject to  J(theta) thetadot = rdot + K (r - f(theta))                      (24)
                zeta-(t) <= thetadot <= zeta+(t)                                  (25)

(eq 24 as corrected in the seeds' README: the feedback is K(r - f(theta)) of eq 16, and the linear
term acts on the velocity) and theta is integrated by Euler, theta_{k+1} = theta_k + tau thetadot_k.

The paper's task is the hands' positions (m = 3 per hand, eq 13): ``task_space = "position"``. In
``pose`` task space (the default of a task) the hands' orientations are stacked under the positions
in (24): J_omega(theta) thetadot = omega_d + K log(R_d R(theta)^T), with the same gain K (see
:class:`~dualarm.ik.velocity.stack.HandStack`), so m = 6 per hand.

Schemes (section 2): MVN M = I, b = 0; RMP M = I, b = lambda (theta - theta(0)); MKE M = the
joint-space inertia matrix from the URDF, b = 0.

Two solvers of the same QP: a CasADi ``conic`` embedded with the kinematics and the bounds in one
CasADi Function per step, and the paper's own LVI projection-equation solver (eqs 26-27).
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal, get_args

import casadi as cs
import numpy as np

from dualarm.contracts.joint_path import JointPath, TaskSpace, check_task_space
from dualarm.contracts.reference import CartesianReference
from dualarm.errors import InvalidArgumentError, StageError
from dualarm.ik.velocity.gesture import position_bounds, velocity_bounds
from dualarm.ik.velocity.stack import (
    HandStack,
    reference_stack,
    stack_joint_path,
    stacked_reference,
    start_configuration,
)
from dualarm.method import Method
from dualarm.model.robot import Robot
from dualarm.settings import check_positive, with_overrides

if TYPE_CHECKING:
    from dualarm.tasks import Task

Scheme = Literal["mvn", "rmp", "mke"]
SCHEMES: tuple[str, ...] = get_args(Scheme)
#: The QP solvers: a CasADi conic in the step's CasADi Function, or the paper's LVI (eqs 26-27).
Backend = Literal["casadi", "lvi"]
BACKENDS: tuple[str, ...] = get_args(Backend)

#: Largest breach of (24)-(25) [m/s or rad/s] a conic solution may have before its step counts as infeasible.
FEASIBILITY_TOLERANCE = 1e-6

#: The LVI solver's constants as published: omega (the dual bound) and the stop on ||epsilon(u)||.
LVI_OMEGA = 1e10
LVI_TOLERANCE = 1e-5
#: Iterations after which the ``lvi`` backend declares a step infeasible (the ball game needs at most ~10,000).
LVI_MAX_ITERATIONS = 200_000


@dataclass(frozen=True)
class TvgddSettings:
    """Settings of TV-GDD. The Euler step tau is the reference's period (there is no other).

    Attributes:
        scheme: ``mvn``, ``rmp`` or ``mke``.
        backend: ``casadi`` (the conic in one CasADi Function per step) or ``lvi`` (eqs 26-27).
        feedback_gain: K of eq (16) [1/s].
        nu: bound scaling nu of eq (21) [1/s].
        t_sp_s: T_SP of eq (19) [s].
        c_tuning: c_tuning of eq (19) [s].
        rmp_lambda: lambda of the RMP scheme [1/s].
        bound_feedforward: add the bounds' own rate over the coming step to eq (21), so that a
            joint pressed against a closing bound moves with it instead of lagging (a departure
            from the paper, off by default).
        goal_lower, goal_upper: theta_goal-, theta_goal+ of eq (19) per joint [rad]; a joint
            without one keeps its position limit.
        free_waist: solve the joints between the reference's frame and the arms (a waist) too
            (Li-Liang's 17-DOF model); otherwise they hold their ``q0`` values.
        qp_plugin: CasADi conic plugin of the ``casadi`` backend.
        lvi_tolerance: the ``lvi`` backend's stop on ||epsilon(u)||_2 (the paper's 1e-5).
        task_space: ``pose`` (positions and orientations of the hands in eq 24) or ``position``
            (positions only, as in the paper).
    """

    scheme: Scheme = "mvn"
    backend: Backend = "casadi"
    feedback_gain: float = 20.0
    nu: float = 2.0
    t_sp_s: float = 0.75
    c_tuning: float = 1.0
    rmp_lambda: float = 10.0
    bound_feedforward: bool = False
    goal_lower: Mapping[str, float] = field(default_factory=dict)
    goal_upper: Mapping[str, float] = field(default_factory=dict)
    free_waist: bool = False
    qp_plugin: str = "daqp"
    lvi_tolerance: float = LVI_TOLERANCE
    task_space: TaskSpace = "pose"

    def __post_init__(self) -> None:
        check_task_space(self.task_space)
        if self.scheme not in SCHEMES:
            raise InvalidArgumentError(
                "scheme", f"unknown TV-GDD scheme '{self.scheme}' (schemes: {', '.join(SCHEMES)})"
            )
        if self.backend not in BACKENDS:
            raise InvalidArgumentError(
                "backend", f"unknown QP backend '{self.backend}' (backends: {', '.join(BACKENDS)})"
            )
        check_positive(self, "feedback_gain", "nu", "t_sp_s", "c_tuning", "rmp_lambda", "lvi_tolerance")
        for name in ("goal_lower", "goal_upper"):
            object.__setattr__(self, name, dict(getattr(self, name)))  # a copy: the caller's dict may change


@dataclass(frozen=True)
class JointBounds:
    """Per active joint: physical limits and gesture goals.

    Attributes:
        lower, upper: position limits theta-, theta+ [rad], (n,).
        goal_lower, goal_upper: theta_goal-, theta_goal+ [rad] (the limits where no goal), (n,).
        velocity: velocity limits, symmetric, [rad/s], (n,).
    """

    lower: np.ndarray
    upper: np.ndarray
    goal_lower: np.ndarray
    goal_upper: np.ndarray
    velocity: np.ndarray


def _inertia(stack: HandStack, urdf_xml: str, all_joints: tuple[str, ...]) -> cs.SX:
    """Joint-space inertia matrix of the active joints (adam-robotics CRBA), fixed base, as SX."""
    from adam.casadi import KinDynComputations

    kd = KinDynComputations(urdf_xml, list(all_joints))
    index = {n: i for i, n in enumerate(stack.joint_names)}
    s = cs.vertcat(*[stack.theta[index[n]] if n in index else stack.fixed[n] for n in all_joints])
    full = kd.mass_matrix_fun()(cs.SX.eye(4), s)[6:, 6:]
    rows = [all_joints.index(n) for n in stack.joint_names]
    return full[rows, rows]


@dataclass(frozen=True)
class TvgddProblem:
    """The QP (23)-(25) of one control step as CasADi Functions.

    Attributes:
        stack: the stacked hands.
        settings: the settings it was built with.
        period_s: the Euler step tau [s].
        data: Function ``(theta, t, r, rdot, theta0) -> (M, b, J, rhs, zeta_lo, zeta_hi, lower_t, upper_t)``,
            r the stack's target (:attr:`HandStack.target`) and rdot its task velocity (m).
        step: Function ``(theta, t, r, rdot, theta0) -> (thetadot, violation)``: data and the conic
            solve in one graph; ``violation`` is the solution's largest breach of (24) or (25),
            above :data:`FEASIBILITY_TOLERANCE` when the QP is infeasible.
        packed_step: the same with its inputs stacked into one vector (see :meth:`pack`), which
            halves the cost of a call from Python.
    """

    stack: HandStack
    settings: TvgddSettings
    period_s: float
    data: cs.Function
    step: cs.Function
    packed_step: cs.Function

    @staticmethod
    def pack(theta, t, r, rdot, theta0) -> np.ndarray:
        """Stack one step's inputs into the vector :attr:`packed_step` takes."""
        return np.concatenate([theta, [t], r, rdot, theta0])

    def stepper(self):
        """A callable ``inputs (packed, see :meth:`pack`) -> (thetadot (n,), violation)``.

        It evaluates :attr:`packed_step` through a CasADi FunctionBuffer, reading and writing numpy
        arrays in place: it skips the DM conversions of a plain call, which cost three quarters of a step.
        """
        buffer, evaluate = self.packed_step.buffer()
        inputs, thetadot, violation = np.zeros(self.packed_step.size1_in(0)), np.zeros(self.stack.n), np.zeros(1)
        buffer.set_arg(0, inputs.data)
        buffer.set_res(0, thetadot.data)
        buffer.set_res(1, violation.data)

        def step(packed: np.ndarray, _keep=buffer) -> tuple[np.ndarray, float]:
            inputs[:] = packed
            evaluate()
            return thetadot.copy(), float(violation[0])

        return step

    def rollout(self, samples: int) -> cs.Function:
        """The whole Euler integration as one CasADi call (``mapaccum``).

        ``(theta0 (n), U (1 + r + m, N), theta_ref0 (n)) -> (theta (n, N), thetadot (n, N))`` where
        column k of U is [t_k; r_k; rdot_k] (r the stack's reference size) and theta[:, k] is the state
        after step k.
        """
        n, size = self.stack.n, self.stack.reference_size
        theta, u, theta0 = cs.MX.sym("theta", n), cs.MX.sym("u", 1 + size + self.stack.m), cs.MX.sym("theta0", n)
        velocity, _ = self.step(theta, u[0], u[1 : 1 + size], u[1 + size :], theta0)
        one = cs.Function("tvgdd_euler", [theta, u, theta0], [theta + self.period_s * velocity, velocity])
        return one.mapaccum("tvgdd_rollout", samples, [0], [0])


def _bands(theta, t, bounds: JointBounds, settings: TvgddSettings, period_s: float):
    """theta_new-+(t) of eq (19) and zeta_new-+(t) of eqs (21)-(22).

    With the bounds' rate over the step [t, t + tau] (tau = ``period_s``) as feedforward when
    ``settings.bound_feedforward``.
    """

    def at(time):
        return position_bounds(
            time, bounds.lower, bounds.upper, bounds.goal_lower, bounds.goal_upper, settings.t_sp_s, settings.c_tuning
        )

    lower_t, upper_t = at(t)
    rates = (0.0, 0.0)
    if settings.bound_feedforward:
        lower_next, upper_next = at(t + period_s)
        rates = ((lower_next - lower_t) / period_s, (upper_next - upper_t) / period_s)
    zeta_lo, zeta_hi = velocity_bounds(theta, lower_t, upper_t, -bounds.velocity, bounds.velocity, settings.nu, *rates)
    return lower_t, upper_t, zeta_lo, zeta_hi


def build_problem(
    stack: HandStack,
    bounds: JointBounds,
    settings: TvgddSettings,
    period_s: float,
    urdf_xml: str = "",
    all_joints: tuple[str, ...] = (),
) -> TvgddProblem:
    """Formulate the TV-GDD QP for ``stack`` with Euler step ``period_s`` [s].

    ``urdf_xml`` and ``all_joints`` are needed for MKE; the task rows of (24) are the stack's (its
    ``task_space``).
    """
    n, m, size = stack.n, stack.m, stack.reference_size
    theta = stack.theta
    t = cs.SX.sym("t")
    r = stack.target  # positions, then (pose) rotation matrices
    rdot = cs.SX.sym("rdot", m)  # linear, then (pose) angular velocities
    theta0 = cs.SX.sym("theta0", n)
    if settings.scheme == "mke":
        M = _inertia(stack, urdf_xml, all_joints)
    else:
        M = cs.SX.eye(n)
    b = settings.rmp_lambda * (theta - theta0) if settings.scheme == "rmp" else cs.SX.zeros(n)
    J = stack.jacobian
    rhs = (
        rdot + settings.feedback_gain * stack.error
    )  # eq (16)/(24): K (r - f(theta)), and (pose) K log(R_d R^T) under it
    lower_t, upper_t, zeta_lo, zeta_hi = _bands(theta, t, bounds, settings, period_s)
    inputs, names = [theta, t, r, rdot, theta0], ["theta", "t", "r", "rdot", "theta0"]
    data = cs.Function(
        "tvgdd_qp_data",
        inputs,
        [cs.densify(M), b, cs.densify(J), rhs, zeta_lo, zeta_hi, lower_t, upper_t],
        names,
        ["M", "b", "J", "rhs", "zeta_lo", "zeta_hi", "lower_t", "upper_t"],
    )
    try:
        qp = cs.conic(
            "tvgdd_qp",
            settings.qp_plugin,
            {"h": cs.Sparsity.dense(n, n), "a": cs.Sparsity.dense(m, n)},
            _plugin_options(settings.qp_plugin),
        )
    except RuntimeError as exc:
        reason = str(exc).strip().splitlines()[-1]
        raise StageError(f"CasADi conic plugin '{settings.qp_plugin}' cannot take the TV-GDD QP: {reason}") from None
    sym = [cs.MX.sym(name, *x.shape) for name, x in zip(names, inputs, strict=True)]
    M_, b_, J_, rhs_, lo_, hi_, _, _ = data(*sym)
    # collapsed bounds (zeta- > zeta+) would trip CasADi's well-posedness assertion: the QP gets
    # [lo, max(lo, hi)] and the collapse shows up in the violation against the true bounds
    x = qp(h=M_, g=b_, a=J_, lba=rhs_, uba=rhs_, lbx=lo_, ubx=cs.fmax(lo_, hi_))["x"]
    violation = cs.mmax(cs.vertcat(cs.fabs(cs.mtimes(J_, x) - rhs_), lo_ - x, x - hi_))
    step = cs.Function("tvgdd_step", sym, [x, violation], names, ["thetadot", "violation"])
    packed = cs.MX.sym("inputs", 2 * n + 1 + size + m)
    pieces = cs.vertsplit(packed, [0, n, n + 1, n + 1 + size, n + 1 + size + m, 2 * n + 1 + size + m])
    packed_step = cs.Function("tvgdd_packed_step", [packed], step(*pieces), ["inputs"], ["thetadot", "violation"])
    return TvgddProblem(
        stack=stack, settings=settings, period_s=period_s, data=data, step=step, packed_step=packed_step
    )


#: Quiet, tight options per conic plugin.
PLUGIN_OPTIONS: dict[str, dict[str, Any]] = {
    "qpoases": {"printLevel": "none"},
    "osqp": {"osqp": {"verbose": False, "eps_abs": 1e-10, "eps_rel": 1e-10, "max_iter": 100000}},
    "daqp": {"daqp": {"primal_tol": 1e-12, "dual_tol": 1e-12}},
    "highs": {"highs": {"output_flag": False}},
    "proxqp": {"proxqp": {"eps_abs": 1e-10, "eps_rel": 0.0}},
    "qrqp": {"print_iter": False, "print_header": False, "print_info": False},
}


def _plugin_options(plugin: str) -> dict[str, Any]:
    """The plugin's :data:`PLUGIN_OPTIONS`, and no exception on a failed solve.

    A failed solve does not raise (CasADi would print every input of the enclosing Functions first);
    the step's ``violation`` output reports it.
    """
    return {**PLUGIN_OPTIONS.get(plugin, {}), "error_on_fail": False}


def lvi_solve(
    M, b, J, rhs, lo, hi, u0=None, *, omega: float = LVI_OMEGA, tol: float = LVI_TOLERANCE, max_iter: int = 1_000_000
):
    """Solve the QP (23)-(25) by the paper's LVI projection method, eqs (26)-(27).

    u = [thetadot; lambda] solves Phi_Omega(u - (Gamma u + q)) - u = 0 with
    Gamma = [[M, -J^T], [J, 0]], q = [b; -rhs], Omega = [zeta-, zeta+] x [-omega, omega]^m; the
    iteration u <- u - ||eps||^2 sigma / ||sigma||^2, eps = u - Phi(u - (Gamma u + q)),
    sigma = (Gamma^T + I) eps, stops at ||eps||_2 <= tol.

    The arguments may carry a leading batch axis (B instances, each iterated until its own stop):
    M (B, n, n), b (B, n), J (B, m, n), rhs (B, m), lo and hi (B, n), u0 (B, n + m).

    Returns:
        (thetadot, u, iterations), batched like the arguments; raises StageError if ``max_iter``
        is reached.
    """
    single = np.ndim(M) == 2
    M, b, J, rhs, lo, hi = (
        np.asarray(x, dtype=float)[None] if single else np.asarray(x, dtype=float) for x in (M, b, J, rhs, lo, hi)
    )
    B, m, n = J.shape
    Gamma = np.block([[M, -J.transpose(0, 2, 1)], [J, np.zeros((B, m, m))]])
    q = np.concatenate([b, -rhs], axis=1)
    u_lo = np.concatenate([lo, np.full((B, m), -omega)], axis=1)
    u_hi = np.concatenate([hi, np.full((B, m), omega)], axis=1)
    A = Gamma.transpose(0, 2, 1) + np.eye(n + m)
    u = np.zeros((B, n + m)) if u0 is None else np.clip(np.reshape(u0, (B, n + m)), u_lo, u_hi)
    solution, iterations = np.empty_like(u), np.zeros(B, dtype=int)
    active = np.arange(B)  # instances still iterating; the arrays below hold only those
    for k in range(max_iter):
        # eq (26) residual; minimum/maximum rather than np.clip, which costs more on small arrays
        eps = u - np.minimum(np.maximum(u - ((Gamma @ u[..., None])[..., 0] + q), u_lo), u_hi)
        e2 = np.einsum("bi,bi->b", eps, eps)
        if e2.min() <= tol * tol:
            done = e2 <= tol * tol
            solution[active[done]], iterations[active[done]] = u[done], k
            keep = ~done
            if not keep.any():
                thetadot = solution[:, :n]
                return (thetadot[0], solution[0], int(iterations[0])) if single else (thetadot, solution, iterations)
            active, Gamma, A, q, u_lo, u_hi, u, eps, e2 = (
                x[keep] for x in (active, Gamma, A, q, u_lo, u_hi, u, eps, e2)
            )
        sigma = (A @ eps[..., None])[..., 0]
        u = u - (e2 / np.einsum("bi,bi->b", sigma, sigma))[:, None] * sigma  # eq (27)
    raise StageError(f"LVI solver did not reach ||eps|| <= {tol} in {max_iter} iterations")


def joint_bounds(robot: Robot, stack: HandStack, settings: TvgddSettings) -> JointBounds:
    """Physical limits and gesture goals of the stack's joints.

    A joint without a goal keeps its limits as goals.

    Raises:
        InvalidArgumentError: a goal for a joint the stack does not move.
    """
    names = stack.joint_names
    for key in ("goal_lower", "goal_upper"):
        for name in getattr(settings, key):
            if name not in names:
                raise InvalidArgumentError(f"{key}.{name}", f"not a joint TV-GDD moves here ({', '.join(names)})")
    lower, upper = robot.lower_upper(names)
    return JointBounds(
        lower=lower,
        upper=upper,
        goal_lower=np.array([settings.goal_lower.get(n, lo) for n, lo in zip(names, lower, strict=True)]),
        goal_upper=np.array([settings.goal_upper.get(n, hi) for n, hi in zip(names, upper, strict=True)]),
        velocity=robot.limit_array("velocity", names),
    )


def settings_for(task: Task, **overrides: object) -> TvgddSettings:
    """TV-GDD settings from a task's ``[gesture]`` table, ``waist`` and ``[ik] task_space``.

    Defaults where it has none, with ``overrides`` (fields of :class:`TvgddSettings`) on top.
    """
    g = task.spec.gesture
    base = TvgddSettings()
    values: dict[str, object] = {"free_waist": task.spec.waist == "free", "task_space": task.spec.ik.task_space}
    if g is not None:
        values.update(
            feedback_gain=g.feedback_gain,
            nu=g.nu,
            t_sp_s=g.t_sp_s,
            c_tuning=g.c_tuning,
            bound_feedforward=g.bound_feedforward,
            goal_lower=g.goal_lower,
            goal_upper=g.goal_upper,
        )
    return with_overrides(base, {**values, **overrides})


def _infeasible(problem: TvgddProblem, args, k: int, t: float) -> StageError:
    """A StageError naming the step, the time and why the step is infeasible.

    Why: the joints whose bounds collapsed, or else the joints whose bounds hold back the velocity
    nearest to meeting (24).
    """
    _, _, J, rhs, lo, hi, lower_t, upper_t = (np.asarray(x) for x in problem.data(*args))
    lo, hi, lower_t, upper_t, rhs = (x.ravel() for x in (lo, hi, lower_t, upper_t, rhs))
    names = problem.stack.joint_names
    collapsed = [f"{names[i]} [{lo[i]:.4g}, {hi[i]:.4g}] rad/s" for i in np.flatnonzero(lo > hi)]
    if collapsed:
        why = "the velocity bounds of " + ", ".join(collapsed) + " collapsed (zeta- > zeta+)"
    else:
        rows = f"{problem.stack.m} task rows ({problem.stack.task_space}) on {len(names)} joints"
        why = f"no joint velocity within the bounds (25) meets the hand-velocity equality (24) ({rows}); " + _nearest(
            J, rhs, lo, hi, np.asarray(args[0], float), lower_t, upper_t, names
        )
    return StageError(f"TV-GDD step {k} (t = {t:.3f} s) is infeasible: {why}", stage="ik", sample=k, t_s=t)


def _nearest(
    J: np.ndarray,
    rhs: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    theta: np.ndarray,
    lower_t: np.ndarray,
    upper_t: np.ndarray,
    names: tuple[str, ...],
) -> str:
    """What holds back the joint velocity within [lo, hi] nearest to J thetadot = rhs.

    The nearest by bounded least squares, scipy's ``lsq_linear``: its miss and the joints at a bound,
    each with its distance to theta_new-+(t) [rad].
    """
    from scipy.optimize import lsq_linear

    free = lo < hi
    x = lo.copy()  # pinned joints (lo == hi) stay there
    if free.any():
        x[free] = lsq_linear(J[:, free], rhs - J[:, ~free] @ x[~free], bounds=(lo[free], hi[free]), tol=1e-12).x
    held = []
    for i in np.flatnonzero((x <= lo + FEASIBILITY_TOLERANCE) | (x >= hi - FEASIBILITY_TOLERANCE)):
        side, bound, gap = (
            ("zeta-", lo[i], theta[i] - lower_t[i])
            if x[i] <= lo[i] + FEASIBILITY_TOLERANCE
            else ("zeta+", hi[i], upper_t[i] - theta[i])
        )
        where = f"{gap:.3g} rad from theta_new{side[-1]}" if np.isfinite(gap) else "a continuous joint"
        held.append(f"{names[i]} at {side} = {bound:.3g} rad/s ({where})")
    miss = float(np.abs(J @ x - rhs).max())
    sigma = float(
        np.linalg.svd(J, compute_uv=False).min()
    )  # near 0: a singular configuration, where no bound is needed to miss
    return (
        f"the nearest velocity within them misses it by {miss:.3g} m/s or rad/s, "
        f"held by {', '.join(held) if held else 'no bound'} (smallest singular value of J {sigma:.3g})"
    )


def solve_tvgdd(
    robot: Robot,
    reference: CartesianReference,
    q0: Mapping[str, float] | str | None = None,
    settings: TvgddSettings = TvgddSettings(),
) -> JointPath:
    """Run TV-GDD along ``reference``: one QP per sample, Euler integration at the reference's period.

    In ``position`` task space TV-GDD solves for the hands' positions only (the paper's eq 24) and
    their orientation follows; in ``pose`` task space the orientation rows are stacked under them.

    Args:
        robot: the robot (its position and velocity limits bound the joints).
        reference: the hands' reference; its period is the Euler step.
        q0: the initial configuration: a home pose's name or joint -> value [rad] (others at 0);
            moved onto the path start if it is off it.
        settings: scheme, gains, gesture goals, the QP backend.

    Returns:
        A JointPath whose extras hold ``theta_lower``/``theta_upper`` (eq 19) and
        ``zeta_lower``/``zeta_upper`` (eq 22) at every sample.

    Raises:
        StageError: an infeasible step (names the step, the time, and the collapsed joints or those
            whose bounds hold back the velocity nearest to meeting eq 24).
    """
    stack = reference_stack(robot, reference, q0, settings.free_waist, settings.task_space)
    bounds = joint_bounds(robot, stack, settings)
    problem = build_problem(stack, bounds, settings, reference.period_s, robot.urdf.kinematic_xml, robot.joint_names)
    R, V = stacked_reference(stack, reference)
    N, n = len(reference), stack.n
    theta0 = start_configuration(stack, reference, bounds.lower, bounds.upper)
    q, qd = np.empty((N, n)), np.empty((N, n))
    solve_time = np.empty(N)
    theta, u = theta0.copy(), None
    step = problem.stepper()
    for k in range(N):
        q[k] = theta
        args = (theta, float(reference.t[k]), R[k], V[k], theta0)
        start = time.perf_counter()
        if settings.backend == "casadi":
            velocity, violation = step(problem.pack(*args))
        else:
            M, b, J, rhs, lo, hi, _, _ = (np.asarray(x) for x in problem.data(*args))
            try:
                if np.any(lo > hi):  # the projection onto Omega would be undefined
                    raise StageError("collapsed bounds")
                velocity, u, _ = lvi_solve(
                    M,
                    b.ravel(),
                    J,
                    rhs.ravel(),
                    lo.ravel(),
                    hi.ravel(),
                    u0=u,
                    tol=settings.lvi_tolerance,
                    max_iter=LVI_MAX_ITERATIONS,
                )
                violation = 0.0
            except StageError:  # an infeasible QP has no LVI solution: the iteration runs out
                violation = np.inf
        solve_time[k] = time.perf_counter() - start
        if violation > FEASIBILITY_TOLERANCE:
            raise _infeasible(problem, args, k, float(reference.t[k]))
        qd[k] = velocity
        theta = theta + reference.period_s * velocity  # Euler
    return stack_joint_path(
        "tvgdd", stack, reference, q, qd, solve_time, gesture_band(bounds, settings, reference.period_s, reference.t, q)
    )


def gesture_band(
    bounds: JointBounds, settings: TvgddSettings, period_s: float, t: np.ndarray, q: np.ndarray
) -> dict[str, np.ndarray]:
    """theta_new+-(t) of eq (19) and zeta_new+-(t) of eq (22) along a joint path.

    t (N,) [s], q (N, n) [rad] -> ``theta_lower``, ``theta_upper`` [rad], ``zeta_lower``,
    ``zeta_upper`` [rad/s], each (N, n).
    """
    lower_t, upper_t, zeta_lo, zeta_hi = _bands(q, t[:, None], bounds, settings, period_s)
    return {"theta_lower": lower_t, "theta_upper": upper_t, "zeta_lower": zeta_lo, "zeta_upper": zeta_hi}


def _options(settings: TvgddSettings, options: Mapping[str, Any]) -> TvgddSettings:
    """The run command's ``--scheme``, ``--qp-backend`` and ``--lvi-tolerance`` on TV-GDD's settings."""
    chosen = {"scheme": "scheme", "qp_backend": "backend", "lvi_tolerance": "lvi_tolerance"}
    return with_overrides(settings, {field: options[option] for option, field in chosen.items() if option in options})


#: TV-GDD in the registry (:data:`dualarm.methods.METHODS`).
METHODS: Mapping[str, Method[TvgddSettings]] = {
    "tvgdd": Method(
        "tvgdd",
        "ik",
        "TV-GDD: velocity-level QP with time-varying gesture bounds (Zhang, Kong, Niu, eqs 15-27)",
        solve_tvgdd,
        TvgddSettings,
        settings_for,
        orientation=False,
        options=_options,
    )
}
