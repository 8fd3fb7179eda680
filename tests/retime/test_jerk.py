"""The jerk-limited timing (`[retime] timing = "jerk-limited"`, dualarm.retime.jerk): within every velocity,
acceleration and jerk limit, on the path, rest to rest, repetitions identical, near TOPP-RA's time. Facts are computed
from the timing's samples by finite differences, from the analytic curve the path samples, and from toppra,
independently of the method."""

import re
import shutil

import numpy as np
import pytest
from scipy.interpolate import make_interp_spline
from scipy.spatial import cKDTree
from typer.testing import CliRunner

from dualarm.cli import app
from dualarm.errors import InvalidArgumentError, StageError
from dualarm.retime.stage import plan, retime_path
from dualarm.retime.timing import path_deviation_max_rad
from dualarm.retime.topp import chord_parameter
from dualarm.run import run_task
from dualarm.tasks import load_task
from dualarm.tasks.schema import Retime
from tests.helpers import HUMANOID, TASKS
from tests.retime.test_topp import ARMS, joint_path, rest_to_rest

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
    """A closed curve of three bent edges through 14 joints, sampled densely near its corners (where a task brings the
    hand to rest), 3 repetitions."""
    sigma = (1 - np.cos(np.linspace(0.0, np.pi, EDGE_SAMPLES)))[:-1] / 2
    one = np.concatenate([_edge(k, sigma) for k in range(3)])
    q = np.concatenate([np.tile(one, (REPS, 1)), one[:1]])
    rep = np.append(np.repeat(np.arange(REPS), len(one)), REPS - 1)
    path = joint_path(q, 0.01 * np.arange(len(q)), ARMS, rep)
    timing = plan(path, V, A, jerk=J)
    return path, timing, len(one)


def _distance_to_polyline(x: np.ndarray, points: np.ndarray, nearest: bool = False):
    """Each point of x (M, n) to the polyline through ``points`` (P, n): to the segments either side of its 8 nearest
    points (near a corner the nearest may be on the other edge); with ``nearest``, also the nearest point of the
    polyline (M, n)."""
    close = cKDTree(points).query(x, k=8)[1]
    best, where = np.full(len(x), np.inf), np.array(x, dtype=float)
    for a, b in [pair for k in range(8) for pair in ((close[:, k] - 1, close[:, k]), (close[:, k], close[:, k] + 1))]:
        a, b = np.clip(a, 0, len(points) - 1), np.clip(b, 0, len(points) - 1)
        d = points[b] - points[a]
        u = np.clip(np.einsum("ij,ij->i", x - points[a], d) / np.maximum(np.einsum("ij,ij->i", d, d), 1e-300), 0.0, 1.0)
        on = points[a] + u[:, None] * d
        distance = np.linalg.norm(on - x, axis=1)
        better = distance < best
        best, where[better] = np.where(better, distance, best), on[better]
    return (best, where) if nearest else best


def test_every_limit_holds_by_finite_differences(loop):
    """Sampled every 0.25 ms, the first, second and third differences of q (each a mean of qd, qdd, the jerk) stay
    within the limits (1 + 1e-6)."""
    _, timing, _ = loop
    q = timing.evaluate(np.arange(0.0, timing.duration_s, STEP_S))[0]
    for order, limit in ((1, V), (2, A), (3, J)):
        ratio = np.abs(np.diff(q, order, axis=0) / STEP_S**order / limit).max()
        assert ratio <= 1 + 1e-6, (order, ratio)
        assert ratio > 0.9  # near time-optimal: some limit is reached


def test_the_trajectory_stays_on_the_curve_and_passes_every_sample(loop):
    """Every 1 ms the joints lie on the analytic curve the path samples (1e-6 rad, to the polyline through 20,001 of its
    points per edge), and at its passing times within 1e-6 rad of each sample (the issue's budget); rest at both
    ends."""
    path, timing, _ = loop
    dense = np.concatenate([_edge(k, np.linspace(0.0, 1.0, 20001)) for k in range(3)])
    q = timing.evaluate(np.arange(0.0, timing.duration_s, 1e-3))[0]
    assert _distance_to_polyline(q, dense).max() < 1e-6
    assert path_deviation_max_rad(timing, path) <= 1e-6
    ends = timing.evaluate(np.array([0.0, timing.duration_s]))[1]
    assert np.abs(ends).max() < 1e-12


