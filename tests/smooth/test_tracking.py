"""The smooth stage: jerk-limited online tracking of a retimed trajectory.

The references are built here from closed forms (a quintic rest-to-rest move, jerk-feasible and
slow, and a trapezoidal-velocity move, whose acceleration jumps), and every fact is recomputed
from the output samples, independently of the stage's own bookkeeping.
"""

import math

import numpy as np
import pytest

from dualarm.contracts.trajectory import JointTrajectory
from dualarm.errors import InvalidArgumentError, StageError
from dualarm.limits import limit_ratios
from dualarm.smooth import Smoothed, smooth_trajectory

V, A, J = 1.0, 3.0, 30.0  # [rad/s], [rad/s^2], [rad/s^3]
DT = 0.001  # [s]
NAMES = tuple(f"arm_j{i}" for i in range(1, 8))
DISTANCES = np.array([1.0, -0.8, 0.5, 1.2, -1.5, 0.3, 0.9])  # [rad]
START = np.array([0.1, -0.2, 0.3, 0.0, 0.5, -0.4, 0.2])  # [rad]
DURATION = 4.0  # [s]
FIXED = {"head_pan": 0.25}


def quintic(d: float, T: float, t: np.ndarray):
    """Rest-to-rest quintic over d [rad] in T [s]: q, qd, qdd at t."""
    s = np.clip(t / T, 0.0, 1.0)
    return (
        d * (10 * s**3 - 15 * s**4 + 6 * s**5),
        d * (30 * s**2 - 60 * s**3 + 30 * s**4) / T,
        d * (60 * s - 180 * s**2 + 120 * s**3) / T**2,
    )


def trapezoid(d: float, v: float, a: float, t: np.ndarray):
    """Rest-to-rest trapezoidal velocity over d [rad] at v, a: q, qd, qdd at t (qdd jumps)."""
    sign, d = np.sign(d), abs(d)
    ta = v / a
    if d < v * ta:
        ta = math.sqrt(d / a)
        v = a * ta
    tc = d / v - ta
    T = 2 * ta + tc
    rest = np.clip(T - t, 0.0, None)
    q = np.where(t < ta, a * t**2 / 2, np.where(t < ta + tc, a * ta**2 / 2 + v * (t - ta), d - a * rest**2 / 2))
    qd = np.where(t < ta, a * t, np.where(t < ta + tc, v, a * rest))
    qdd = np.where(t < ta, a, np.where(t < ta + tc, 0.0, np.where(t < T, -a, 0.0)))
    return sign * q, sign * qd, sign * qdd


def reference(profile, dt: float = DT, duration: float = DURATION) -> JointTrajectory:
    t = np.arange(round(duration / dt) + 1) * dt
    q, qd, qdd = (np.column_stack(c) for c in zip(*(profile(d, t) for d in DISTANCES), strict=True))
    return JointTrajectory("retime", NAMES, t, START + q, qd, qdd, rep=(t >= duration / 2).astype(int), fixed=FIXED)


def slow_profile(d, t):
    return quintic(d, 3.5, t)  # peaks: 0.80 rad/s, 0.71 rad/s^2, 2.1 rad/s^3 for d = 1.5 rad


def fast_profile(d, t):
    return trapezoid(2 * d, V, A, t)  # up to 3 rad at 1 rad/s, accelerations jumping by 3 rad/s^2


@pytest.fixture(scope="module")
def slow():
    ref = reference(slow_profile)
    return ref, smooth_trajectory(ref, V, A, J, period_s=DT)


@pytest.fixture(scope="module")
def fast():
    ref = reference(fast_profile)
    return ref, smooth_trajectory(ref, V, A, J, period_s=DT)


def reference_at(ref: JointTrajectory, t: np.ndarray) -> np.ndarray:
    """The reference positions at t, linearly interpolated, held at the last one after the end."""
    return np.column_stack([np.interp(t, ref.t, ref.q[:, i]) for i in range(ref.q.shape[1])])


