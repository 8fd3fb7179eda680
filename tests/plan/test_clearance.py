"""The ``auto`` arm angle kept clear of collisions (:mod:`dualarm.plan.clearance`), checked with PyBullet's
closest points on the robot's own URDF."""

from __future__ import annotations

import re

import numpy as np
import pytest

from dualarm.ik.analytic.mc_path import settings_for, solve_mc_inverse
from dualarm.paths.build import build_reference
from dualarm.plan.clearance import CLEARANCE_MARGIN_M, ArmClearance
from dualarm.sim.world import disable_unchecked_pairs, load_pybullet_robot, pb
from dualarm.tasks import load_task
from tests.helpers import HUMANOID, TASKS

pytestmark = pytest.mark.integration


def _circle(tmp_path, toward_paper: float):
    """The circle, its centre moved ``toward_paper`` of the way to the paper's (where every arm angle of (-pi, 0)
    puts the upper arm into the torso), started from ``ready``."""
    cx, cy = 0.31 + toward_paper * (0.293 - 0.31), -0.11 + toward_paper * (-0.2 + 0.11)
    text = (TASKS / "circle.toml").read_text().replace('robot = "../robots/humanoid"', f'robot = "{HUMANOID}"')
    text = text.replace("position = [0.31, 0.04, -0.35]", f"position = [{cx:.4f}, {cy + 0.15:.4f}, -0.35]")
    text = text.replace("arc_center = [0.31, -0.11, -0.35]", f"arc_center = [{cx:.4f}, {cy:.4f}, -0.35]")
    text = re.sub(r"\[initial\][^\[]*", "", text, count=1).replace(
        'waist = "locked"', 'waist = "locked"\ninitial = "ready"'
    )
    (tmp_path / "circle.toml").write_text(text)
    return load_task(tmp_path / "circle.toml", 1)


def _nearest_m(task, q: np.ndarray, names) -> np.ndarray:
    """Per configuration, PyBullet's least distance between a left-arm link and a link of the body [m]."""
    robot = task.robot
    first = next(j for j in robot.hand_chain("left").joints if j.movable)
    parent = {j.child: j.parent for j in robot.urdf.joints}

    def arm(link: str) -> bool:
        while link in parent and link != first.child:
            link = parent[link]
        return link == first.child

    with load_pybullet_robot(robot.urdf.path, self_collision=True) as sim:
        unchecked = disable_unchecked_pairs(sim, robot.disabled_pairs)
        sim.set_positions(list(task.initial_q), list(task.initial_q.values()))
        mine = [link for link in sim.link_index if arm(link)]
        body = [link for link in sim.link_index if not arm(link) and "right" not in link]
        pairs = [(a, b) for a in mine for b in body if tuple(sorted((a, b))) not in unchecked]
        out = []
        for row in q:
            sim.set_positions(names, row)
            out.append(
                min(
                    (
                        p[8]
                        for a, b in pairs
                        for p in pb.getClosestPoints(
                            sim.body, sim.body, 0.1, sim.link_index[a], sim.link_index[b], physicsClientId=sim.client
                        )
                    ),
                    default=0.1,
                )
            )
    return np.array(out)


def test_auto_keeps_the_arm_clear_where_the_least_travel_profile_does_not(tmp_path):
    """40 % of the way to the paper's circle centre, the least-travel profile brings the upper arm within the margin
    of the torso (PyBullet); with the collision check the profile keeps every sample clear, and still reaches
    every pose (MC-Inverse is exact)."""
    task = _circle(tmp_path, 0.4)
    reference = build_reference(task)
    names = task.robot.hand_chain("left").joint_names
    plain = solve_mc_inverse(task.robot, reference, task.initial_q, settings_for(task))
    with ArmClearance(task) as clearance:
        clear = solve_mc_inverse(task.robot, reference, task.initial_q, settings_for(task), clearance=clearance)
    columns = [plain.joint_names.index(n) for n in names]
    before = _nearest_m(task, plain.q[::5, columns], names)
    after = _nearest_m(task, clear.q[:, columns], names)
    assert before.min() < 2 * CLEARANCE_MARGIN_M - 1e-3
    assert after.min() >= 2 * CLEARANCE_MARGIN_M - 1e-4  # PyBullet's distances are single precision
    assert np.abs(clear.hand_error_m).max() < 1e-9


def test_auto_that_cannot_keep_clear_says_so(tmp_path):
    """80 % of the way: no profile of (-pi, 0) within the limits and steps keeps clear: the error says collisions."""
    task = _circle(tmp_path, 0.8)
    from dualarm.errors import StageError

    with ArmClearance(task) as clearance, pytest.raises(StageError, match="and the arm clear of collisions beyond"):
        solve_mc_inverse(task.robot, build_reference(task), task.initial_q, settings_for(task), clearance=clearance)