def test_repetitions_repeat_and_it_is_deterministic(loop):
    """Each repetition, shifted to its start (when it passes its first sample), equals the first to 1e-9 rad; timing the
    path again gives the same samples bit for bit."""
    path, timing, per_rep = loop
    starts = timing.sample_times_s[np.arange(REPS) * per_rep]
    t = np.linspace(0.0, starts[1] - starts[0], 3001)
    first = timing.evaluate(starts[0] + t)[0]
    for start in starts[1:]:
        assert np.abs(timing.evaluate(start + t)[0] - first).max() <= 1e-9
    assert np.array_equal(plan(path, V, A, jerk=J).sample(1e-3).q, timing.sample(1e-3).q)


def test_it_takes_at_most_ten_percent_longer_than_topp_ra_without_jerk_limit(loop):
    """The duration is at most 1.10 times TOPP-RA's (toppra, full velocity and acceleration limits, jerk unlimited): the
    price of a finite jerk."""
    path, timing, _ = loop
    assert timing.duration_s <= 1.10 * plan(path, V, A).duration_s


def test_a_bad_jerk_limit_is_refused_in_one_line(loop):
    path, _, _ = loop
    with pytest.raises(InvalidArgumentError, match="jerk"):
        retime_path(path, V, A, jerk=np.append(J[:-1], -1.0))


@pytest.mark.integration  # the ik stage's auto arm angle checks collisions in a PyBullet world
def test_the_retime_stage_reports_and_checks_the_jerk():
    """The shipped triangle with `[retime] timing = "jerk-limited"`: the retime stage's velocity, acceleration and
    (mean, per sample period) jerk ratios are within 1 + 1e-6 and it has no violation."""
    result = run_task(
        TASKS / "triangle.toml", "mc-inverse", stages=("path", "ik", "retime"), retime=Retime(timing="jerk-limited")
    )
    for kind in ("velocity", "acceleration", "jerk"):
        assert result.metrics[f"retime.{kind}_ratio_max"] <= 1 + 1e-6
    assert result.verdict.status == "complete", result.verdict.violations


def _fd_ratios(timing, limits=(V, A, J)) -> list[float]:
    """Velocity, acceleration and jerk ratios of the timing every :data:`STEP_S`, by finite differences.

    The velocity and the acceleration by first and second differences of its positions, the jerk by first differences
    of its acceleration, which those second differences confirm: each is q'' within STEP_S of the middle sample, so
    within the jerk limit times STEP_S of it. A difference quotient is an average of the derivative over its window (q
    is twice continuously differentiable, its jerk bounded), so none passes the derivative's largest value. Not third
    differences of the positions: their rounding (eight of a few 1e-16 rad at 2.8 rad, over STEP_S^3) is up to 5e-6 of
    a 100 rad/s^3 limit, and a motion riding that limit exactly read 1.0000017 (the property test, TRAC-IK's path of
    trial 11).
    """
    v, a, j = limits
    x, _, xdd = timing.evaluate(np.arange(0.0, timing.duration_s, STEP_S))
    second = np.diff(x, 2, axis=0) / STEP_S**2
    assert (np.abs(second - xdd[1:-1]) <= j * STEP_S + 1e-6 * a).all()
    return [
        float((np.abs(np.diff(x, axis=0)) / STEP_S / v).max()),
        float((np.abs(second) / a).max()),
        float((np.abs(np.diff(xdd, axis=0)) / STEP_S / j).max()),
    ]


def test_rounding_noise_in_the_samples_neither_breaks_a_limit_nor_slows_it_down(loop):
    """The loop's samples with the IK's rounding noise added (uniform, 1e-7 rad per joint): within the limits by finite
    differences, within 1e-6 rad of every sample, and as fast as without noise (0.5 %); an interpolating spline would
    put the noise into the jerk."""
    path, clean, _ = loop
    noise = np.random.default_rng(0).uniform(-1e-7, 1e-7, path.q.shape)
    noisy = joint_path(path.q + noise, path.t, ARMS, path.rep)
    timing = plan(noisy, V, A, jerk=J)
    assert max(_fd_ratios(timing)) <= 1 + 1e-6
    assert path_deviation_max_rad(timing, noisy) <= 1e-6
    assert timing.duration_s <= 1.005 * clean.duration_s


