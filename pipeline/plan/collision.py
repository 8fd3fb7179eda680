"""Collision checking of configurations and joint-space segments for the planners.

The humanoid's collision shapes are capsules (arms, torso, pelvis) and a sphere (head); the task's
fixed objects are boxes, cylinders and spheres. Checking is PyBullet's own narrow phase (exact
convex distance, GJK/EPA) on a copy of the robot whose every collision shape is inflated by the
safety margin: the URDF is rewritten with each capsule's, sphere's and cylinder's radius (and each
box's half-extents) grown by ``margin_m``. So a configuration is free exactly when every checked
robot link keeps ``margin_m`` from every object and ``2 margin_m`` from every other checked link.
One check teleports the joints (``resetJointStatesMultiDof``), runs
``performCollisionDetection`` (the broad phase prefilters the pairs by their bounding boxes) and
reads the contact points with a negative distance.

Pairs not checked: those that touch by construction, one list shared with the execute stage
(:func:`~dualarm.execute.world.disable_touching_pairs`), and the task's expected contacts.

Segments are checked at configurations spaced at most ``resolution_rad`` apart in every joint
(the max-norm), end points excluded (a tree's nodes are checked when they are made).
"""

from __future__ import annotations

import tempfile
import time
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dualarm.errors import StageError
from dualarm.execute.world import add_environment, disable_touching_pairs, in_contact, load_pybullet_robot, pb
from dualarm.model.robot import Robot


def inflated_urdf(text: str, margin_m: float) -> str:
    """The URDF ``text`` with every ``<collision>`` shape grown by ``margin_m`` [m] on every side."""
    root = ET.fromstring(text)
    for link, geometry in ((link, collision) for link in root.iter("link") for collision in link.iter("collision")):
        for shape in geometry.iter():
            if shape.tag in ("capsule", "sphere", "cylinder"):
                shape.set("radius", repr(float(_attribute(shape, "radius")) + margin_m))
                if shape.tag == "cylinder":
                    shape.set("length", repr(float(_attribute(shape, "length")) + 2 * margin_m))
            elif shape.tag == "box":
                shape.set("size", " ".join(repr(float(s) + 2 * margin_m) for s in _attribute(shape, "size").split()))
            elif shape.tag == "mesh":
                raise StageError(
                    f"collision checking: link '{link.get('name')}' collides as a mesh ({shape.get('filename')}), which the planners' safety margin cannot inflate; "
                    "give its <collision> capsules, spheres, cylinders or boxes (a run's execution checks the meshes themselves)"
                )
    return ET.tostring(root, encoding="unicode")


def _attribute(shape: ET.Element, name: str) -> str:
    """The attribute ``name`` of a URDF collision shape, which URDF requires of it."""
    value = shape.get(name)
    if value is None:
        raise StageError(f"collision checking: a <{shape.tag}> collision shape has no '{name}' attribute")
    return value


def bisection_order(steps: int) -> np.ndarray:
    """The integers 1 .. steps - 1 in bisection order: the middle first, then the middles of the two halves, and so on (each once)."""
    order, seen, spans = [], set(), [(0, steps)]
    while spans:
        next_spans = []
        for lo, hi in spans:
            if hi - lo > 1:
                mid = (lo + hi) // 2
                if mid not in seen:
                    seen.add(mid)
                    order.append(mid)
                next_spans += [(lo, mid), (mid, hi)]
        spans = next_spans
    return np.array(order, dtype=float)


@dataclass(frozen=True)
class Contact:
    """A checked pair that is closer than the margin allows.

    Attributes:
        a: a robot link.
        b: another robot link, or an environment object's name.
        depth_m: how far the inflated shapes overlap [m] (> 0).
    """

    a: str
    b: str
    depth_m: float


class CollisionChecker:
    """Checks configurations of ``joint_names`` (the others at ``fixed``) against self-collision and the task's fixed objects, with a safety margin.

    Pairs in ``allowed_contacts`` (a task's ``expected_contacts``: a palm on the bowl it grasps) are
    not checked.

    Attributes:
        joint_names: the planned joints, the order of every configuration.
        margin_m: safety margin [m] (see the module docstring).
        resolution_rad: largest joint step between the configurations checked along a segment [rad].
        checks: configurations checked so far.
        check_time_s: time spent in checks so far [s].
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
        if not (np.isfinite(margin_m) and margin_m >= 0):
            raise StageError(f"collision checking: the safety margin must be a non-negative number of metres, not {margin_m}")
        if not (np.isfinite(resolution_rad) and resolution_rad > 0):
            raise StageError(f"collision checking: the segment resolution must be a positive number of radians, not {resolution_rad}")
        self.joint_names = tuple(joint_names)
        self.margin_m = float(margin_m)
        self.resolution_rad = float(resolution_rad)
        self.checks = 0
        self.check_time_s = 0.0
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
            raise StageError(f"collision checking: the robot has no joint {missing[0]}")
        self._index = [sim.joint_index[n] for n in self.joint_names]
        self.unchecked_pairs = disable_touching_pairs(sim, self.margin_m)
        sim.set_positions(list(fixed), list(fixed.values()))
        self._objects = add_environment(sim, environment)
        self._link_name = {i: n for n, i in sim.link_index.items()}
        bodies = {name: body for body, name in self._objects.items()}
        for a, b in allowed_contacts:
            link, other = (a, b) if a in sim.link_index else (b, a)
            if link not in sim.link_index:
                raise StageError(f"collision checking: allowed contact ({a}, {b}) names no robot link")
            if other in bodies:
                pb.setCollisionFilterPair(sim.body, bodies[other], sim.link_index[link], -1, enableCollision=0, physicsClientId=sim.client)
            elif other in sim.link_index:
                pb.setCollisionFilterPair(sim.body, sim.body, sim.link_index[link], sim.link_index[other], enableCollision=0, physicsClientId=sim.client)
            else:
                raise StageError(f"collision checking: allowed contact ({a}, {b}): '{other}' is neither a robot link nor an object of the task")

    def _contact_points(self, q: np.ndarray) -> list:
        """PyBullet's contact points of the robot at ``q`` [rad] (timed and counted as a check)."""
        started = time.perf_counter()
        sim = self._sim
        pb.resetJointStatesMultiDof(sim.body, self._index, np.asarray(q, dtype=float).reshape(-1, 1).tolist(), physicsClientId=sim.client)
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

    def segment_steps(self, a: np.ndarray, b: np.ndarray) -> int:
        """Into how many equal steps the segment from ``a`` to ``b`` [rad] is cut so that no joint moves more than :attr:`resolution_rad` in one (at least 1)."""
        return max(1, int(np.ceil(np.abs(b - a).max() / self.resolution_rad)))

    def segment_configurations(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """The configurations checked strictly between ``a`` and ``b`` [rad], evenly spaced at most :attr:`resolution_rad` apart in every joint, in bisection order (the midpoint, then the quarter points, ...) so that a blocked segment is found blocked early; (k, n), k may be 0."""
        steps = self.segment_steps(a, b)
        return a + bisection_order(steps)[:, None] / steps * (b - a)

    def segment_free(self, a: np.ndarray, b: np.ndarray) -> bool:
        """The straight joint-space segment from ``a`` to ``b`` is free at :attr:`resolution_rad` (the ends are not checked)."""
        return all(self.free(q) for q in self.segment_configurations(a, b))

    def close(self) -> None:
        """Disconnect PyBullet."""
        self._sim.close()

    def __enter__(self) -> "CollisionChecker":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
