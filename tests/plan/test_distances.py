"""The closed-form distances (dualarm.plan.distances) against brute force: dense sampling along the
segments with the exact distance of a point, and, for a segment in a box, the overlap along a dense
set of directions."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dualarm.plan.distances import SORT_SIX, distance_functions

F = distance_functions()
#: Samples along a segment: the brute force is within (segment length) / SAMPLES of the distance.
SAMPLES = 100_001


def call(name: str, *args) -> float:
    return float(F[name](*args))


def along(p: np.ndarray, q: np.ndarray, n: int = SAMPLES) -> np.ndarray:
    return p + np.linspace(0.0, 1.0, n)[:, None] * (q - p)


def point_to_segment(x: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distances from the points ``x`` (N, 3) to the segment a-b, by projection."""
    d = b - a
    t = np.clip((x - a) @ d / (d @ d), 0.0, 1.0)
    return np.linalg.norm(a + t[:, None] * d - x, axis=1)


def point_to_box(x: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Distances from the points ``x`` (N, 3) to the box of half-extents ``h`` (0 inside)."""
    return np.linalg.norm(x - np.clip(x, -h, h), axis=1)


def box_pose(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    return Rotation.random(random_state=int(rng.integers(1 << 30))).as_matrix(), rng.normal(size=3) * 0.2


def segments(rng: np.random.Generator, count: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Random segments, a quarter of them short; some parallel to an axis (to a box's faces)."""
    out = []
    for k in range(count):
        p = rng.normal(size=3) * 0.4
        q = p + rng.normal(size=3) * (0.02 if k % 4 == 0 else 0.4)
        if k % 5 == 0:
            q[k % 3] = p[k % 3]
        out.append((p, q))
    return out


def test_the_sorting_network_sorts_six_values():
    for bits in range(64):  # the 0-1 principle: a network that sorts every 0/1 input sorts every input
        v = [(bits >> i) & 1 for i in range(6)]
        for i, j in SORT_SIX:
            v[i], v[j] = min(v[i], v[j]), max(v[i], v[j])
        assert v == sorted(v)


def test_segment_segment_against_dense_sampling():
    rng = np.random.default_rng(1)
    cases = [(p, q, *segments(rng, 1)[0]) for p, q in segments(rng, 60)]
    z, x = np.zeros(3), np.array([1.0, 0, 0])
    cases += [
        (z, x, np.array([0.5, 1, 0]), np.array([2.0, 1, 0])),  # parallel, overlapping: 1
        (z, x, np.array([2.0, 0, 0]), np.array([3.0, 0, 0])),  # collinear, apart: 1
        (z, x, np.array([0.5, -1, 0.2]), np.array([0.5, 1, 0.2])),  # crossing: 0.2
        (z, x, np.array([0.5, -1, 0.0]), np.array([0.5, 1, 0.0])),  # intersecting: 0
    ]
    for p1, q1, p2, q2 in cases:
        exact = call("segment_segment", p1, q1, p2, q2)
        assert exact == pytest.approx(call("segment_segment", p2, q2, p1, q1), abs=1e-12)  # symmetric
        brute = point_to_segment(along(p1, q1), p2, q2).min()
        assert exact <= brute + 1e-12
        assert brute - exact <= 2 * np.linalg.norm(q1 - p1) / SAMPLES + 1e-12
    assert [call("segment_segment", *c) for c in cases[-4:]] == pytest.approx([1.0, 1.0, 0.2, 0.0], abs=1e-15)


def test_point_distances_against_brute_force():
    rng = np.random.default_rng(2)
    for p, q in segments(rng, 40):
        x = rng.normal(size=3) * 0.4
        assert call("point_point", x, p) == pytest.approx(np.linalg.norm(x - p), abs=1e-15)
        brute = np.linalg.norm(along(p, q) - x, axis=1).min()
        exact = call("point_segment", x, p, q)
        assert exact <= brute + 1e-12 and brute - exact <= 2 * np.linalg.norm(q - p) / SAMPLES + 1e-12
        R, c = box_pose(rng)
        h = rng.uniform(0.02, 0.3, 3)
        local = R.T @ (x - c)
        inside = np.all(np.abs(local) < h)
        expected = -np.min(h - np.abs(local)) if inside else point_to_box(local[None], h)[0]
        assert call("point_box", x, R, c, h) == pytest.approx(expected, abs=1e-14)


def test_segment_box_apart_against_dense_sampling():
    rng = np.random.default_rng(3)
    apart = 0
    for p, q in segments(rng, 200):
        R, c = box_pose(rng)
        h = rng.uniform(0.02, 0.3, 3)
        brute = point_to_box(along(R.T @ (p - c), R.T @ (q - c)), h).min()
        exact = call("segment_box", p, q, R, c, h)
        if brute > 1e-3:  # apart (the overlapping ones are the next test's)
            apart += 1
            assert exact <= brute + 1e-12
            assert brute - exact <= 2 * np.linalg.norm(q - p) / SAMPLES + 1e-12
    assert apart >= 100


def penetration_by_directions(p: np.ndarray, q: np.ndarray, h: np.ndarray, directions: np.ndarray) -> float:
    """The smallest overlap of the segment and the box along any of ``directions`` (unit, (M, 3)): the shortest
    separating translation among them."""
    return float(np.min(np.abs(directions) @ h - np.minimum(directions @ p, directions @ q)))


def test_segment_box_overlapping_against_every_direction():
    """Overlapping: minus the penetration depth, the smallest overlap along any direction: no larger than along each of
    a dense set of directions, and equal to the overlap along one of the box's axes or their cross products with the
    segment (the polytope's face normals)."""
    rng = np.random.default_rng(4)
    directions = rng.normal(size=(200_000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    directions = np.vstack([directions, np.eye(3), -np.eye(3)])
    overlapping = 0
    for k in range(120):
        h = rng.uniform(0.05, 0.3, 3)
        p = rng.uniform(-h, h)  # one end inside the box
        q = p + rng.normal(size=3) * (0.05 if k % 3 else 0.5)
        if k % 7 == 0:
            q[k % 3] = p[k % 3]
        exact = call("segment_box", p, q, np.eye(3), np.zeros(3), h)
        assert exact < 0
        overlapping += 1
        assert -exact <= penetration_by_directions(p, q, h, directions) + 1e-12
        normals = [np.cross(q - p, axis) for axis in np.eye(3)]
        normals = np.vstack([np.eye(3), *[n / np.linalg.norm(n) for n in normals if np.linalg.norm(n) > 1e-12]])
        assert -exact == pytest.approx(penetration_by_directions(p, q, h, np.vstack([normals, -normals])), abs=1e-12)
    # a point in the box: the distance to the nearest face; a segment through it along x: the smaller of y, z
    h = np.array([0.3, 0.2, 0.1])
    assert call(
        "segment_box", np.array([0.1, 0.05, 0.0]), np.array([0.1, 0.05, 0.0]), np.eye(3), np.zeros(3), h
    ) == pytest.approx(-0.1)
    assert call(
        "segment_box", np.array([-1.0, 0.15, 0.05]), np.array([1.0, 0.15, 0.05]), np.eye(3), np.zeros(3), h
    ) == pytest.approx(-0.05)
    assert overlapping == 120
