"""Which configurations of one arm keep it clear of the robot and the task's objects, for an IK search.

MC-Inverse's and SEW's ``auto`` arm angle is searched over the arm's configurations; without this, the search
keeps joint limits only, and where an arm passes close to the torso it may choose a profile that puts the upper
arm through it. :class:`ArmClearance` gives the search the planners' closed-form collision checker
(:class:`~dualarm.plan.collision.CollisionChecker`), one per arm, built when the search first asks about it.

Each arm's checker moves that arm's joints, the others held at the task's initial configuration, and checks
the pairs between a link the arm moves and every other link and object of the task, but not the other driven
arms' links (they move too, and their motion is solved apart) nor the task's expected contacts; pairs that no
joint of the arm moves are not its business. The margin is :data:`CLEARANCE_MARGIN_M` (half the planners'); on
a robot with collision meshes, which no margin grows (:func:`~dualarm.plan.checker.inflated_urdf`), it is 0:
no contact.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from dualarm.plan.checker import mesh_collisions
from dualarm.plan.collision import CollisionChecker

if TYPE_CHECKING:
    from dualarm.tasks import Task

#: Safety margin of the arm-angle search's collision check [m]: each checked link keeps this from every object
#: and twice this from every other checked link.
CLEARANCE_MARGIN_M = 0.005


class ArmClearance:
    """``(hand, Q (M, 7)) -> (M,) bool``: which configurations of ``hand``'s arm are clear (module doc).

    Close it (or use it in a ``with``) to free the PyBullet worlds of its checkers.
    """

    def __init__(self, task: Task, margin_m: float = CLEARANCE_MARGIN_M):
        meshes = mesh_collisions(task.robot.urdf.path.read_text())
        self.task, self.margin_m = task, 0.0 if meshes else margin_m
        self._checkers: dict[str, CollisionChecker] = {}

    def __call__(self, hand: str, Q: np.ndarray) -> np.ndarray:
        """Whether each configuration of the arm's joints (chain order) [rad] is clear; (M,) bool."""
        Q = np.asarray(Q, dtype=float).reshape(-1, 7)
        if not len(Q):
            return np.zeros(0, bool)
        if hand not in self._checkers:
            self._checkers[hand] = self._checker(hand)
        return self._checkers[hand].free_many(Q)

    def _checker(self, hand: str) -> CollisionChecker:
        task = self.task
        robot = task.robot
        urdf = robot.urdf
        moved = {h: _moved_links(task, h) for h in task.spec.hands if h in robot.hands}
        mine = moved[hand]
        others = set().union(*(links for h, links in moved.items() if h != hand))
        links = list(urdf.links)
        allowed = [(a, b) for i, a in enumerate(links) for b in links[i + 1 :] if a not in mine and b not in mine]
        allowed += [(a, b) for a in mine for b in others]
        allowed += [(link, obj.name) for link in links if link not in mine for obj in task.spec.environment]
        allowed += list(task.spec.expected_contacts)
        joints = robot.hand_chain(hand).joint_names
        fixed = {n: v for n, v in task.initial_q.items() if n not in joints}
        return CollisionChecker(robot, joints, fixed, task.spec.environment, allowed, self.margin_m)

    def close(self) -> None:
        """Disconnect every checker's PyBullet world."""
        for checker in self._checkers.values():
            checker.close()
        self._checkers.clear()

    def __enter__(self) -> ArmClearance:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _moved_links(task: Task, hand: str) -> frozenset[str]:
    """The links below the first movable joint of ``hand``'s arm."""
    arm = task.robot.hand_chain(hand)
    return task.robot.urdf.subtree(next(j for j in arm.joints if j.movable).child)