def test_a_reversal_where_the_samples_crowd_and_wander_is_followed_within_the_limits():
    """Out along one line, to rest, and back along another, the samples crowding near the turn (as the task slows down)
    with 1e-6 rad of noise where they are closer than that (the IK at rest): within the limits by finite differences,
    and within 1e-6 rad of every sample."""
    rng = np.random.default_rng(3)
    turn, out, back = rng.uniform(-0.5, 0.5, (3, 14))
    sigma = 1 - np.cos(np.linspace(0.0, np.pi / 2, 150))  # 0 .. 1, dense near 0 (the turn)
    q = np.concatenate([turn + np.outer(sigma[::-1], out - turn), turn + np.outer(sigma[1:], back - turn)])
    q[140:160] += rng.uniform(-1e-6, 1e-6, (20, 14))
    path = joint_path(q, 0.01 * np.arange(len(q)), ARMS)
    timing = plan(path, V, A, jerk=J)
    assert max(_fd_ratios(timing)) <= 1 + 1e-6
    assert path_deviation_max_rad(timing, path) <= 1e-6


@pytest.mark.integration  # the ik stage's auto arm angle checks collisions in a PyBullet world
def test_the_shipped_triangles_repetitions_repeat_to_1e_9_rad():
    """Three repetitions of the triangle by MC-Inverse, timed jerk-limited: each repetition's motion, from when it
    leaves corner A, equals the first's to 1e-9 rad."""
    task = load_task(TASKS / "triangle.toml", 3)
    path = run_task(task, "mc-inverse", stages=("path", "ik")).joint_path
    v, a, j = (task.robot.limit_array(kind, path.joint_names) for kind in ("velocity", "acceleration", "jerk"))
    timing = plan(path, v, a, jerk=j)
    starts = timing.sample_times_s[
        np.append(0, np.searchsorted(path.rep, [1, 2]) - 1)
    ]  # at corner A: the first sample, and the last of each repetition before
    t = np.linspace(0.0, starts[1] - starts[0], 5001)
    first = timing.evaluate(starts[0] + t)[0]
    for start in starts[1:]:
        assert np.abs(timing.evaluate(start + t)[0] - first).max() <= 1e-9


@pytest.mark.integration
def test_the_task_timing_is_checked_against_the_jerk_limit_in_one_line(tmp_path):
    """The triangle at its own timing (2 s per edge) on a copy of the humanoid whose left elbow's jerk limit is 0.5
    rad/s^3: the run fails in one line naming the joint and the jerk limit (exit 1)."""
    robot = tmp_path / "humanoid"
    shutil.copytree(HUMANOID, robot)
    text = (robot / "robot.toml").read_text()
    (robot / "robot.toml").write_text(
        re.sub(r"(\[limits\.jerk\][^\[]*?left_elbow = )[0-9.]+", r"\g<1>0.5", text, count=1)
    )
    task = tmp_path / "triangle.toml"
    task.write_text(
        (TASKS / "triangle.toml").read_text().replace('robot = "../robots/humanoid"', f'robot = "{robot}"')
        + '\n[retime]\ntiming = "task"\n'
    )
    result = CliRunner().invoke(
        app, ["run", str(task), "--ik", "mc-inverse", "--reps", "1", "--out", str(tmp_path / "runs")]
    )
    assert result.exit_code == 1, result.output
    lines = result.output.strip().splitlines()
    assert (
        lines[0] == "verdict: failed"
        and "left_elbow" in lines[1]
        and "jerk limit" in lines[1]
        and "keep_timing" in lines[1]
    ), result.output


