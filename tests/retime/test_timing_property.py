"""The default timing on paths nobody tuned it for: every IK method's paths on the study's random shapes.

Each path is timed as a run times it (jerk-limited, the robot's velocity, acceleration, jerk and position limits), as
the IK gave it and in three variants: 1e-7 rad of Gaussian noise added (the IK's rounding), reversed half-way (the
path goes back over itself), and every joint shifted so that its extreme sample sits on its nearest limit. Either the
timing is refused in one line because the path jumps, or it holds every limit (by finite differences every 0.25 ms:
of positions, and of accelerations for the jerk, ``test_jerk._fd_ratios``; every position within the joint's range or
the samples') and passes within 1e-6 rad of every
sample, also where the curve through the samples would leave a limit between them. Never another error, never a
crash.

Each trial is a test of its own, so that the workers share them; their counts are printed
(``pytest -s``). TRAC-IK's paths change from run to run (its timeout is wall-clock), and so do the counts.
"""

import functools
from collections import Counter

import numpy as np
import pytest

from dualarm.contracts.joint_path import JointPath
from dualarm.errors import StageError
from dualarm.retime.stage import plan
from dualarm.retime.timing import path_deviation_max_rad
from dualarm.run import run_task
from dualarm.study.spec import study_from_toml
from dualarm.study.trials import reachable_trial
from dualarm.tasks.task import Task
from tests.helpers import REPO
from tests.retime.test_jerk import STEP_S, _fd_ratios
from tests.retime.test_topp import joint_path

#: The study the paths come from: short tasks, sparse samples (the variants' timing is what costs).
SPEC = """
name = "timing"
methods = ["mc-inverse", "tvgdd", "pinv", "dls-svd", "trac-ik", "pybullet", "ikfast-style"]
trials = 12
seed = 7
hands = ["left", "right", "both"]
repetitions = [2, 2]
period_s = [1.5, 2.5]
control_period_s = 0.05
"""
#: The trials, and the paths each IK path gives (itself and three variants).
TRIALS, VARIANTS = 12, 4


def _variants(q: np.ndarray, lower: np.ndarray, upper: np.ndarray, rng: np.random.Generator):
    yield "ik", q
    yield "noise", q + rng.normal(0.0, 1e-7, q.shape)
    half = len(q) // 2
    yield "reversal", np.concatenate([q[:half], q[half - 2 :: -1][: half // 2]])
    shift = np.where(upper - q.max(axis=0) < q.min(axis=0) - lower, upper - q.max(axis=0), lower - q.min(axis=0))
    fits = np.isfinite(shift) & (np.ptp(q, axis=0) < upper - lower)
    yield "at-limit", q + np.where(fits, shift, 0.0)


def _leaves(timing, lower: np.ndarray, upper: np.ndarray) -> float:
    """How far [rad] the timing's positions every 0.25 ms go beyond [lower, upper]."""
    q = timing.evaluate(np.arange(0.0, timing.duration_s, STEP_S))[0]
    return float(max((q - upper).max(), (lower - q).max(), 0.0))


@functools.cache
def _paths(index: int) -> tuple[Task, list[JointPath]]:
    """Trial ``index`` of :data:`SPEC`: its task, and every IK method's path that solves every sample."""
    _, task = reachable_trial(study_from_toml(SPEC), index, REPO)
    paths = []
    for method in study_from_toml(SPEC).methods:
        try:
            path = run_task(task, method, stages=("path", "ik")).joint_path
        except StageError:  # the IK found no path (TV-GDD's QP without this task's tuning): nothing to time
            continue
        if path is not None and not (path.status != 0).any():
            paths.append(path)
    return task, paths


@pytest.mark.integration  # the IK methods' paths: MC-Inverse's arm angle search checks collisions in PyBullet
def test_the_study_gives_at_least_200_paths_with_their_variants():
    assert sum(VARIANTS * len(_paths(index)[1]) for index in range(TRIALS)) >= 200


@pytest.mark.integration
@pytest.mark.parametrize("index", range(TRIALS))
def test_the_default_timing_holds_every_limit_or_refuses_a_jump_on_generated_paths(index):
    task, paths = _paths(index)
    rng = np.random.default_rng(index)
    counts: Counter[str] = Counter()
    for path in paths:
        names = path.joint_names
        v, a, j = (task.robot.limit_array(kind, names) for kind in ("velocity", "acceleration", "jerk"))
        lower, upper = task.robot.lower_upper(names)
        for kind, q in _variants(path.q, lower, upper, rng):
            counts["paths"] += 1
            variant = joint_path(q, path.t[1] * np.arange(len(q)), names)
            where = (path.method, kind)
            try:
                timing = plan(variant, v, a, jerk=j, position=(lower, upper))
            except StageError as error:
                assert "the joint path jumps" in str(error) and "\n" not in str(error), where
                counts["refused: the path jumps"] += 1
                continue
            assert max(_fd_ratios(timing, (v, a, j))) <= 1 + 1e-6, where
            assert _leaves(timing, np.minimum(lower, q.min(axis=0)), np.maximum(upper, q.max(axis=0))) <= 1e-12
            counts["timed"] += 1
            counts["with a fallback piece"] += bool(timing.fallbacks)
            assert path_deviation_max_rad(timing, variant) <= 1e-6, where
    print(index, dict(counts))


@pytest.mark.integration
def test_a_jerk_peak_between_two_points_of_the_check_is_found():
    """Trial 11's MC-Inverse path (deterministic): its jerk peaks between two points of a check 0.1 ms apart.

    Checked every 10 us by finite differences of the timing's accelerations, which stay within the limit's 1e-6 only
    if the final check bounds the ratios between its points (a check of the ratios at points 0.1 ms apart found 1 +
    1.4e-5).
    """
    _, task = reachable_trial(study_from_toml(SPEC), 11, REPO)
    path = run_task(task, "mc-inverse", stages=("path", "ik")).joint_path
    v, a, jerk = (task.robot.limit_array(kind, path.joint_names) for kind in ("velocity", "acceleration", "jerk"))
    timing = plan(path, v, a, jerk=jerk, position=task.robot.lower_upper(path.joint_names))
    step_s, worst = 1e-5, 0.0
    for start in np.arange(0.0, timing.duration_s, 1.0):  # a second at a time: 100,000 points
        qdd = timing.evaluate(np.arange(start, min(start + 1.0 + step_s, timing.duration_s), step_s))[2]
        worst = max(worst, float((np.abs(np.diff(qdd, axis=0)) / step_s / jerk).max()))
    assert 0.999 < worst <= 1 + 1e-6
