"""Collision checking of configurations and joint-space segments for the planners.

A configuration is free exactly when every checked robot link keeps ``margin_m`` from every
object of the task and ``2 margin_m`` from every other checked link. Pairs not checked: those that
touch by construction, one list shared with the execute stage
(:func:`~dualarm.sim.world.disable_touching_pairs`), and the task's expected contacts.

:class:`CollisionChecker` computes the distances in closed form, many configurations at once. The
humanoid's collision shapes are capsules (arms, torso, pelvis) and a sphere (head), a task's
objects boxes, cylinders and spheres. A capsule is a segment grown by its radius and a sphere a
point grown by its radius, so two of them are apart by the distance of their segments or centres
less both radii, and one is apart from a box by its segment's signed distance to the box less its
radius (:mod:`.distances`, exact). A box is PyBullet's box: its edges and corners rounded by
PyBullet's collision margin (:data:`BOX_ROUNDING_M`). One compiled CasADi call
(:func:`dualarm.numerics.compiled.compiled`) per batch of configurations computes, for each, the forward
kinematics of every shape, a broad phase (the bounding spheres of the two shapes, or a bounding
sphere and the box, closer than the pair's threshold) and the exact distance only of the pairs the
broad phase keeps (a conditional: the others cost nothing more). Pairs that no planned joint
moves (the pelvis and the table) are computed once. Where nothing can be compiled, CasADi's
virtual machine runs the same Function, with the same results, about 1.4 times as long as
PyBullet's check (measured in one run).

Shapes without a closed form here are checked by PyBullet, pair by pair, with its closest points on
the inflated robot (:meth:`PyBulletChecker.overlaps`, a query that keeps no state between calls, so
that a verdict does not depend on the configurations checked before): a cylinder object in the
configurations where its bounding capsule (its axis grown by its radius) comes within the margin,
and a robot link whose shape is a mesh, box or cylinder in every configuration.

:class:`PyBulletChecker` is the reference, the checker the planners used before: PyBullet's own
narrow phase (exact convex distance, GJK/EPA) on a copy of the robot whose every collision shape is
inflated by the margin: the URDF is rewritten with each capsule's, sphere's and cylinder's radius
(and each box's half-extents) grown by ``margin_m``. One check teleports the joints
(``resetJointStatesMultiDof``), runs ``performCollisionDetection`` (the broad phase prefilters the
pairs by their bounding boxes) and reads the contact points with a negative distance.

Segments are checked at configurations spaced at most ``resolution_rad`` apart in every joint
(the max-norm), end points excluded (a tree's nodes are checked when they are made), in one batch.
"""

from __future__ import annotations

import itertools
import tempfile
import time
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import ClassVar

import casadi as cs
import numpy as np

from dualarm.errors import InvalidArgumentError, StageError
from dualarm.model.kinematics import link_frames
from dualarm.model.poses import pose_matrix
from dualarm.model.robot import Robot
from dualarm.numerics.compiled import compiled
from dualarm.plan.distances import distance_functions
from dualarm.sim.world import add_environment, disable_touching_pairs, in_contact, load_pybullet_robot, pb

#: PyBullet's collision margin of a box: its box is the half-extents less this, grown by a ball of this radius (rounded edges and corners) [m].
BOX_ROUNDING_M = 0.001
#: Most configurations in one compiled call, and most for which a call of their own number is built (more are rounded up to a power of two).
CHUNK, EXACT_SIZES = 1024, 32
#: The compiled verdict of a configuration: in collision, free, or up to PyBullet (a pair without a closed form is near).
COLLIDES, FREE, UNDECIDED = 0, 1, 2


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


@cache
def bisection_order(steps: int) -> np.ndarray:
    """The integers 1 .. steps - 1 in bisection order: the middle first, then the middles of the two halves, and so on (each once); read-only."""
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
    out = np.array(order, dtype=float)
    out.setflags(write=False)
    return out


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