@pytest.mark.parametrize("value", ["0.0", "-40.0", "inf"])
def test_an_infeasible_jerk_limit_is_refused_in_one_line_before_running(tmp_path, value):
    """A jerk limit no motion can keep (0, negative, infinite) in robot.toml: `dualarm run` prints one line naming the
    key, exits 2, and leaves no run directory."""
    robot = tmp_path / "humanoid"
    shutil.copytree(HUMANOID, robot)
    text = (robot / "robot.toml").read_text()
    (robot / "robot.toml").write_text(
        re.sub(r"(\[limits\.jerk\][^\[]*?left_elbow = )[0-9.]+", rf"\g<1>{value}", text, count=1)
    )
    task = tmp_path / "triangle.toml"
    task.write_text((TASKS / "triangle.toml").read_text().replace('robot = "../robots/humanoid"', f'robot = "{robot}"'))
    result = CliRunner().invoke(
        app, ["run", str(task), "--ik", "mc-inverse", "--reps", "1", "--out", str(tmp_path / "runs")]
    )
    assert result.exit_code == 2, result.output
    assert len(result.output.strip().splitlines()) == 1 and "limits.jerk.left_elbow" in result.output, result.output
    assert not (tmp_path / "runs").exists()


@pytest.fixture
def ipopt_stops_at_once(monkeypatch):
    """IPOPT allowed one iteration: every piece's program ends Maximum_Iterations_Exceeded, a real failure of IPOPT."""
    from dualarm.retime import jerk

    monkeypatch.setitem(jerk.IPOPT, "max_iter", 1)
    jerk._program.cache_clear()
    yield
    jerk._program.cache_clear()


def test_a_piece_ipopt_does_not_time_falls_back_within_every_limit_and_says_so(loop, ipopt_stops_at_once):
    """With every program failing, the loop is still timed: within the limits by finite differences, within 1e-6 rad of
    every sample, each piece reported as timed on the worst-case limits, each no faster than its velocity- and
    acceleration-limited bound, and the whole no faster than TOPP-RA's (the bound over every jerk-limited timing)."""
    path, _, _ = loop
    timing = plan(path, V, A, jerk=J)
    assert max(_fd_ratios(timing)) <= 1 + 1e-6
    assert path_deviation_max_rad(timing, path) <= 1e-6
    assert timing.fallbacks and {f.how for f in timing.fallbacks} == {"worst-case limits"}
    assert all(f.duration_s >= f.bound_s for f in timing.fallbacks)
    assert timing.duration_s >= plan(path, V, A).duration_s


def test_a_path_that_jumps_is_refused_in_one_line_naming_the_samples_and_the_joint():
    """A joint stepping 2 rad between two samples 10 ms apart (the IK changing branch): refused, not timed as a line."""
    t = 0.01 * np.arange(100)
    q = rest_to_rest(t, 14, 0.4)
    q[60:, 3] += 2.0
    with pytest.raises(StageError) as error:
        retime_path(joint_path(q, t, ARMS), V, A, jerk=J)
    message = str(error.value)
    assert "\n" not in message
    assert f"{ARMS[3]} moves {abs(q[60, 3] - q[59, 3]):.4g} rad between samples 59 and 60" in message
    assert error.value.joint == ARMS[3] and error.value.sample == 60


def test_a_joint_held_at_its_limit_stays_within_it_where_the_free_curve_overshoots():
    """A joint swinging up to its upper limit and held there (as an IK clamps it), then back: the curve through the
    samples overshoots the limit between them; with the position limits the trajectory stays within (evaluated every
    0.1 ms), within the other limits by finite differences, and within 1e-6 rad of every sample."""
    t = 0.01 * np.arange(300)
    q = rest_to_rest(t, 14, 0.4)
    q[:, 2] = np.minimum(0.2 + 0.15 * np.sin(np.pi * t / t[-1]) ** 2, 0.3)
    lower, upper = np.full(14, -np.inf), np.full(14, np.inf)
    upper[2] = 0.3
    path = joint_path(q, t, ARMS)
    free, bounded = (plan(path, V, A, jerk=J, position=limits) for limits in (None, (lower, upper)))
    overshoot = free.evaluate(np.arange(0.0, free.duration_s, 1e-4))[0][:, 2].max() - 0.3
    assert overshoot > 1e-6  # the case: the free curve leaves the limit
    assert bounded.evaluate(np.arange(0.0, bounded.duration_s, 1e-4))[0][:, 2].max() <= 0.3 + 1e-15
    assert max(_fd_ratios(bounded)) <= 1 + 1e-6
    assert path_deviation_max_rad(bounded, path) <= 1e-6


