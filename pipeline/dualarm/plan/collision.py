"""Collision checking of configurations and joint-space segments for the planners.

A configuration is free exactly when every checked robot link keeps ``margin_m`` from every
object of the task and ``2 margin_m`` from every other checked link. Pairs not checked: those that
touch by construction and those the robot's ``[collision] disabled`` lists, one list shared with
the execute stage (:func:`~dualarm.sim.world.disable_unchecked_pairs`), and the task's expected
contacts.

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
the inflated robot (:meth:`~dualarm.plan.pybullet_checker.PyBulletChecker.overlaps`, a query that
keeps no state between calls, so that a verdict does not depend on the configurations checked
before): a cylinder object in the
configurations where its bounding capsule (its axis grown by its radius) comes within the margin,
and a robot link whose shape is a mesh, box or cylinder in every configuration.

:class:`~dualarm.plan.pybullet_checker.PyBulletChecker` is the reference, the checker the planners
used before: PyBullet's own narrow phase (exact convex distance, GJK/EPA) on a copy of the robot
whose every collision shape is inflated by the margin: the URDF is rewritten with each capsule's,
sphere's and cylinder's radius (and each box's half-extents) grown by ``margin_m``. One check
teleports the joints (``resetJointStatesMultiDof``), runs ``performCollisionDetection`` (the broad
phase prefilters the pairs by their bounding boxes) and reads the contact points with a negative
distance.

Segments are checked at configurations spaced at most ``resolution_rad`` apart in every joint
(the max-norm), end points excluded (a tree's nodes are checked when they are made), in one batch.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Mapping, Sequence

import casadi as cs
import numpy as np

from dualarm.model.kinematics import link_frames
from dualarm.model.robot import Robot
from dualarm.plan.checker import COLLIDES, FREE, UNDECIDED, Contact, _Checker
from dualarm.plan.pybullet_checker import PyBulletChecker
from dualarm.plan.shapes import (
    _Box,
    _compiled_checks,
    _distance,
    _Mapped,
    _object_shape,
    _Pair,
    _robot_shapes,
    _Segment,
)


class CollisionChecker(_Checker):
    """Checks configurations of ``joint_names`` (the others at ``fixed``) in closed form and in batches.

    Against self-collision and the task's fixed objects, with a safety margin (module docstring).

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
        """The checked pairs, the contacts of those no planned joint moves, and the others' Function.

        The compiled Function of the others.
        """
        q = cs.SX.sym("q", len(self.joint_names))
        shapes, ends = _robot_shapes(
            robot,
            link_frames(
                robot.urdf.joints,
                robot.urdf.root,
                {**fixed, **dict(zip(self.joint_names, cs.vertsplit(q), strict=True))},
            ),
            q,
        )
        sim = self._pybullet._sim

        def kept(link: str) -> str:  # a link PyBullet merged into its parent (a robot of many links): the parent
            return sim.link_name[sim.link_index[link]]

        skipped = {tuple(sorted((kept(a), kept(b)))) for a, b in self.unchecked_pairs}

        def unchecked(a: str, b: str) -> bool:
            return kept(a) == kept(b) or tuple(sorted((kept(a), kept(b)))) in skipped

        checked: list[tuple[tuple[str, str], float, list[_Segment] | None, Sequence[_Segment | _Box] | None]] = [
            ((a, b), 2 * self.margin_m, shapes[a], shapes[b])
            for a, b in itertools.combinations(sorted(shapes), 2)
            if not unchecked(a, b) and frozenset((a, b)) not in allowed
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
        """The checked pairs of shapes some planned joint moves, the columns of :meth:`distances`.

        A pair: (robot link, object), or two robot links in sorted order.
        """
        return list(self._names)

    def distances(self, Q: np.ndarray) -> np.ndarray:
        """Signed distances [m] of :attr:`pairs` at each configuration of ``Q`` (N, n) [rad]; (N, P).

        Exact wherever the broad phase keeps the pair (always when it is closer than its threshold),
        +inf where it does not; for a cylinder object, the distance to its bounding capsule. Not a
        check (neither counted nor timed).
        """
        return self._compiled(self._configurations(Q))[:, :-1].copy()

    def free_many(self, Q: np.ndarray) -> np.ndarray:
        """For each configuration of ``Q`` (N, n) [rad], whether no checked pair is closer than the margin.

        Returns (N,) bool.
        """
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
        """No checked pair is closer than the margin at ``q`` [rad].

        :meth:`free_many` of one configuration, without its array operations.
        """
        started = time.perf_counter()
        q = np.asarray(q, dtype=float)
        free = self._decide(q, self._compiled(self._configurations(q[None]))[0])
        self.checks += 1
        self.check_time_s += time.perf_counter() - started
        return free

    def _decide(self, q: np.ndarray, out: np.ndarray) -> bool:
        """Whether ``q`` [rad] is free, from its compiled distances and verdict ``out``.

        PyBullet decides an undecided one.
        """
        return bool(
            out[-1] == FREE or (out[-1] == UNDECIDED and not self._pybullet.overlaps(q, self._undecided(out[:-1])))
        )

    def _undecided(self, d: np.ndarray) -> list[tuple[str, str]]:
        """The pairs PyBullet decides at a configuration whose distances :attr:`pairs` are ``d`` [m].

        Those of a link without a closed form, and each cylinder whose bounding capsule is near.
        """
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
