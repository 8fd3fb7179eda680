"""The retime stage (TOPP-RA): limits, passing the IK samples, rest to rest, time-optimality, holds,
bad limits and keep_timing. Facts are computed from the output samples, independently of the stage."""

import numpy as np
import pytest
import toppra
import toppra.algorithm
import toppra.constraint

from dualarm.contracts.joint_path import JointPath
from dualarm.contracts.trajectory import JointTrajectory
from dualarm.errors import InvalidArgumentError, StageError
from dualarm.limits import LimitRatio, limit_ratios
from dualarm.retime import topp
from dualarm.retime.stage import plan, retime_path
from dualarm.retime.timing import path_deviation_max_rad
from dualarm.retime.topp import chord_parameter, gridpoints

DT = 1e-3
ARM = tuple(f"left_j{i}" for i in range(1, 8))
ARMS = ARM + tuple(f"right_j{i}" for i in range(1, 8))
V7 = np.array([1.0, 0.9, 1.2, 1.1, 1.5, 0.8, 1.3])  # rad/s
A7 = np.array([3.0, 2.5, 3.5, 4.0, 2.0, 3.0, 5.0])  # rad/s^2


def joint_path(q: np.ndarray, t: np.ndarray, names: tuple[str, ...], rep: np.ndarray | None = None) -> JointPath:
    N, n = q.shape
    return JointPath(
        method="test",
        joint_names=names,
        t=t,
        rep=np.zeros(N, int) if rep is None else rep,
        q=q,
        qd=np.zeros((N, n)),
        status=np.zeros(N, int),
        solve_time_s=np.zeros(N),
        hand_error_m=np.zeros((N, 1)),
        hands=("left",),
        fixed={"head": 0.25},
    )


def rest_to_rest(t: np.ndarray, n: int, amplitude: float) -> np.ndarray:
    """Each joint moves by a different amount along 1 - cos, at rest at both ends [rad]."""
    phase = (1 - np.cos(np.pi * (t - t[0]) / (t[-1] - t[0]))) / 2
    return np.outer(phase, amplitude * np.linspace(-1.0, 1.0, n)) + np.linspace(0.0, 0.6, n)


def sinusoids(t: np.ndarray, n: int, amplitude: float = 0.5, period_s: float = 10.0) -> np.ndarray:
    """Smooth joint motions with a different frequency and phase per joint [rad]."""
    return np.stack([amplitude * np.sin(2 * np.pi * t / period_s * (1 + 0.3 * j) + j) for j in range(n)], axis=1)