def test_the_benchs_lower_bound_holds_under_every_timing_and_is_met_on_a_straight_line(loop):
    """`dualarm bench trajectory`'s bound: no longer than the loop's jerk-limited timing (nor than TOPP-RA's time along
    each piece, nor any joint's own rest-to-rest move); on a straight line whose one joint binds every limit, Ruckig's
    time for that joint alone, which the jerk-limited timing meets within its 0.2 % margin."""
    from dualarm.bench.trajectory import rest_to_rest_bound_s
    from dualarm.retime.jerk import MARGIN

    path, timing, _ = loop
    assert plan(path, V, A).duration_s <= rest_to_rest_bound_s(path, V, A, J) <= timing.duration_s
    q = np.zeros((2, 14))
    q[1] = 0.01
    q[1, 4] = 1.0  # a hundred times farther than the others: joint 4 binds every limit
    line = joint_path(q, np.array([0.0, 1.0]), ARMS)
    bound = rest_to_rest_bound_s(line, V, A, J)
    assert bound <= plan(line, V, A, jerk=J).duration_s <= bound / MARGIN


def test_each_node_constrains_the_joints_nearest_their_limits_as_the_motion_itself_shows(loop):
    """The joints whose acceleration and jerk a program bounds at a node (`jerk._loaded`) are the LOADED largest of
    max(sqrt(|q''| / a), cbrt(|q'''| / j)) there, q'' and q''' (before and after the node) evaluated from the timed
    motion itself, and every joint of the 14 is within its limits after (finite differences)."""
    from dualarm.retime import jerk

    _, timing, _ = loop
    piece = timing.evaluate.pieces[0]
    nodes = piece.stretch * piece.starts_s  # node times of the stretched motion (it ranks the joints the same)
    d1, d2, d3 = (piece.path(piece.s, m) for m in (1, 2, 3))
    chosen = jerk._loaded(d1, d2, d3, piece.sd, piece.sdd, piece.sddd, A, J)
    _, _, qdd, _ = piece(nodes)
    before, after = piece(np.clip(nodes - 1e-9, 0, None))[3], piece(nodes + 1e-9)[3]
    before[0], after[-1] = after[0], before[-1]  # no interval before the first node, nor after the last
    load = np.maximum(np.sqrt(np.abs(qdd) / A), np.cbrt(np.maximum(np.abs(before), np.abs(after)) / J))
    ranked = np.sort(load, axis=1)[:, ::-1]
    clear = ranked[:, jerk.LOADED - 1] > ranked[:, jerk.LOADED] * (1 + 1e-6)  # no tie at the cut
    assert clear.mean() > 0.9
    expected = np.sort(np.argsort(-load, axis=1)[:, : jerk.LOADED], axis=1)
    assert chosen.shape == (len(nodes), jerk.LOADED) and len(np.unique(chosen)) > jerk.LOADED
    np.testing.assert_array_equal(chosen[clear], expected[clear])
    assert max(_fd_ratios(timing)) <= 1 + 1e-6


def _cubic_piece():
    """A cubic through 12 samples of a bent edge, timed by the program: its jerk jumps where s passes its knots.

    So is a piece of 4 samples whose curve had knots inserted to keep it within a limit (the property test's trial 5).
    """
    from dualarm.retime import jerk

    sigma = np.linspace(0.0, 1.0, 12)
    q = _edge(0, sigma)
    s = chord_parameter(q)[0]
    return jerk._time_piece(make_interp_spline(s, q, k=3), V, A, J, (0, 11))


