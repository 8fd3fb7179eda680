"""Closed-form distances between points, segments and boxes, as CasADi expressions.

A capsule is a segment grown by its radius and a sphere a point grown by its radius, so the
distance between two of them is the distance between their segments (or points) less both radii,
and a capsule's or sphere's distance to a box is its segment's (or point's) signed distance to the
box less its radius. Every function here is exact (no iteration, no tolerance): its operations
are those of the closed form, and it branches only through ``if_else`` (which compiles to a
select, unlike ``fmin``/``fmax``, which compile to calls into the C library).

Boxes are centred at the origin of their own frame, axis-aligned, given by their half-extents; a
point or segment is given in that frame. The signed distance to a box is negative inside it: minus
the penetration depth, the shortest translation that separates the two (as PyBullet reports it).
"""

from __future__ import annotations

from functools import cache

import casadi as cs

#: Compare-exchange pairs that sort six values (Knuth's optimal network of 12 comparators).
SORT_SIX = ((0, 5), (1, 3), (2, 4), (1, 2), (3, 4), (0, 3), (2, 5), (0, 1), (2, 3), (4, 5), (1, 2), (3, 4))


def smaller(a, b):
    """The smaller of ``a`` and ``b``."""
    return cs.if_else(a < b, a, b)


def larger(a, b):
    """The larger of ``a`` and ``b``."""
    return cs.if_else(a < b, b, a)


def clip(x, lo, hi):
    """``x`` limited to [lo, hi]."""
    return smaller(larger(x, lo), hi)


def point_point_distance(p: cs.SX, q: cs.SX) -> cs.SX:
    """Distance between points ``p`` and ``q`` (3-vectors) [m]."""
    return cs.norm_2(p - q)


def point_segment_distance(p: cs.SX, a: cs.SX, b: cs.SX) -> cs.SX:
    """Distance from point ``p`` to the segment from ``a`` to ``b`` (of non-zero length) [m]."""
    d = b - a
    t = clip(cs.dot(p - a, d) / cs.dot(d, d), 0, 1)
    return cs.norm_2(a + t * d - p)


def segment_segment_distance(p1: cs.SX, q1: cs.SX, p2: cs.SX, q2: cs.SX) -> cs.SX:
    """Distance between the segments ``p1``-``q1`` and ``p2``-``q2`` (both of non-zero length) [m].

    Ericson, Real-Time Collision Detection (2005), 5.1.9: the closest points of the two lines,
    clamped to the first segment, the second's parameter for that point, clamped, and the first's
    recomputed for it; parallel segments take the first's start.
    """
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e, f = cs.dot(d1, d1), cs.dot(d2, d2), cs.dot(d2, r)
    b, c = cs.dot(d1, d2), cs.dot(d1, r)
    denominator = a * e - b * b
    s = cs.if_else(denominator > 0, clip((b * f - c * e) / denominator, 0, 1), 0)
    t = (b * s + f) / e
    s = cs.if_else(t < 0, clip(-c / a, 0, 1), cs.if_else(t > 1, clip((b - c) / a, 0, 1), s))
    t = clip(t, 0, 1)
    return cs.norm_2(p1 + s * d1 - (p2 + t * d2))


def point_box_distance(p: cs.SX, h: cs.SX) -> cs.SX:
    """Signed distance from point ``p`` to the box of half-extents ``h`` [m].

    Negative inside: minus the distance to the nearest face.
    """
    outside = p - clip(p, -h, h)
    depth = _minimum([h[i] - cs.fabs(p[i]) for i in range(3)])
    return cs.if_else(depth > 0, -depth, cs.norm_2(outside))


def segment_box_distance(p: cs.SX, q: cs.SX, h: cs.SX) -> cs.SX:
    """Signed distance from the segment ``p``-``q`` to the box of half-extents ``h`` [m].

    Negative when they overlap: minus the penetration depth.

    Apart: the squared distance from the point ``p + t (q - p)`` to the box is a convex, piecewise
    quadratic function of t whose pieces end where the point crosses a face's plane (six values of
    t). Its half-derivative ``g(t)`` is continuous, piecewise linear and non-decreasing, so the
    minimiser on [0, 1] is the length of the set where ``g < 0``: the sum, over the pieces between
    the sorted crossings, of each piece's length times the share of it where its linear ``g`` is
    negative.

    Overlapping: separating axes. The Minkowski difference of the box and the segment is a convex
    polytope whose face normals are the box's axes and the cross products of the segment with
    them; the overlap along a normal n is ``h.|n| - min(n.p, n.q)`` (and with -n), the sets overlap
    exactly when every overlap is positive, and the penetration depth is the smallest.
    """
    d = q - p

    def excess(t):
        x = p + t * d
        return x - clip(x, -h, h)

    crossings = []
    for i in range(3):
        inverse = cs.if_else(d[i] != 0, 1 / d[i], 0)
        crossings += [clip((-h[i] - p[i]) * inverse, 0, 1), clip((h[i] - p[i]) * inverse, 0, 1)]
    for i, j in SORT_SIX:
        crossings[i], crossings[j] = smaller(crossings[i], crossings[j]), larger(crossings[i], crossings[j])
    ends = [0, *crossings, 1]
    slopes = [cs.dot(excess(t), d) for t in ends]  # g at each end
    t = 0
    for k in range(7):
        t += (ends[k + 1] - ends[k]) * clip(-slopes[k] / larger(slopes[k + 1] - slopes[k], 1e-300), 0, 1)
    apart = cs.norm_2(excess(t))
    overlaps = [h[i] - smaller(p[i], q[i]) for i in range(3)] + [h[i] + larger(p[i], q[i]) for i in range(3)]
    for i in range(3):
        n = cs.cross(d, cs.DM.eye(3)[:, i])
        length = cs.norm_2(n)
        overlaps.append(cs.if_else(length > 0, (cs.dot(cs.fabs(n), h) - cs.fabs(cs.dot(n, p))) / length, cs.inf))
    depth = _minimum(overlaps)
    return cs.if_else(depth > 0, -depth, apart)


def _minimum(values: list) -> cs.SX:
    """The smallest of ``values``."""
    out = values[0]
    for v in values[1:]:
        out = smaller(out, v)
    return out


@cache
def distance_functions() -> dict[str, cs.Function]:
    """The distances as CasADi Functions of 3-vectors.

    A box is given by its rotation R (3x3), centre c and half-extents h.

    ``point_point(p, q)``, ``point_segment(p, a, b)``, ``segment_segment(p1, q1, p2, q2)``,
    ``point_box(p, R, c, h)``, ``segment_box(p, q, R, c, h)``.
    """
    p, q, a, b = (cs.SX.sym(name, 3) for name in "pqab")
    R, c, h = cs.SX.sym("R", 3, 3), cs.SX.sym("c", 3), cs.SX.sym("h", 3)
    local = R.T @ (p - c), R.T @ (q - c)
    return {
        "point_point": cs.Function("point_point", [p, q], [point_point_distance(p, q)]),
        "point_segment": cs.Function("point_segment", [p, a, b], [point_segment_distance(p, a, b)]),
        "segment_segment": cs.Function("segment_segment", [p, q, a, b], [segment_segment_distance(p, q, a, b)]),
        "point_box": cs.Function("point_box", [p, R, c, h], [point_box_distance(local[0], h)]),
        "segment_box": cs.Function("segment_box", [p, q, R, c, h], [segment_box_distance(*local, h)]),
    }
