"""The jerk-limited timing (`[retime] timing = "jerk-limited"`, dualarm.retime.jerk): within every velocity, acceleration and
jerk limit, on the path, rest to rest, repetitions identical, near TOPP-RA's time. Facts are computed from the timing's
samples by finite differences, from the analytic curve the path samples, and from toppra, independently of the method."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from dualarm.errors import InvalidArgumentError
from dualarm.retime.retiming import plan, retime_path
from dualarm.retime.timing import path_deviation_max_rad
from dualarm.run import run_task
from dualarm.tasks.schema import Retime
from tests.conftest import TASKS
from tests.retime.test_topp import ARMS, joint_path

V = np.tile([1.0, 0.9, 1.2, 1.1, 1.5, 0.8, 1.3], 2)  # rad/s
A = np.tile([3.0, 2.5, 3.5, 4.0, 2.0, 3.0, 5.0], 2)  # rad/s^2
J = np.tile([30.0, 25.0, 35.0, 40.0, 20.0, 30.0, 50.0], 2)  # rad/s^3
#: Samples per edge, repetitions.
EDGE_SAMPLES, REPS = 120, 3
#: Finite-difference step of the limit checks [s].
STEP_S = 2.5e-4


def _corners_and_bends() -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(5)
    return rng.uniform(-0.8, 0.8, (3, 14)), rng.uniform(-0.15, 0.15, (3, 14))


def _edge(k: int, sigma: np.ndarray) -> np.ndarray:
    """Edge k of the closed curve from corner k to corner k + 1, bent by sin(pi sigma) (sigma in [0, 1]) [rad]."""
    corners, bends = _corners_and_bends()
    start, end = corners[k], corners[(k + 1) % 3]
    return start + np.outer(sigma, end - start) + np.outer(np.sin(np.pi * sigma), bends[k])


@pytest.fixture(scope="module")
def loop():
    """A closed curve of three bent edges through 14 joints, sampled densely near its corners (where a task brings the hand to rest), 3 repetitions."""
    sigma = (1 - np.cos(np.linspace(0.0, np.pi, EDGE_SAMPLES)))[:-1] / 2
    one = np.concatenate([_edge(k, sigma) for k in range(3)])
    q = np.concatenate([np.tile(one, (REPS, 1)), one[:1]])
    rep = np.append(np.repeat(np.arange(REPS), len(one)), REPS - 1)
    path = joint_path(q, 0.01 * np.arange(len(q)), ARMS, rep)
    timing = plan(path, V, A, jerk=J)
    return path, timing, len(one)


def _distance_to_polyline(x: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Each point of x (M, n) to the polyline through ``points`` (P, n): to the segments either side of its 8 nearest points (near a corner the nearest may be on the other edge)."""
    nearest = cKDTree(points).query(x, k=8)[1]
    best = np.full(len(x), np.inf)
    for a, b in [pair for k in range(8) for pair in ((nearest[:, k] - 1, nearest[:, k]), (nearest[:, k], nearest[:, k] + 1))]:
        a, b = np.clip(a, 0, len(points) - 1), np.clip(b, 0, len(points) - 1)
        d = points[b] - points[a]
        u = np.clip(np.einsum("ij,ij->i", x - points[a], d) / np.maximum(np.einsum("ij,ij->i", d, d), 1e-300), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(points[a] + u[:, None] * d - x, axis=1))
    return best


def test_every_limit_holds_by_finite_differences(loop):
    """Sampled every 0.25 ms, the first, second and third differences of q (each a mean of qd, qdd, the jerk) stay within the limits (1 + 1e-6)."""
    _, timing, _ = loop
    q = timing.evaluate(np.arange(0.0, timing.duration_s, STEP_S))[0]
    for order, limit in ((1, V), (2, A), (3, J)):
        ratio = np.abs(np.diff(q, order, axis=0) / STEP_S**order / limit).max()
        assert ratio <= 1 + 1e-6, (order, ratio)
        assert ratio > 0.9  # near time-optimal: some limit is reached


def test_the_trajectory_stays_on_the_curve_and_passes_every_sample(loop):
    """Every 1 ms the joints lie on the analytic curve the path samples (1e-6 rad, to the polyline through 20,001 of its points per edge), and at its passing times on each sample (1e-9); rest at both ends."""
    path, timing, _ = loop
    dense = np.concatenate([_edge(k, np.linspace(0.0, 1.0, 20001)) for k in range(3)])
    q = timing.evaluate(np.arange(0.0, timing.duration_s, 1e-3))[0]
    assert _distance_to_polyline(q, dense).max() < 1e-6
    assert path_deviation_max_rad(timing, path) < 1e-9
    ends = timing.evaluate(np.array([0.0, timing.duration_s]))[1]
    assert np.abs(ends).max() < 1e-12


def test_repetitions_repeat_and_it_is_deterministic(loop):
    """Each repetition, shifted to its start (when it passes its first sample), equals the first to 1e-9 rad; timing the path again gives the same samples bit for bit."""
    path, timing, per_rep = loop
    starts = timing.sample_times_s[np.arange(REPS) * per_rep]
    t = np.linspace(0.0, starts[1] - starts[0], 3001)
    first = timing.evaluate(starts[0] + t)[0]
    for start in starts[1:]:
        assert np.abs(timing.evaluate(start + t)[0] - first).max() <= 1e-9
    assert np.array_equal(plan(path, V, A, jerk=J).sample(1e-3).q, timing.sample(1e-3).q)


def test_it_takes_at_most_ten_percent_longer_than_topp_ra_without_jerk_limit(loop):
    """The duration is at most 1.10 times TOPP-RA's (toppra, full velocity and acceleration limits, jerk unlimited): the price of a finite jerk."""
    path, timing, _ = loop
    assert timing.duration_s <= 1.10 * plan(path, V, A).duration_s


def test_a_bad_jerk_limit_is_refused_in_one_line(loop):
    path, _, _ = loop
    with pytest.raises(InvalidArgumentError, match="jerk"):
        retime_path(path, V, A, jerk=np.append(J[:-1], -1.0))


def test_the_retime_stage_reports_and_checks_the_jerk():
    """The shipped triangle with `[retime] timing = "jerk-limited"`: the retime stage's velocity, acceleration and (mean, per sample period) jerk ratios are within 1 + 1e-6 and it has no violation."""
    result = run_task(TASKS / "triangle.toml", "mc-inverse", stages=("path", "ik", "retime"), retime=Retime(timing="jerk-limited"))
    for kind in ("velocity", "acceleration", "jerk"):
        assert result.metrics[f"retime.{kind}_ratio_max"] <= 1 + 1e-6
    assert result.verdict.status == "complete", result.verdict.violations