class _Checker:
    """What both checkers share: the settings, the counters, the segments, the context manager.

    Attributes:
        joint_names: the planned joints, the order of every configuration.
        margin_m: safety margin [m] (see the module docstring).
        resolution_rad: largest joint step between the configurations checked along a segment [rad].
        checks: configurations checked so far.
        check_time_s: time spent in checks so far [s].
        unchecked_pairs: the robot's link pairs (sorted names) that touch by construction.
    """

    unchecked_pairs: frozenset[tuple[str, str]]

    def __init__(self, joint_names: Sequence[str], margin_m: float, resolution_rad: float):
        if not (np.isfinite(margin_m) and margin_m >= 0):
            raise StageError(
                f"collision checking: the safety margin must be a non-negative number of metres, not {margin_m}"
            )
        if not (np.isfinite(resolution_rad) and resolution_rad > 0):
            raise StageError(
                f"collision checking: the segment resolution must be a positive number of radians, not {resolution_rad}"
            )
        self.joint_names = tuple(joint_names)
        self.margin_m = float(margin_m)
        self.resolution_rad = float(resolution_rad)
        self.checks = 0
        self.check_time_s = 0.0

    def free_many(self, Q: np.ndarray) -> np.ndarray:
        """For each configuration of ``Q`` (N, n) [rad], whether no checked pair is closer than the margin; (N,) bool."""
        raise NotImplementedError

    def contacts(self, q: np.ndarray) -> list[Contact]:
        """Every checked pair closer than the margin at ``q`` [rad], deepest first."""
        raise NotImplementedError

    def free(self, q: np.ndarray) -> bool:
        """No checked pair is closer than the margin at ``q`` [rad]."""
        raise NotImplementedError

    def segment_steps(self, a: np.ndarray, b: np.ndarray) -> int:
        """Into how many equal steps the segment from ``a`` to ``b`` [rad] is cut so that no joint moves more than :attr:`resolution_rad` in one (at least 1)."""
        return max(1, int(np.ceil(np.abs(b - a).max() / self.resolution_rad)))

    def segment_configurations(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """The configurations checked strictly between ``a`` and ``b`` [rad], evenly spaced at most :attr:`resolution_rad` apart in every joint, in bisection order (the midpoint, then the quarter points, ...); (k, n), k may be 0."""
        steps = self.segment_steps(a, b)
        return a + bisection_order(steps)[:, None] / steps * (b - a)

    def segment_free(self, a: np.ndarray, b: np.ndarray) -> bool:
        """The straight joint-space segment from ``a`` to ``b`` is free at :attr:`resolution_rad` (the ends are not checked), its configurations checked in one batch."""
        return bool(self.free_many(self.segment_configurations(a, b)).all())

    def _configurations(self, Q: np.ndarray) -> np.ndarray:
        """``Q`` as an (N, n) float array; InvalidArgumentError otherwise."""
        Q = np.ascontiguousarray(Q, dtype=float)
        if Q.ndim != 2 or Q.shape[1] != len(self.joint_names):
            raise InvalidArgumentError(
                "Q", f"expected configurations of shape (N, {len(self.joint_names)}), got {Q.shape}"
            )
        return Q

    def close(self) -> None:
        """Release PyBullet."""
        raise NotImplementedError

    def __enter__(self):
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class PyBulletChecker(_Checker):
    """Checks configurations of ``joint_names`` (the others at ``fixed``) with PyBullet's narrow phase on the inflated robot (module docstring), one at a time.

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
        self.unchecked_pairs = disable_touching_pairs(sim, self.margin_m)
        sim.set_positions(list(fixed), list(fixed.values()))
        self._objects = add_environment(sim, environment)
        self._link_name = {i: n for n, i in sim.link_index.items()}
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
                    f"collision checking: allowed contact ({a}, {b}): '{other}' is neither a robot link nor an object of the task"
                )

    def overlaps(self, q: np.ndarray, pairs: Sequence[tuple[str, str]]) -> dict[tuple[str, str], float]:
        """How deep [m] each of ``pairs`` (a robot link, another link or an object) of the inflated robot overlaps at ``q`` [rad], by PyBullet's closest points (a query that keeps no state between calls, unlike the contact points); the pairs apart are left out. Not a check (neither counted nor timed)."""
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


@dataclass(frozen=True)
class _Segment:
    """A capsule's axis or a sphere's centre (``half_length_m`` 0) grown by ``radius_m`` [m]: of a robot link, whose ends are columns ``column`` and ``column + 1`` of the matrix of every link segment's ends (3 x 2S) in the robot's root frame, or of an object, ends ``ends_m`` (2, 3) [m] in that frame.

    ``moving``: some planned joint moves it. ``exact``: False for the bounding capsule of a cylinder, which PyBullet checks.
    """

    owner: str
    radius_m: float
    half_length_m: float
    column: int = -1
    ends_m: tuple[tuple[float, ...], ...] = ()
    moving: bool = False
    exact: bool = True

    def ends(self, E):
        """Its two ends (3-vectors), given the ends matrix ``E`` (SX, MX or DM)."""
        if self.column < 0:
            return cs.DM(self.ends_m[0]), cs.DM(self.ends_m[1])
        return E[:, self.column], E[:, self.column + 1]


@dataclass(frozen=True)
class _Box:
    """An object's box: the pose of its centre (4x4) and PyBullet's inner half-extents, the box's less :data:`BOX_ROUNDING_M` [m]."""

    owner: str
    pose: tuple[tuple[float, ...], ...]
    half_extents_m: tuple[float, ...]
    moving: ClassVar[bool] = False
    exact: ClassVar[bool] = True

    def frame(self) -> tuple[cs.DM, cs.DM, cs.DM]:
        """Rotation, centre and inner half-extents as CasADi constants."""
        T = np.array(self.pose)
        return cs.DM(T[:3, :3]), cs.DM(T[:3, 3]), cs.DM(self.half_extents_m)


#: A checked pair of shapes: the pair's names (robot link, object; or two links, sorted), a robot link's shape, the other shape, the threshold [m].
_Pair = tuple[tuple[str, str], _Segment, "_Segment | _Box", float]


def _robot_shapes(
    robot: Robot, frames: Mapping[str, cs.SX], q: cs.SX
) -> tuple[dict[str, list[_Segment] | None], cs.SX]:
    """The robot's links with collision shapes: each one's capsules and spheres as segments, or None when it has another shape (a mesh, box or cylinder); and the matrix of the segments' ends (3 x 2S) in the root frame, SX of ``q`` (``frames``: the links' frames)."""
    shapes: dict[str, list[_Segment] | None] = {}
    ends: list[cs.SX] = []
    for link in ET.parse(robot.urdf.path).getroot().iter("link"):
        name = link.get("name", "")
        for collision in link.findall("collision"):
            origin = collision.find("origin")
            xyz, rpy = (
                [float(v) for v in origin.get(key, "0 0 0").split()] if origin is not None else [0.0] * 3
                for key in ("xyz", "rpy")
            )
            geometry = collision.find("geometry")
            shape = geometry[0] if geometry is not None and len(geometry) else None
            if shape is None or shape.tag not in ("capsule", "sphere") or shapes.get(name, []) is None:
                shapes[name] = None
                continue
            T = frames[name] @ pose_matrix(xyz, rpy)
            half = float(_attribute(shape, "length")) / 2 if shape.tag == "capsule" else 0.0
            two = [T[:3, :3] @ np.array([0.0, 0.0, z]) + T[:3, 3] for z in (-half, half)]
            segment = _Segment(
                name,
                float(_attribute(shape, "radius")),
                half,
                column=len(ends),
                moving=bool(cs.depends_on(cs.vertcat(*two), q)),
            )
            ends += two
            shapes.setdefault(name, []).append(segment)  # type: ignore[union-attr]
    return shapes, cs.horzcat(*ends) if ends else cs.SX(3, 0)


def _object_shape(obj) -> _Segment | _Box:
    """A task's object (:class:`~dualarm.tasks.schema.EnvironmentObject`) as a box, a sphere's centre, or a cylinder's bounding capsule."""
    T = pose_matrix(obj.pose.position, obj.pose.rpy)
    if obj.shape == "box":
        return _Box(obj.name, tuple(map(tuple, T)), tuple(float(s) / 2 - BOX_ROUNDING_M for s in obj.size_m))
    half = obj.height_m / 2 if obj.shape == "cylinder" else 0.0
    ends = tuple(tuple(T[:3, 3] + z * T[:3, 2]) for z in (-half, half))
    return _Segment(obj.name, float(obj.radius_m), half, ends_m=ends, exact=obj.shape != "cylinder")


def _distance(a: _Segment, b: _Segment | _Box, E):
    """Signed distance of the shapes ``a`` and ``b`` [m] (for a cylinder, of its bounding capsule), the ends matrix ``E`` (SX, MX or DM) given."""
    f = distance_functions()
    p, q = a.ends(E)
    if isinstance(b, _Box):
        apart = f["point_box"](p, *b.frame()) if a.half_length_m == 0 else f["segment_box"](p, q, *b.frame())
        return apart - a.radius_m - BOX_ROUNDING_M
    r, s = b.ends(E)
    if a.half_length_m == 0:
        apart = f["point_point"](p, r) if b.half_length_m == 0 else f["point_segment"](p, r, s)
    else:
        apart = f["point_segment"](r, p, q) if b.half_length_m == 0 else f["segment_segment"](p, q, r, s)
    return apart - a.radius_m - b.radius_m


def _near(a: _Segment, b: _Segment | _Box, E: cs.SX, threshold_m: float) -> cs.SX:
    """The broad phase: whether the bounding sphere of ``a`` comes within ``threshold_m`` [m] of that of ``b``, or of box ``b``; when not, the pair is at least that far apart."""
    p, q = a.ends(E)
    centre, reach = (p + q) / 2, a.radius_m + a.half_length_m + threshold_m
    if isinstance(b, _Box):
        R, c, h = b.frame()
        beyond = cs.fabs(R.T @ (centre - c)) - h
        outside = cs.if_else(beyond > 0, beyond, 0)
        reach += BOX_ROUNDING_M
    else:
        r, s = b.ends(E)
        outside = centre - (r + s) / 2
        reach += b.radius_m + b.half_length_m
    return cs.dot(outside, outside) < reach**2


def _slab_near(a: _Segment, b: _Box, E: cs.MX, threshold_m: float) -> cs.MX:
    """The mid phase of a box pair: whether the extent of segment ``a`` along each axis of box ``b`` comes within ``threshold_m`` [m] of the box's (the box's faces as separating axes); when not, the pair is at least that far apart."""
    p, q = a.ends(E)
    R, c, h = b.frame()
    x, y = R.T @ (p - c), R.T @ (q - c)
    return cs.mmax(cs.fmax(cs.fmin(x, y) - h, -h - cs.fmax(x, y))) < a.radius_m + BOX_ROUNDING_M + threshold_m


def _compiled_checks(q: cs.SX, ends: cs.SX, pairs: list[_Pair], otherwise: int) -> cs.Function:
    """``q -> [d; verdict]``: the signed distance of each pair [m] where the broad phase keeps it (+inf elsewhere), and the configuration's verdict: :data:`COLLIDES` when an exact pair is closer than its threshold, else :data:`UNDECIDED` when a bounded one is, else ``otherwise`` (from the pairs no planned joint moves).

    One Function, compiled: the broad phase over the forward kinematics, then one conditional per
    pair (and for a box, a second one after the mid phase).
    """
    x = cs.MX.sym("q", q.numel())
    if not pairs:
        return cs.Function("collision_checks", [x], [cs.MX(otherwise)])
    broad = cs.Function("broad", [q], [ends, cs.vertcat(*[_near(a, b, ends, t) for _, a, b, t in pairs])])
    E, keep = cs.MX.sym("ends", *ends.shape), cs.MX.sym("keep", len(pairs))
    d = []
    for k, (_, a, b, t) in enumerate(pairs):
        exact = _distance(a, b, E)
        if isinstance(b, _Box):
            exact = cs.if_else(_slab_near(a, b, E, t), exact, cs.inf, True)
        d.append(cs.if_else(keep[k], exact, cs.inf, True))
    exact_clearance = cs.mmin(cs.vertcat(cs.MX(cs.inf), *[dk - t for dk, (_, _, b, t) in zip(d, pairs) if b.exact]))
    bounded_clearance = cs.mmin(
        cs.vertcat(cs.MX(cs.inf), *[dk - t for dk, (_, _, b, t) in zip(d, pairs) if not b.exact])
    )
    verdict = cs.if_else(exact_clearance < 0, COLLIDES, cs.if_else(bounded_clearance < 0, UNDECIDED, otherwise))
    narrow = cs.Function("narrow", [E, keep], [cs.vertcat(*d, verdict)])
    return compiled(cs.Function("collision_checks", [x], [narrow(*broad(x))]))


class _Mapped:
    """A Function of one column to one column evaluated over many inputs: in maps of :data:`EXACT_SIZES` sizes and of powers of two up to :data:`CHUNK` (so few maps are built, each at most twice the work), each called through a FunctionBuffer on arrays allocated once (a plain call costs ~30 µs, :class:`~dualarm.numerics.batched.Batched`'s ~20 µs). Not thread-safe: one set of arrays per size."""

    def __init__(self, function: cs.Function):
        self.function = function
        self._m = function.numel_out(0)
        self._maps: dict[int, tuple] = {}

    def __call__(self, X: np.ndarray) -> np.ndarray:
        """The outputs (N, m) of inputs ``X`` (N, n), a view of the output buffer up to :data:`CHUNK` inputs (valid until the next call)."""
        m = self._m
        if not len(X):
            return np.empty((0, m))
        if len(X) <= CHUNK:
            run, x, y = self._map(len(X))
            x[: X.size] = X.ravel()  # column-major (n, size): one input after another
            run()
            return y[: len(X) * m].reshape(-1, m)
        return np.concatenate([self(X[start : start + CHUNK]).copy() for start in range(0, len(X), CHUNK)])

    def _map(self, count: int) -> tuple:
        """The map for ``count`` inputs: of that size up to :data:`EXACT_SIZES`, else of the next power of two."""
        size = count if count <= EXACT_SIZES else 1 << (count - 1).bit_length()
        if size not in self._maps:
            mapped = self.function.map(size, "serial")
            buffer, run = mapped.buffer()
            x, y = np.zeros(mapped.numel_in(0)), np.zeros(mapped.numel_out(0))
            buffer.set_arg(0, x.data)
            buffer.set_res(0, y.data)
            self._maps[size] = (run, x, y, buffer)
        return self._maps[size][:3]


class CollisionChecker(_Checker):
    """Checks configurations of ``joint_names`` (the others at ``fixed``) against self-collision and the task's fixed objects, with a safety margin, in closed form and in batches (module docstring).

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
        self._pybullet = PyBulletChecker(
            robot, joint_names, fixed, environment, allowed_contacts, margin_m, resolution_rad
        )
        self.unchecked_pairs = self._pybullet.unchecked_pairs
        try:
            self._build(
                robot,
                fixed,
                [_object_shape(obj) for obj in environment],
                {frozenset(pair) for pair in allowed_contacts},
            )
        except BaseException:
            self.close()
            raise

    def _build(
        self, robot: Robot, fixed: Mapping[str, float], objects: list[_Segment | _Box], allowed: set[frozenset[str]]
    ) -> None:
        """The checked pairs, the contacts of those no planned joint moves, and the compiled Function of the others."""
        q = cs.SX.sym("q", len(self.joint_names))
        shapes, ends = _robot_shapes(
            robot,
            link_frames(robot.urdf.joints, robot.urdf.root, {**fixed, **dict(zip(self.joint_names, cs.vertsplit(q)))}),
            q,
        )
        checked: list[tuple[tuple[str, str], float, list[_Segment] | None, Sequence[_Segment | _Box] | None]] = [
            ((a, b), 2 * self.margin_m, shapes[a], shapes[b])
            for a, b in itertools.combinations(sorted(shapes), 2)
            if (a, b) not in self.unchecked_pairs and frozenset((a, b)) not in allowed
        ]
        checked += [
            ((link, obj.owner), self.margin_m, shapes[link], [obj])
            for link in shapes
            for obj in objects
            if frozenset((link, obj.owner)) not in allowed
        ]
        self._pybullet_pairs = [
            names for names, _, first, second in checked if first is None or second is None
        ]  # of a link without a closed form: PyBullet's in every configuration
        pairs: list[_Pair] = [
            (names, a, b, threshold)
            for names, threshold, first, second in checked
            if first and second
            for a in first
            for b in second
        ]
        moving = [pair for pair in pairs if pair[1].moving or pair[2].moving]
        constant_ends = cs.Function("ends", [q], [ends])(np.zeros(q.numel()))
        self._constant_contacts: dict[tuple[str, str], float] = {}
        for names, a, b, threshold in (pair for pair in pairs if pair not in moving):
            d = float(_distance(a, b, constant_ends))
            if d < threshold:
                depth = (
                    threshold - d if b.exact else self._pybullet.overlaps(np.zeros(q.numel()), [names]).get(names, 0.0)
                )
                if depth > 0:
                    self._constant_contacts[names] = max(self._constant_contacts.get(names, 0.0), depth)
        self._names = [names for names, *_ in moving]
        self._threshold_m = np.array([threshold for *_, threshold in moving])
        self._exact = np.array([b.exact for _, _, b, _ in moving], dtype=bool)
        self._undecidable = bool(self._pybullet_pairs) or not self._exact.all()  # a verdict may be UNDECIDED
        otherwise = COLLIDES if self._constant_contacts else UNDECIDED if self._pybullet_pairs else FREE
        self._compiled = _Mapped(_compiled_checks(q, ends, moving, otherwise))

    @property
    def pairs(self) -> list[tuple[str, str]]:
        """The checked pairs of shapes some planned joint moves, the columns of :meth:`distances`: (robot link, object), or two robot links in sorted order."""
        return list(self._names)

    def distances(self, Q: np.ndarray) -> np.ndarray:
        """Signed distances [m] of :attr:`pairs` at each configuration of ``Q`` (N, n) [rad]; (N, P).

        Exact wherever the broad phase keeps the pair (always when it is closer than its threshold),
        +inf where it does not; for a cylinder object, the distance to its bounding capsule. Not a
        check (neither counted nor timed).
        """
        return self._compiled(self._configurations(Q))[:, :-1].copy()

    def free_many(self, Q: np.ndarray) -> np.ndarray:
        """For each configuration of ``Q`` (N, n) [rad], whether no checked pair is closer than the margin; (N,) bool."""
        started = time.perf_counter()
        Q = self._configurations(Q)
        out = self._compiled(Q)
        free = out[:, -1] == FREE
        if self._undecidable and not free.all():
            for i in np.flatnonzero(out[:, -1] == UNDECIDED):
                free[i] = self._decide(Q[i], out[i])
        self.checks += len(Q)
        self.check_time_s += time.perf_counter() - started
        return free

    def free(self, q: np.ndarray) -> bool:
        """No checked pair is closer than the margin at ``q`` [rad] (:meth:`free_many` of one configuration, without its array operations)."""
        started = time.perf_counter()
        q = np.asarray(q, dtype=float)
        free = self._decide(q, self._compiled(self._configurations(q[None]))[0])
        self.checks += 1
        self.check_time_s += time.perf_counter() - started
        return free

    def _decide(self, q: np.ndarray, out: np.ndarray) -> bool:
        """Whether ``q`` [rad] is free, from its compiled distances and verdict ``out``; PyBullet decides an undecided one."""
        return bool(
            out[-1] == FREE or (out[-1] == UNDECIDED and not self._pybullet.overlaps(q, self._undecided(out[:-1])))
        )

    def _undecided(self, d: np.ndarray) -> list[tuple[str, str]]:
        """The pairs PyBullet decides at a configuration whose distances :attr:`pairs` are ``d`` [m]: those of a link without a closed form, and each cylinder whose bounding capsule is near."""
        return self._pybullet_pairs + [self._names[k] for k in np.flatnonzero((d < self._threshold_m) & ~self._exact)]

    def contacts(self, q: np.ndarray) -> list[Contact]:
        """Every checked pair closer than the margin at ``q`` [rad], deepest first."""
        started = time.perf_counter()
        q = np.asarray(q, dtype=float)
        d = self._compiled(self._configurations(q[None]))[0, :-1]
        deepest = dict(self._constant_contacts)
        for k in np.flatnonzero((d < self._threshold_m) & self._exact):
            deepest[self._names[k]] = max(deepest.get(self._names[k], 0.0), float(self._threshold_m[k] - d[k]))
        for pair, depth in self._pybullet.overlaps(q, self._undecided(d)).items():
            deepest[pair] = max(deepest.get(pair, 0.0), depth)
        self.checks += 1
        self.check_time_s += time.perf_counter() - started
        return sorted((Contact(a, b, depth) for (a, b), depth in deepest.items()), key=lambda c: -c.depth_m)

    def close(self) -> None:
        """Disconnect PyBullet."""
        self._pybullet.close()
