"""What every collision checker of the planners shares: contacts, the inflated URDF, the edge order.

:class:`~dualarm.plan.collision.CollisionChecker` (closed form) and
:class:`~dualarm.plan.pybullet_checker.PyBulletChecker` (the reference) check configurations and
joint-space segments the same way (:class:`_Checker`).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache

import numpy as np

from dualarm.errors import InvalidArgumentError, StageError

#: Most configurations in one compiled call, and most for which a call of their own number is built
#: (more are rounded up to a power of two).
CHUNK, EXACT_SIZES = 1024, 32
#: The compiled verdict of a configuration: in collision, free, or up to PyBullet (a pair without a
#: closed form is near).
COLLIDES, FREE, UNDECIDED = 0, 1, 2


def inflated_urdf(text: str, margin_m: float) -> str:
    """The URDF ``text`` with every ``<collision>`` shape grown by ``margin_m`` [m] on every side."""
    root = ET.fromstring(text)
    for link, geometry in ((node, collision) for node in root.iter("link") for collision in node.iter("collision")):
        for shape in geometry.iter():
            if shape.tag in ("capsule", "sphere", "cylinder"):
                shape.set("radius", repr(float(_attribute(shape, "radius")) + margin_m))
                if shape.tag == "cylinder":
                    shape.set("length", repr(float(_attribute(shape, "length")) + 2 * margin_m))
            elif shape.tag == "box":
                shape.set("size", " ".join(repr(float(s) + 2 * margin_m) for s in _attribute(shape, "size").split()))
            elif shape.tag == "mesh":
                raise StageError(
                    f"collision checking: link '{link.get('name')}' collides as a mesh "
                    f"({shape.get('filename')}), which the planners' safety margin cannot inflate; "
                    "give its <collision> capsules, spheres, cylinders or "
                    "boxes (a run's execution checks the meshes themselves)"
                )
    return ET.tostring(root, encoding="unicode")


def mesh_collisions(text: str) -> bool:
    """Whether the URDF ``text`` has a ``<collision>`` mesh (which :func:`inflated_urdf` cannot grow)."""
    root = ET.fromstring(text)
    return any(collision.find(".//mesh") is not None for collision in root.iter("collision"))


def _attribute(shape: ET.Element, name: str) -> str:
    """The attribute ``name`` of a URDF collision shape, which URDF requires of it."""
    value = shape.get(name)
    if value is None:
        raise StageError(f"collision checking: a <{shape.tag}> collision shape has no '{name}' attribute")
    return value


@cache
def bisection_order(steps: int) -> np.ndarray:
    """The integers 1 .. steps - 1 in bisection order, each once; read-only.

    The middle first, then the middles of the two halves, and so on.
    """
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
        unchecked_pairs: the robot's link pairs (sorted names) not checked
            (:func:`~dualarm.sim.world.disable_unchecked_pairs`).
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
        """For each configuration of ``Q`` (N, n) [rad], whether no checked pair is closer than the margin.

        Returns (N,) bool.
        """
        raise NotImplementedError

    def contacts(self, q: np.ndarray) -> list[Contact]:
        """Every checked pair closer than the margin at ``q`` [rad], deepest first."""
        raise NotImplementedError

    def free(self, q: np.ndarray) -> bool:
        """No checked pair is closer than the margin at ``q`` [rad]."""
        raise NotImplementedError

    def segment_steps(self, a: np.ndarray, b: np.ndarray) -> int:
        """Into how many equal steps (at least 1) the segment from ``a`` to ``b`` [rad] is cut.

        So that no joint moves more than :attr:`resolution_rad` in one.
        """
        return max(1, int(np.ceil(np.abs(b - a).max() / self.resolution_rad)))

    def segment_configurations(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """The configurations checked strictly between ``a`` and ``b`` [rad]; (k, n), k may be 0.

        Evenly spaced at most :attr:`resolution_rad` apart in every joint, in bisection order (the
        midpoint, then the quarter points, ...).
        """
        steps = self.segment_steps(a, b)
        return a + bisection_order(steps)[:, None] / steps * (b - a)

    def segment_free(self, a: np.ndarray, b: np.ndarray) -> bool:
        """The straight joint-space segment from ``a`` to ``b`` is free at :attr:`resolution_rad`.

        The ends are not checked; its configurations are checked in one batch.
        """
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