@pytest.fixture(scope="module")
def arm():
    t = np.linspace(0.0, 10.0, 300)
    path = joint_path(sinusoids(t, 7), t, ARM, rep=(t // 3.4).astype(int))
    timing = plan(path, V7, A7)
    return path, timing, timing.sample(DT)


def sample_ratios(traj: JointTrajectory, v: np.ndarray, a: np.ndarray) -> dict[str, LimitRatio]:
    """The largest |qd| / v and |qdd| / a over the samples (the shared limit ratios)."""
    return limit_ratios(
        traj.t,
        traj.joint_names,
        {"velocity": traj.qd, "acceleration": traj.qdd},
        {"velocity": v, "acceleration": a},
        "retime",
    )


def central_difference(x: np.ndarray, t: np.ndarray) -> np.ndarray:
    """d/dt of the samples by second-order (central) differences, one-sided at the ends."""
    return np.gradient(x, t, axis=0, edge_order=2)


def test_limits_hold_on_the_samples(arm):
    path, timing, traj = arm
    assert np.abs(traj.qd / V7).max() <= 1 + 1e-6
    assert np.abs(traj.qdd / A7).max() <= 1 + 1e-6
    ratios = sample_ratios(traj, V7, A7)
    assert ratios["velocity"].ratio <= 1 + 1e-6 and ratios["acceleration"].ratio <= 1 + 1e-6
    assert 1.0 <= timing.stretch <= 1.001  # the between-gridpoint excess TOPP-RA leaves is small


def test_samples_are_consistent_by_finite_differences(arm):
    """The returned qd is the derivative of q, and qdd that of qd, by central differences.

    The path acceleration is piecewise constant (ParametrizeConstAccel), so qdd jumps at the
    gridpoints: a central difference of q straddling a jump is off by up to dt |jump| / 8 in
    velocity, and differences of qd are only close away from the jumps (checked by the median)."""
    _, _, traj = arm
    fd_qd = central_difference(traj.q, traj.t)
    assert np.abs(fd_qd - traj.qd)[1:-1].max() <= DT * 2 * A7.max() / 8 * 1.01
    assert np.median(np.abs(fd_qd - traj.qd)) <= 1e-6
    assert (np.abs(fd_qd) / V7).max() <= 1 + 1e-3
    fd_qdd = central_difference(traj.qd, traj.t)
    assert np.median(np.abs(fd_qdd - traj.qdd) / A7) <= 1e-3


def test_time_optimal(arm):
    """Some joint is at its velocity or acceleration limit at (nearly) every instant."""
    _, _, traj = arm
    saturation = np.maximum(np.abs(traj.qd) / V7, np.abs(traj.qdd) / A7).max(axis=1)
    assert saturation.max() >= 0.99
    assert np.mean(saturation >= 0.99) >= 0.9


def test_rest_to_rest_between_the_path_ends(arm):
    path, _, traj = arm
    assert np.abs(traj.qd[[0, -1]]).max() <= 1e-9
    assert np.abs(traj.q[0] - path.q[0]).max() <= 1e-12 and np.abs(traj.q[-1] - path.q[-1]).max() <= 1e-12
    assert traj.stage == "retime" and traj.joint_names == ARM and dict(traj.fixed) == {"head": 0.25}


def test_passes_the_ik_samples(arm):
    """At its sample times the trajectory is at the IK samples; the samples of the 1 ms output
    extrapolated to those times by a second-order Taylor step (|dt| <= 0.5 ms) agree too."""
    path, timing, traj = arm
    assert path_deviation_max_rad(timing, path) <= 1e-6
    assert timing.sample_times_s[0] == 0 and timing.sample_times_s[-1] == pytest.approx(traj.duration_s, abs=1e-12)
    assert (np.diff(timing.sample_times_s) > 0).all()
    j = np.abs(traj.t[None, :] - timing.sample_times_s[:, None]).argmin(axis=1)
    h = (timing.sample_times_s - traj.t[j])[:, None]
    taylor = traj.q[j] + traj.qd[j] * h + 0.5 * traj.qdd[j] * h**2
    assert np.abs(taylor - path.q).max() <= 2e-6


def test_matches_toppra_own_trajectory(arm):
    """The vectorised s(t) reproduces toppra's ParametrizeConstAccel output (slowed by the stretch)."""
    path, timing, traj = arm
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path.q, axis=0), axis=1))])
    spline = toppra.SplineInterpolator(s, path.q)
    constraints = [
        toppra.constraint.JointVelocityConstraint(np.vstack([-V7, V7]).T),
        toppra.constraint.JointAccelerationConstraint(np.vstack([-A7, A7]).T),
    ]
    grid = timing.evaluate.s_grid  # the stage's gridpoints (the initial ones: this path needs no refinement)
    assert np.array_equal(grid, gridpoints(s)[0])
    reference = toppra.algorithm.TOPPRA(
        constraints, spline, gridpoints=grid, parametrizer="ParametrizeConstAccel"
    ).compute_trajectory(0, 0)
    k = timing.stretch
    assert traj.duration_s == pytest.approx(k * reference.duration, rel=1e-12)
    some = np.arange(0, len(traj), 37)
    assert np.abs(reference.eval(traj.t[some] / k) - traj.q[some]).max() <= 1e-9
    assert np.abs(reference.evald(traj.t[some] / k) / k - traj.qd[some]).max() <= 1e-9


def test_sampling_and_repetitions(arm):
    path, timing, traj = arm
    steps = np.diff(traj.t)
    assert np.allclose(steps[:-1], DT, atol=1e-12) and 0.5 * DT <= steps[-1] < 1.5 * DT
    assert traj.rep[0] == path.rep[0] and traj.rep[-1] == path.rep[-1]
    assert (np.diff(traj.rep) >= 0).all() and set(traj.rep) == set(path.rep)
    for r in np.unique(path.rep)[1:]:  # a repetition starts when the trajectory passes its first sample
        start = timing.sample_times_s[np.argmax(path.rep == r)]
        assert traj.t[np.argmax(traj.rep == r)] == pytest.approx(start, abs=DT)