def test_the_final_checks_bound_between_two_points_is_above_the_motion_there(loop):
    """Between two of the check's times 1 ms apart, the final check's bound of max(velocity ratio, sqrt(acceleration
    ratio), cbrt(jerk ratio)) (`PieceTiming._bounds`: Faa di Bruno's formula, no sampling) is above that ratio of the
    motion evaluated every 1 us between them (the ends alone are not: a peak between them is above both), and close to
    it: the stretch it gives holds every limit and wastes no time. On the loop's quintic pieces, and on a cubic, whose
    jerk jumps where s passes its knots (the check looks on both sides of each)."""
    _, timing, _ = loop
    cubic = _cubic_piece()
    assert cubic.path.k == 3 and len(np.unique(cubic.path.t)) > 2
    for piece in (*timing.evaluate.pieces, cubic):
        t = piece.check_times(1e-3)  # every 1 ms, both sides of every node and of each knot where P'''' jumps
        upper = piece._bounds(t, V, A, J)[1]
        dense = np.linspace(t[:-1], t[1:], 1001, axis=1).ravel()  # 1001 times per pair, the pair's ends included
        _, qd, qdd, qddd = piece(dense)
        ratio = np.max([np.abs(qd) / V, np.sqrt(np.abs(qdd) / A), np.cbrt(np.abs(qddd) / J)], axis=(0, 2))
        between = ratio.reshape(len(t) - 1, 1001).max(axis=1)
        ends = np.maximum(ratio[::1001], ratio[1000::1001])
        assert (upper >= between * (1 - 1e-12)).all() and (ends < between * (1 - 1e-9)).any()
        assert (upper - between).max() < 1e-4


def test_a_program_allowed_a_share_of_its_limits_at_every_node_times_the_motion_slowed_down_by_it():
    """A program whose nodes each allow lambda of the limits (the velocity times lambda, the acceleration lambda^2, the
    jerk lambda^3) finds the full program's timing slowed down by 1 / lambda (t -> t / lambda meets exactly those
    limits): its durations 1 / lambda times, its path velocities lambda times, to IPOPT's tolerance. The refinement
    tightens the limits of a few nodes so, to slow down there only; on three joints, all constrained at every node."""
    from dualarm.retime import jerk

    path, nodes = _three_joint_piece()
    limits = V[:3], A[:3], J[:3]
    full = jerk._solve(path, nodes, *limits, (0, 39), None)
    for share in (0.8, 0.5):
        slow = jerk._solve(path, nodes, *limits, (0, 39), None, limits=np.full(len(nodes), share))
        assert slow.duration_s == pytest.approx(full.duration_s / share, rel=1e-6)
        np.testing.assert_allclose(slow.dt, full.dt / share, rtol=1e-4, atol=1e-6 * full.duration_s)
        np.testing.assert_allclose(slow.sd, share * full.sd, rtol=1e-4, atol=1e-6 * full.sd.max())


def _three_joint_piece():
    """The curve of a bent edge through three joints, and 31 nodes on it (30 intervals, as refinements leave them)."""
    from dualarm.retime import jerk

    q = _edge(1, np.linspace(0.0, 1.0, 40))[:, :3]
    s = chord_parameter(q)[0]
    path, _ = jerk.fit(s, q)
    return path, s[-1] * (1 - np.cos(np.linspace(0.0, np.pi, 31))) / 2


@pytest.mark.parametrize("step", [32, 64])
def test_a_program_built_larger_than_its_piece_times_it_as_one_of_its_own_size(monkeypatch, step):
    """The program of 30 intervals solved in one of 32 or 64 (`jerk.PROGRAM_STEP`; the intervals after the piece's
    null) gives the timing of a program of exactly 30, built for it, to IPOPT's tolerance, in as many IPOPT iterations:
    the null intervals change nothing (left as equations 0 = 0, IPOPT's handling of them changed the bench's ball game
    by 0.7 %), and the timing is read from the right unknowns."""
    from dualarm.retime import jerk

    path, nodes = _three_joint_piece()
    limits = V[:3], A[:3], J[:3]

    def solve(size: int):  # the timing, and IPOPT's iterations
        monkeypatch.setattr(jerk, "PROGRAM_STEP", size)
        timing = jerk._solve(path, nodes, *limits, (0, 39), None)
        return timing, jerk._program(3, -(-30 // size) * size, warm=False)[0].stats()["iter_count"]

    (own, iterations), (larger, larger_iterations) = solve(1), solve(step)
    assert len(larger.dt) == len(own.dt) == 30 and larger_iterations == iterations
    np.testing.assert_allclose(larger.dt, own.dt, rtol=1e-6, atol=1e-9 * own.duration_s)
    np.testing.assert_allclose(larger.sd, own.sd, rtol=1e-6, atol=1e-9 * own.sd.max())