def fd_ratios(traj: JointTrajectory, dt: float, v, a, j) -> tuple[float, float, float]:
    """Mean velocity, acceleration and jerk over each period, by finite differences, over the limits."""
    return (
        float((np.abs(np.diff(traj.q, axis=0)) / dt / v).max()),
        float((np.abs(np.diff(traj.qd, axis=0)) / dt / a).max()),
        float((np.abs(np.diff(traj.qdd, axis=0)) / dt / j).max()),
    )


def ratios(out: Smoothed, v, a, j) -> dict[str, float]:
    """The largest |velocity|, |acceleration| and |jerk| over their limits, by the shared limit ratios."""
    traj = out.trajectory
    samples = {"velocity": traj.qd, "acceleration": traj.qdd, "jerk": out.jerk}
    return {
        kind: r.ratio
        for kind, r in limit_ratios(
            traj.t, traj.joint_names, samples, {"velocity": v, "acceleration": a, "jerk": j}, "smooth"
        ).items()
    }


def test_the_references_are_as_intended():
    """Both within v and a; the slow one within j, the fast one far beyond it."""
    for profile, jerky in ((slow_profile, False), (fast_profile, True)):
        ref = reference(profile)
        assert np.abs(ref.qd).max() <= V + 1e-12 and np.abs(ref.qdd).max() <= A + 1e-12
        jerk = np.abs(np.diff(ref.qdd, axis=0)).max() / DT
        assert (jerk > 10 * J) if jerky else (jerk < J / 10)


@pytest.mark.parametrize("case", ["slow", "fast"])
def test_limits_never_exceeded(case, request):
    ref, out = request.getfixturevalue(case)
    traj = out.trajectory
    velocity, acceleration, jerk = fd_ratios(traj, DT, V, A, J)
    assert velocity <= 1 + 1e-6 and acceleration <= 1 + 1e-6 and jerk <= 1 + 1e-6
    assert np.abs(traj.qd).max() <= V * (1 + 1e-9) and np.abs(traj.qdd).max() <= A * (1 + 1e-9)
    if case == "fast":  # the limits are used, not just respected
        assert min(velocity, acceleration, jerk) > 0.99


@pytest.mark.parametrize("case", ["slow", "fast"])
def test_samples_are_of_one_jerk_limited_motion(case, request):
    """Taylor with |jerk| <= J on each period: the samples chain into one continuous motion."""
    _, out = request.getfixturevalue(case)
    q, qd, qdd = out.trajectory.q, out.trajectory.qd, out.trajectory.qdd
    dq = q[1:] - q[:-1] - qd[:-1] * DT - qdd[:-1] * DT**2 / 2
    dqd = qd[1:] - qd[:-1] - qdd[:-1] * DT
    assert np.abs(dq).max() <= J * DT**3 / 6 * (1 + 1e-6) + 1e-14
    assert np.abs(dqd).max() <= J * DT**2 / 2 * (1 + 1e-6) + 1e-14


@pytest.mark.parametrize("case", ["slow", "fast"])
def test_reported_jerk_and_ratios(case, request):
    _, out = request.getfixturevalue(case)
    traj = out.trajectory
    assert out.jerk.shape == traj.q.shape and not out.jerk[0].any()
    np.testing.assert_allclose(out.jerk[1:], np.diff(traj.qdd, axis=0) / DT, rtol=0, atol=1e-9)
    assert ratios(out, V, A, J) == pytest.approx(
        {
            "velocity": np.abs(traj.qd).max() / V,
            "acceleration": np.abs(traj.qdd).max() / A,
            "jerk": np.abs(np.diff(traj.qdd, axis=0)).max() / DT / J,
        },
        rel=1e-9,
    )