def test_two_arms_with_holds_are_one_synchronised_path():
    """14 joints: the right arm holds still for a while, and the IK repeats samples (holds)."""
    t = np.linspace(0.0, 8.0, 400)
    left = sinusoids(t, 7, 0.4, 8.0)
    right = sinusoids(np.clip(t, 3.0, None), 7, 0.6, 8.0)
    q = np.hstack([left, right])
    q = np.concatenate([q[:100], np.repeat(q[100:101], 20, axis=0), q[100:]])  # both arms hold (a repeated sample)
    t = (t[1] - t[0]) * np.arange(len(q))
    v, a = np.tile(V7, 2), np.tile(A7, 2)
    path = joint_path(q, t, ARMS)
    timing = plan(path, v, a)
    traj = timing.sample(DT)
    ratios = sample_ratios(traj, v, a)
    assert ratios["velocity"].ratio <= 1 + 1e-6 and ratios["acceleration"].ratio <= 1 + 1e-6
    assert max(ratios["velocity"].ratio, ratios["acceleration"].ratio) >= 0.99
    assert path_deviation_max_rad(timing, path) <= 1e-6
    assert np.abs(traj.qd[[0, -1]]).max() <= 1e-9
    assert np.ptp(timing.sample_times_s[100:121]) == 0  # the hold takes no time


def test_a_short_motion_keeps_its_ends():
    """A motion shorter than half a sample period still gives t = [0, duration], at rest at both ends."""
    q = np.array([[0.0] * 7, [1e-7] * 7])
    traj = retime_path(joint_path(q, np.array([0.0, 1.0]), ARM), V7, A7, sample_period_s=DT).trajectory
    assert len(traj) == 2 and traj.t[0] == 0 and 0 < traj.t[1] < 0.5 * DT
    assert np.abs(traj.q - q).max() <= 1e-15 and np.abs(traj.qd).max() <= 1e-12


def reversal() -> JointPath:
    """All joints go out and back twice in phase: the joint-space path reverses (a cusp)."""
    t = np.linspace(0.0, 10.0, 300)
    return joint_path(np.outer(np.sin(2 * np.pi * t / 5), np.linspace(0.2, 0.8, 7)), t, ARM)


def test_a_reversal_is_refined_not_slowed_down():
    """At a reversal q''(s) is large and TOPP-RA alone exceeds the limits between gridpoints (its
    result would need a 26 % slow-down here); splitting those stages keeps it within 0.1 %."""
    path = reversal()
    timing = plan(path, V7, A7)
    traj = timing.sample(DT)
    ratios = sample_ratios(traj, V7, A7)
    assert ratios["velocity"].ratio <= 1 + 1e-6 and ratios["acceleration"].ratio <= 1 + 1e-6
    assert max(ratios["velocity"].ratio, ratios["acceleration"].ratio) >= 0.99
    assert 1.0 <= timing.stretch <= 1.001
    assert path_deviation_max_rad(timing, path) <= 1e-6
    assert np.abs(traj.qd[[0, -1]]).max() <= 1e-9


def test_the_samples_are_checked_last(monkeypatch):
    """With the refinement and the between-gridpoint check disabled, the final check on the
    samples still slows the trajectory down until every sample is within the limits."""
    monkeypatch.setattr(topp, "MAX_REFINEMENTS", 1)
    monkeypatch.setattr(topp, "CHECK_POINTS_PER_STAGE", 1)
    path = reversal()
    assert (np.abs(plan(path, V7, A7).sample(DT).qdd) / A7).max() > 1.01
    traj = retime_path(path, V7, A7, sample_period_s=DT).trajectory
    ratios = sample_ratios(traj, V7, A7)
    assert ratios["velocity"].ratio <= 1 + 1e-9 and ratios["acceleration"].ratio <= 1 + 1e-9


def test_repeated_samples_give_the_same_trajectory(arm):
    path, _, traj = arm
    index = np.sort(np.concatenate([np.arange(len(path)), [0, 0, 50, 50, 50, 120, 299, 299]]))
    held = joint_path(path.q[index], np.linspace(0.0, 10.0, len(index)), ARM)
    assert len(chord_parameter(held.q)[1]) == len(path)
    again = retime_path(held, V7, A7, sample_period_s=DT).trajectory
    assert len(again) == len(traj)
    for name in ("t", "q", "qd", "qdd"):
        assert np.abs(getattr(again, name) - getattr(traj, name)).max() <= 1e-12


@pytest.mark.parametrize("N", [1, 5])
def test_a_path_that_does_not_move_gives_one_sample_at_rest(N):
    q = np.tile(np.linspace(-0.5, 0.5, 7), (N, 1))
    path = joint_path(q, np.arange(N, dtype=float), ARM, rep=np.arange(N))
    traj = retime_path(path, V7, A7).trajectory
    assert len(traj) == 1 and traj.t[0] == 0 and traj.rep[0] == N - 1
    assert np.array_equal(traj.q[0], q[0]) and not traj.qd.any() and not traj.qdd.any()


