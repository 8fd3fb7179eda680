"""The reference collision checker: PyBullet's closest points on the inflated robot, one at a time.

:class:`~dualarm.plan.collision.CollisionChecker` agrees with it (tested) and ``dualarm bench plan``
times both.
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from dualarm.errors import StageError
from dualarm.model.robot import Robot
from dualarm.plan.checker import Contact, _Checker, inflated_urdf
from dualarm.sim.world import add_environment, disable_unchecked_pairs, in_contact, load_pybullet_robot, pb


class PyBulletChecker(_Checker):
    """Checks configurations of ``joint_names`` (the others at ``fixed``) one at a time, with PyBullet.

    PyBullet's narrow phase on the inflated robot (module docstring).

    Pairs in ``allowed_contacts`` (a task's ``expected_contacts``: a palm on the bowl it grasps) are
    not checked. Attributes as :class:`_Checker`'s.
    """

    def __init__(
        self,
        robot: Robot,
        joint_names: Sequence[str],
        fixed: Mapping[str, float],
        environment=(),
        allowed_contacts: Sequence[tuple[str, str]] = (),
        margin_m: float = 0.01,
        resolution_rad: float = 0.02,
    ):
        super().__init__(joint_names, margin_m, resolution_rad)
        if self.margin_m == 0:  # the robot's own file, so that its relative mesh paths resolve
            self._sim = load_pybullet_robot(robot.urdf.path, self_collision=True)
        else:
            with tempfile.TemporaryDirectory() as tmp:
                urdf = Path(tmp) / robot.urdf.path.name
                urdf.write_text(inflated_urdf(robot.urdf.path.read_text(), self.margin_m))
                self._sim = load_pybullet_robot(urdf, self_collision=True)
        sim = self._sim
        missing = [n for n in (*self.joint_names, *fixed) if n not in sim.joint_index]
        if missing:
            self.close()
            raise StageError(f"collision checking: the robot has no joint {missing[0]}")
        self._index = [sim.joint_index[n] for n in self.joint_names]
        self.unchecked_pairs = disable_unchecked_pairs(sim, robot.disabled_pairs, self.margin_m)
        sim.set_positions(list(fixed), list(fixed.values()))
        self._objects = add_environment(sim, environment)
        self._link_name = sim.link_name
        self._bodies = {name: body for body, name in self._objects.items()}
        for a, b in allowed_contacts:
            link, other = (a, b) if a in sim.link_index else (b, a)
            if link not in sim.link_index:
                self.close()
                raise StageError(f"collision checking: allowed contact ({a}, {b}) names no robot link")
            if other in self._bodies:
                pb.setCollisionFilterPair(
                    sim.body,
                    self._bodies[other],
                    sim.link_index[link],
                    -1,
                    enableCollision=0,
                    physicsClientId=sim.client,
                )
            elif other in sim.link_index:
                pb.setCollisionFilterPair(
                    sim.body,
                    sim.body,
                    sim.link_index[link],
                    sim.link_index[other],
                    enableCollision=0,
                    physicsClientId=sim.client,
                )
            else:
                self.close()
                raise StageError(
                    f"collision checking: allowed contact ({a}, {b}): '{other}' "
                    "is neither a robot link nor an object of the task"
                )

    def overlaps(self, q: np.ndarray, pairs: Sequence[tuple[str, str]]) -> dict[tuple[str, str], float]:
        """How deep [m] each of ``pairs`` of the inflated robot overlaps at ``q`` [rad], by PyBullet.

        A pair: a robot link, another link or an object. By PyBullet's closest points (a query that
        keeps no state between calls, unlike the contact points); the pairs apart are left out. Not
        a check (neither counted nor timed).
        """
        sim, out = self._sim, {}
        if pairs:
            pb.resetJointStatesMultiDof(
                sim.body, self._index, np.asarray(q, dtype=float).reshape(-1, 1).tolist(), physicsClientId=sim.client
            )
        for a, b in pairs:
            other, link = (self._bodies[b], -1) if b in self._bodies else (sim.body, sim.link_index[b])
            points = [
                p
                for p in pb.getClosestPoints(sim.body, other, 0.0, sim.link_index[a], link, physicsClientId=sim.client)
                if in_contact(p)
            ]
            if points:
                out[(a, b)] = -min(p[8] for p in points)
        return out

    def _contact_points(self, q: np.ndarray) -> list:
        """PyBullet's contact points of the robot at ``q`` [rad] (timed and counted as a check)."""
        started = time.perf_counter()
        sim = self._sim
        pb.resetJointStatesMultiDof(
            sim.body, self._index, np.asarray(q, dtype=float).reshape(-1, 1).tolist(), physicsClientId=sim.client
        )
        pb.performCollisionDetection(physicsClientId=sim.client)
        points = pb.getContactPoints(bodyA=sim.body, physicsClientId=sim.client)
        self.checks += 1
        self.check_time_s += time.perf_counter() - started
        return points

    def contacts(self, q: np.ndarray) -> list[Contact]:
        """Every checked pair closer than the margin at ``q`` [rad], deepest first."""
        deepest: dict[tuple[str, str], float] = {}
        for point in self._contact_points(q):
            if in_contact(point):
                other = self._link_name[point[4]] if point[2] == self._sim.body else self._objects[point[2]]
                key = (self._link_name[point[3]], other)
                deepest[key] = max(deepest.get(key, 0.0), -point[8])
        return sorted((Contact(a, b, d) for (a, b), d in deepest.items()), key=lambda c: -c.depth_m)

    def free(self, q: np.ndarray) -> bool:
        """No checked pair is closer than the margin at ``q`` [rad]."""
        return not any(in_contact(point) for point in self._contact_points(q))

    def free_many(self, Q: np.ndarray) -> np.ndarray:
        """:meth:`free` of each configuration of ``Q`` (N, n) [rad] in turn; (N,) bool."""
        return np.array([self.free(q) for q in self._configurations(Q)], dtype=bool)

    def close(self) -> None:
        """Disconnect PyBullet."""
        self._sim.close()
