"""The collision shapes of the robot and the scene as segments and boxes, and their compiled checks.

What :class:`~dualarm.plan.collision.CollisionChecker` evaluates over many configurations per call.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar

import casadi as cs
import numpy as np

from dualarm.model.poses import pose_matrix
from dualarm.model.robot import Robot
from dualarm.numerics.compiled import compiled
from dualarm.plan.checker import CHUNK, COLLIDES, EXACT_SIZES, UNDECIDED, _attribute
from dualarm.plan.distances import distance_functions

#: PyBullet's collision margin of a box: its box is the half-extents less this, grown by a ball of
#: this radius (rounded edges and corners) [m].
BOX_ROUNDING_M = 0.001


@dataclass(frozen=True)
class _Segment:
    """A capsule's axis or a sphere's centre (``half_length_m`` 0) grown by ``radius_m`` [m].

    Of a robot link, whose ends are columns ``column`` and ``column + 1`` of the matrix of every
    link segment's ends (3 x 2S) in the robot's root frame, or of an object, ends ``ends_m`` (2, 3)
    [m] in that frame.

    ``moving``: some planned joint moves it. ``exact``: False for the bounding capsule of a
    cylinder, which PyBullet checks.
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
    """An object's box: the pose of its centre (4x4) and PyBullet's inner half-extents.

    The inner half-extents are the box's less :data:`BOX_ROUNDING_M` [m].
    """

    owner: str
    pose: tuple[tuple[float, ...], ...]
    half_extents_m: tuple[float, ...]
    moving: ClassVar[bool] = False
    exact: ClassVar[bool] = True

    def frame(self) -> tuple[cs.DM, cs.DM, cs.DM]:
        """Rotation, centre and inner half-extents as CasADi constants."""
        T = np.array(self.pose)
        return cs.DM(T[:3, :3]), cs.DM(T[:3, 3]), cs.DM(self.half_extents_m)


#: A checked pair of shapes: the pair's names (robot link, object; or two links, sorted), a robot
#: link's shape, the other shape, the threshold [m].
_Pair = tuple[tuple[str, str], _Segment, "_Segment | _Box", float]


def _robot_shapes(
    robot: Robot, frames: Mapping[str, cs.SX], q: cs.SX
) -> tuple[dict[str, list[_Segment] | None], cs.SX]:
    """The robot's links with collision shapes, and the matrix of the segments' ends (3 x 2S).

    Each link's capsules and spheres as segments, or None when it has another shape (a mesh, box or
    cylinder); the ends in the root frame, SX of ``q`` (``frames``: the links' frames).
    """
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
    """A task's object as a box, a sphere's centre, or a cylinder's bounding capsule.

    The object: :class:`~dualarm.tasks.schema.EnvironmentObject`.
    """
    T = pose_matrix(obj.pose.position, obj.pose.rpy)
    if obj.shape == "box":
        return _Box(obj.name, tuple(map(tuple, T)), tuple(float(s) / 2 - BOX_ROUNDING_M for s in obj.size_m))
    half = obj.height_m / 2 if obj.shape == "cylinder" else 0.0
    ends = tuple(tuple(T[:3, 3] + z * T[:3, 2]) for z in (-half, half))
    return _Segment(obj.name, float(obj.radius_m), half, ends_m=ends, exact=obj.shape != "cylinder")


def _distance(a: _Segment, b: _Segment | _Box, E):
    """Signed distance of the shapes ``a`` and ``b`` [m], the ends matrix ``E`` (SX, MX or DM) given.

    For a cylinder, of its bounding capsule.
    """
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
    """The broad phase: whether the bounding sphere of ``a`` comes within ``threshold_m`` [m] of ``b``.

    Of the bounding sphere of ``b``, or of box ``b``; when not, the pair is at least that far apart.
    """
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
    """The mid phase of a box pair: the box's faces as separating axes.

    Whether the extent of segment ``a`` along each axis of box ``b`` comes within ``threshold_m``
    [m] of the box's; when not, the pair is at least that far apart.
    """
    p, q = a.ends(E)
    R, c, h = b.frame()
    x, y = R.T @ (p - c), R.T @ (q - c)
    return cs.mmax(cs.fmax(cs.fmin(x, y) - h, -h - cs.fmax(x, y))) < a.radius_m + BOX_ROUNDING_M + threshold_m


def _compiled_checks(q: cs.SX, ends: cs.SX, pairs: list[_Pair], otherwise: int) -> cs.Function:
    """``q -> [d; verdict]``: the signed distance of each pair [m], and the configuration's verdict.

    A distance where the broad phase keeps the pair (+inf elsewhere). The verdict: :data:`COLLIDES`
    when an exact pair is closer than its threshold, else :data:`UNDECIDED` when a bounded one is,
    else ``otherwise`` (from the pairs no planned joint moves).

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
    exact_clearance = cs.mmin(
        cs.vertcat(cs.MX(cs.inf), *[dk - t for dk, (_, _, b, t) in zip(d, pairs, strict=True) if b.exact])
    )
    bounded_clearance = cs.mmin(
        cs.vertcat(cs.MX(cs.inf), *[dk - t for dk, (_, _, b, t) in zip(d, pairs, strict=True) if not b.exact])
    )
    verdict = cs.if_else(exact_clearance < 0, COLLIDES, cs.if_else(bounded_clearance < 0, UNDECIDED, otherwise))
    narrow = cs.Function("narrow", [E, keep], [cs.vertcat(*d, verdict)])
    return compiled(cs.Function("collision_checks", [x], [narrow(*broad(x))]))


class _Mapped:
    """A Function of one column to one column evaluated over many inputs. Not thread-safe.

    In maps of :data:`EXACT_SIZES` sizes and of powers of two up to :data:`CHUNK` (so few maps are
    built, each at most twice the work), each called through a FunctionBuffer on arrays allocated
    once (a plain call costs ~30 µs, :class:`~dualarm.numerics.batched.Batched`'s ~20 µs). Not
    thread-safe: one set of arrays per size.
    """

    def __init__(self, function: cs.Function):
        self.function = function
        self._m = function.numel_out(0)
        self._maps: dict[int, tuple] = {}

    def __call__(self, X: np.ndarray) -> np.ndarray:
        """The outputs (N, m) of inputs ``X`` (N, n).

        A view of the output buffer up to :data:`CHUNK` inputs (valid until the next call).
        """
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
