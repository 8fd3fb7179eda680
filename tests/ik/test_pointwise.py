"""Pose-level baselines along a path: each one wired, seeded with its previous solution, and
scored by independent forward kinematics."""

import numpy as np
import pytest

from dualarm.describe.check import pybullet_poses
from dualarm.ik.pose_level.pointwise import POINTWISE_METHODS, solve_pointwise
from dualarm.paths import build_reference
from dualarm.tasks import load_task
from tests.helpers import HUMANOID, TASKS

pytestmark = pytest.mark.integration

#: Position accuracy each method promises on a sample it reports as solved [m] (TRAC-IK runs with
#: its own default epsilon, 1e-5 per twist component); PyBullet's FK is single precision (~1e-7).
PROMISED_M = {"trac-ik": np.sqrt(3) * 1e-5, "pybullet": 1e-9, "dls-svd": 1e-9, "ikfast-style": 1e-9}


@pytest.fixture(scope="module")
def short_circle(tmp_path_factory):
    """The circle task, one 1-s circle, twice."""
    text = (TASKS / "circle.toml").read_text().replace('robot = "../robots/humanoid"', f'robot = "{HUMANOID}"')
    path = tmp_path_factory.mktemp("tasks") / "circle.toml"
    path.write_text(text.replace("duration_s = 4.0", "duration_s = 1.0").replace("repetitions = 5", "repetitions = 2"))
    task = load_task(path)
    return task, build_reference(task)


@pytest.mark.parametrize("method", POINTWISE_METHODS)
def test_each_method_follows_the_path_checked_by_pybullet(short_circle, method):
    """Solved samples put the hand on the path by PyBullet's own FK (to its single-precision
    floor plus the method's promise); failed samples hold the last solved joints; and, seeded
    with the previous solution, no joint jumps on the smooth path (max step well below pi)."""
    task, ref = short_circle
    path = solve_pointwise(method, task.robot, ref, task.initial_q)
    chain = task.hand_chain_from_root("left")
    q = np.array([[path.configuration(k)[n] for n in chain.joint_names] for k in range(len(path))])
    reached = pybullet_poses(task.robot, chain, q)
    ok = path.status == 0
    assert ok.mean() >= 0.9, f"{method} solved only {ok.mean():.0%} of the samples"
    error = np.linalg.norm(reached[:, :3, 3] - ref.hands["left"].position, axis=1)
    assert error[ok].max() <= PROMISED_M[method] + 1e-6
    failed = np.flatnonzero(~ok)
    assert all(np.array_equal(path.q[k], path.q[k - 1]) for k in failed if k > 0)
    lower, upper = task.robot.lower_upper(path.joint_names)
    assert ((path.q >= lower - 1e-12) & (path.q <= upper + 1e-12)).all()
    if method != "trac-ik":  # TRAC-IK's random restarts may jump anywhere; the others are local
        consecutive = ok[1:] & ok[:-1]  # after failed samples a solver may land elsewhere
        assert np.abs(np.diff(path.q, axis=0)[consecutive]).max() < 1.0