@pytest.mark.parametrize("case", ["slow", "fast"])
def test_rest_to_rest(case, request):
    ref, out = request.getfixturevalue(case)
    traj = out.trajectory
    assert traj.stage == "smooth" and traj.joint_names == NAMES and dict(traj.fixed) == FIXED
    np.testing.assert_allclose(np.diff(traj.t), DT, rtol=0, atol=1e-12)
    assert traj.t[0] == 0 and traj.duration_s >= ref.duration_s
    np.testing.assert_array_equal(traj.q[0], ref.q[0])
    assert not traj.qd[0].any() and not traj.qdd[0].any()
    assert np.abs(traj.qd[-1]).max() <= 1e-9 and np.abs(traj.qdd[-1]).max() <= 1e-9
    assert np.abs(traj.q[-1] - ref.q[-1]).max() <= 1e-6


@pytest.mark.parametrize("case", ["slow", "fast"])
def test_deviation_and_rep_recomputed(case, request):
    ref, out = request.getfixturevalue(case)
    traj = out.trajectory
    expected = np.abs(traj.q - reference_at(ref, traj.t))
    np.testing.assert_allclose(out.deviation_rad, expected, rtol=0, atol=1e-12)
    assert out.path_deviation_max_rad == pytest.approx(expected.max(), abs=1e-12)
    last = [int(np.flatnonzero(ref.t <= t + 1e-12)[-1]) for t in traj.t]
    np.testing.assert_array_equal(traj.rep, ref.rep[last])


def test_a_feasible_reference_is_reproduced(slow):
    """Jerk-feasible and slow: the output passes through the reference's samples."""
    ref, out = slow
    assert out.path_deviation_max_rad < 1e-9  # measured 4e-16
    assert not out.lookahead_s.any() and out.fallbacks == 0
    assert len(out.trajectory) == len(ref) and out.trajectory.duration_s == pytest.approx(ref.duration_s)


def test_a_jerky_reference_is_followed_with_a_bounded_lag(fast):
    """Accelerations jumping by 3 rad/s^2 cannot be followed at 30 rad/s^3.

    Lower bound: from rest, by t = 0.1 s the reference has moved a t^2 / 2 = 15 mrad and a
    motion with |jerk| <= J at most J t^3 / 6 = 5 mrad. Upper bound: an S-curve lags a
    trapezoid by a / (2 J) = 50 ms, i.e. 50 mrad at 1 rad/s; 20 % margin.
    """
    ref, out = fast
    k = round(0.1 / DT)
    assert out.deviation_rad[k].max() >= A * 0.1**2 / 2 - J * 0.1**3 / 6 - 1e-12
    assert 0.01 < out.path_deviation_max_rad <= 0.06  # measured 0.0507
    assert out.lookahead_s.max() > 0
    assert out.trajectory.duration_s < ref.duration_s + 0.5


def test_per_joint_limits_and_coarse_reference():
    """A reference sampled every 10 ms, a 2 ms period, and one limit per joint."""
    ref = reference(slow_profile, dt=0.01)
    v = np.array([1.0, 0.5, 1.0, 0.6, 0.7, 1.0, 1.0])
    a = np.array([3.0, 1.0, 3.0, 2.0, 3.0, 0.5, 3.0])
    j = np.array([30.0, 5.0, 30.0, 1.0, 30.0, 2.0, 30.0])
    out = smooth_trajectory(ref, v, a, j, period_s=0.002)
    traj = out.trajectory
    assert max(fd_ratios(traj, 0.002, v, a, j)) <= 1 + 1e-6
    worst = ratios(out, v, a, j)
    assert max(worst.values()) <= 1 + 1e-6
    assert worst["velocity"] > 0.99  # joint 5 is slowed to its 0.7 rad/s
    np.testing.assert_allclose(np.diff(traj.t), 0.002, rtol=0, atol=1e-12)
    assert np.abs(traj.q[-1] - ref.q[-1]).max() <= 1e-6 and np.abs(traj.qd[-1]).max() <= 1e-9
    np.testing.assert_allclose(out.deviation_rad, np.abs(traj.q - reference_at(ref, traj.t)), rtol=0, atol=1e-12)
    free = [0, 2, 6]  # joints whose limits the reference respects: followed closely
    assert out.deviation_rad[:, free].max() < 1e-3