@pytest.mark.parametrize("kind", ["velocity", "acceleration"])
@pytest.mark.parametrize("bad", [0.0, -1.0, np.nan, np.inf])
def test_a_bad_limit_is_named(arm, kind, bad):
    path = arm[0]
    limits = {"velocity": V7.copy(), "acceleration": A7.copy()}
    limits[kind][3] = bad
    with pytest.raises(
        InvalidArgumentError,
        match=(
            rf"^{kind}: the limit of joint 3 \(left_j4\) is [-\w.]+ rad/s(\^2)? in retime;"
            r" every limit must be a positive finite number$"
        ),
    ):
        retime_path(path, limits["velocity"], limits["acceleration"])


def test_limits_of_the_wrong_size_are_refused(arm):
    with pytest.raises(InvalidArgumentError, match=r"^velocity: retime expected 7 limits"):
        retime_path(arm[0], V7[:6], A7)


def test_a_non_finite_joint_is_named(arm):
    path = arm[0]
    q = path.q.copy()
    q[17, 2] = np.nan
    with pytest.raises(StageError, match=r"left_j3 is nan at sample 17"):
        retime_path(joint_path(q, path.t, ARM), V7, A7)


def test_no_feasible_parameterisation_raises_not_none(arm, monkeypatch):
    monkeypatch.setattr(toppra.algorithm.TOPPRA, "compute_trajectory", lambda self, *args: None)
    with pytest.raises(
        StageError, match=r"^retime: TOPP-RA found no feasible time parameterisation .*joint limits: velocity \[1, 0\.9"
    ):
        retime_path(arm[0], V7, A7)


def test_keep_timing_a_slow_path_keeps_its_timing():
    t = np.linspace(5.0, 25.0, 201)  # the path's clock need not start at 0
    path = joint_path(rest_to_rest(t, 7, 2.0), t, ARM)
    timing = plan(path, V7, A7, keep_timing=True)
    traj = retime_path(path, V7, A7, keep_timing=True).trajectory
    assert traj.duration_s == pytest.approx(20.0, abs=1e-12)
    assert np.allclose(timing.sample_times_s, t - 5.0, rtol=0, atol=1e-12)
    assert path_deviation_max_rad(timing, path) <= 1e-12
    assert np.abs(traj.q[::100] - path.q).max() <= 1e-12  # samples every 0.1 s fall on the IK samples
    assert np.abs(traj.qd[[0, -1]]).max() <= 1e-12
    ratios = sample_ratios(traj, V7, A7)
    assert ratios["velocity"].ratio < 0.5 and ratios["acceleration"].ratio < 0.5
    fd_qd = central_difference(traj.q, traj.t)
    assert np.abs(fd_qd - traj.qd).max() <= 1e-5


def test_keep_timing_a_too_fast_path_names_joint_time_and_ratio():
    t = np.linspace(0.0, 2.0, 101)
    q = rest_to_rest(t, 7, 0.1)
    q[:, 4] = 1.6 * (
        1 - np.cos(np.pi * t / 2)
    )  # left_j5: 2.51 rad/s at t = 1 s (limit 1.5), 3.95 rad/s^2 at t = 0 (limit 2)
    path = joint_path(q, t, ARM)
    with pytest.raises(
        StageError, match=r"^retime: keep_timing: left_j5 reaches 1\.\d+x its velocity limit at t = 1\.0\d\d s"
    ) as error:
        retime_path(path, V7, 100 * A7, keep_timing=True)
    assert "\n" not in str(error.value)
    assert error.value.stage == "retime" and error.value.joint == "left_j5"
    with pytest.raises(
        StageError, match=r"keep_timing: left_j5 reaches 1\.9\dx its acceleration limit at t = [02]\.000 s"
    ):
        retime_path(path, 100 * V7, A7, keep_timing=True)


def test_keep_timing_needs_increasing_times():
    t = np.linspace(0.0, 2.0, 21)
    t[7] = t[6]
    with pytest.raises(
        StageError,
        match=r"keep_timing needs increasing sample times, but sample 7 \(t = 0\.6 s\) does not come after sample 6",
    ):
        retime_path(joint_path(rest_to_rest(t, 7, 0.1), t, ARM), V7, A7, keep_timing=True)
