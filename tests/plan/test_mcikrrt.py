"""MCIKRRT on a 2-D problem with a known narrow passage: a wall across the unit square with one
gap, the start on one side and a goal region (sampled like a WTA) on the other."""

import numpy as np
import pytest

from dualarm.errors import InvalidArgumentError, StageError
from dualarm.plan.mcikrrt import TreeSearchSettings, mcikrrt, path_length, shortcut
from dualarm.plan.problem import PlanningSettings

WALL = (0.45, 0.55)  # x band of the wall
GAP = (0.49, 0.51)  # the only opening, in y
LOWER, UPPER = np.zeros(2), np.ones(2)
START = np.array([0.1, 0.1])
#: The planner settings of :func:`plan` unless a test gives its own.
SETTINGS = TreeSearchSettings(step_rad=0.1, timeout_s=10.0)


class WallChecker:
    """Point robot against the wall; segments checked every ``resolution`` (max-norm)."""

    def __init__(self, gap=GAP, resolution=0.002):
        self.gap, self.resolution, self.checks = gap, resolution, 0

    def free(self, q):
        self.checks += 1
        in_wall = WALL[0] <= q[0] <= WALL[1]
        return not in_wall or (self.gap is not None and self.gap[0] <= q[1] <= self.gap[1])

    def segment_free(self, a, b):
        steps = int(np.ceil(np.abs(b - a).max() / self.resolution))
        return all(self.free(a + s / steps * (b - a)) for s in range(1, steps))


def crosses_wall_outside_gap(a, b) -> bool:
    """Analytic: does the segment a-b pass through the wall band anywhere outside the gap?"""
    lo, hi = sorted((a[0], b[0]))
    if hi < WALL[0] or lo > WALL[1]:
        return False
    if a[0] == b[0]:
        ys = (a[1], b[1])
    else:  # y where the segment enters and leaves the band (clipped to the segment)
        ts = [np.clip((x - a[0]) / (b[0] - a[0]), 0, 1) for x in WALL]
        ys = [a[1] + t * (b[1] - a[1]) for t in ts]
    return not all(GAP[0] <= y <= GAP[1] for y in ys)


def goal_sampler(rng, goals):
    def sample():
        q = np.array([rng.uniform(0.8, 0.95), rng.uniform(0.8, 0.95)])
        goals.append(q)
        return q

    return sample


def plan(seed, checker=None, settings=SETTINGS):
    goals = []
    checker = checker or WallChecker()
    result = mcikrrt(
        START,
        LOWER,
        UPPER,
        checker,
        goal_sampler(np.random.default_rng([seed, 0]), goals),
        np.random.default_rng([seed, 1]),
        settings,
    )
    return result, goals, checker


@pytest.mark.parametrize("seed", range(5))
def test_finds_a_path_through_the_narrow_passage(seed):
    result, goals, checker = plan(seed)
    assert result.success, result.reason
    path = result.path
    assert np.array_equal(path[0], START)
    assert any(np.array_equal(path[-1], g) for g in goals)
    for a, b in zip(path[:-1], path[1:], strict=True):
        assert not crosses_wall_outside_gap(a, b), (a, b)
    # the path gets from x < 0.45 to x > 0.55, so some segment crosses the band, through the gap
    assert any(
        a[0] < WALL[0] and b[0] > WALL[1] or WALL[0] <= a[0] <= WALL[1]
        for a, b in zip(path[:-1], path[1:], strict=True)
    )
    assert result.collision_checks == checker.checks
    assert result.nodes >= 2 and result.goals >= 1
    assert result.path_length_rad <= result.raw_path_length_rad + 1e-12


def test_same_seed_same_path():
    a, _, _ = plan(3)
    b, _, _ = plan(3)
    assert np.array_equal(a.path, b.path)
    assert a.nodes == b.nodes and a.collision_checks == b.collision_checks


def test_no_passage_times_out():
    result, goals, _ = plan(0, WallChecker(gap=None), TreeSearchSettings(step_rad=0.1, timeout_s=0.3))
    assert not result.success
    assert "timeout" in result.reason
    assert result.path.shape == (0, 2)
    assert goals  # it did sample goals, it just could not reach them
    assert 0.3 <= result.planning_time_s < 3.0


def test_start_in_collision_is_refused():
    with pytest.raises(StageError, match="start configuration is in collision"):
        mcikrrt(np.array([0.5, 0.2]), LOWER, UPPER, WallChecker(), lambda: None, np.random.default_rng(0))


def test_shortcut_keeps_ends_and_never_lengthens():
    rng = np.random.default_rng(7)
    path = [START] + [rng.uniform(0, 0.4, 2) for _ in range(8)] + [np.array([0.3, 0.3])]
    out = shortcut(path, WallChecker(), 50, rng)
    assert np.array_equal(out[0], path[0]) and np.array_equal(out[-1], path[-1])
    assert path_length(np.array(out)) <= path_length(np.array(path))
    assert len(out) == 2  # every point is on the free side of the wall: one straight segment remains


def test_settings_are_checked():
    with pytest.raises(InvalidArgumentError, match="goal probability"):
        TreeSearchSettings(goal_probability=1.5)
    with pytest.raises(InvalidArgumentError, match="timeout"):
        TreeSearchSettings(timeout_s=0)
    with pytest.raises(InvalidArgumentError, match="step_rad: must be a positive number, not nan"):
        TreeSearchSettings(step_rad=float("nan"))
    with pytest.raises(InvalidArgumentError, match="margin_m: must be a non-negative number, not -0.1"):
        PlanningSettings(margin_m=-0.1)