def test_a_single_sample_reference_rests():
    ref = JointTrajectory("retime", NAMES, [0.0], [START], [np.zeros(7)], [np.zeros(7)], rep=[3])
    out = smooth_trajectory(ref, V, A, J)
    assert isinstance(out, Smoothed)
    np.testing.assert_array_equal(out.trajectory.q[-1], START)
    assert not out.trajectory.qd.any() and (out.trajectory.rep == 3).all() and out.path_deviation_max_rad == 0


@pytest.mark.parametrize("kind", ["velocity", "acceleration", "jerk"])
@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, math.inf])
def test_bad_limits_name_the_joint(kind, bad):
    ref = reference(slow_profile, dt=0.1, duration=1.0)
    limits = {"velocity": np.full(7, V), "acceleration": np.full(7, A), "jerk": np.full(7, J)}
    limits[kind][3] = bad
    with pytest.raises(InvalidArgumentError) as err:
        smooth_trajectory(ref, limits["velocity"], limits["acceleration"], limits["jerk"])
    message = str(err.value)
    assert "\n" not in message and "(arm_j4)" in message and kind in message and err.value.joint == "arm_j4"
    scalar = {"velocity": V, "acceleration": A, "jerk": J, kind: bad}
    with pytest.raises(
        InvalidArgumentError,
        match=(
            rf"^{kind}: the limit of joint 0 \(arm_j1\) is \S+ rad/s(\^[23])? in smooth;"
            r" every limit must be a positive finite number$"
        ),
    ):
        smooth_trajectory(ref, scalar["velocity"], scalar["acceleration"], scalar["jerk"])


@pytest.mark.parametrize("period", [0.0, -0.001, math.nan])
def test_bad_period(period):
    with pytest.raises(StageError, match="period"):
        smooth_trajectory(reference(slow_profile, dt=0.1, duration=1.0), V, A, J, period_s=period)


def test_wrong_number_of_limits():
    with pytest.raises(
        InvalidArgumentError,
        match=r"^velocity: smooth expected 7 limits \(one per joint: arm_j1, .*, arm_j7\), got \(2,\)$",
    ):
        smooth_trajectory(reference(slow_profile, dt=0.1, duration=1.0), [V, V], A, J)


def _segfault() -> None:
    """Read address 0 through ctypes: a genuine crash in C code (signal 11)."""
    import ctypes

    ctypes.string_at(0)


@pytest.mark.integration  # a process of its own
def test_a_crash_in_c_code_in_an_isolated_case_is_an_error_naming_the_signal():
    from dualarm.isolation import CrashedError, isolated

    with pytest.raises(CrashedError, match=r"signal 11 \(SIGSEGV\)"):
        isolated(_segfault)


@pytest.mark.integration  # the ik stage's PyBullet world, and a process of its own
def test_the_triangle_tracked_at_full_limits_where_the_bench_died_of_signal_11_exits_normally():
    """`dualarm bench trajectory` died without a message (signal 11 in Ruckig's calculate, ruckig 0.19.4) at
    "triangle: TOPP-RA 1.0/1.0 + tracking" on another machine (issue 36). That exact case, in a process of its own as
    the bench runs it: it returns, and its motion holds every limit by finite differences of its positions."""
    from dualarm.bench.trajectory import tracked_row
    from dualarm.isolation import isolated
    from dualarm.retime.stage import plan
    from dualarm.run import run_task
    from dualarm.tasks import load_task
    from tests.helpers import TASKS

    task = load_task(TASKS / "triangle.toml")
    path = run_task(task, "mc-inverse", stages=("path", "ik")).joint_path
    names = path.joint_names
    optimal = plan(path, *(task.robot.limit_array(k, names) for k in ("velocity", "acceleration"))).duration_s
    fields = (names, path.t, path.q, path.rep, dict(path.fixed))
    row = isolated(tracked_row, str(TASKS / "triangle.toml"), fields, "TOPP-RA 1.0/1.0 + tracking", (1.0, 1.0), optimal)
    assert row.failure is None and row.duration_s >= optimal
    assert max(row.ratios) <= 1 + 1e-6
