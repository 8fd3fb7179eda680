"""Goal configurations from Workspace Target Areas: HR_IK of MCIKRRT's line 03.

Each sample draws one WTA per hand by weight and a pose in it (eqs 27-31, :mod:`.wta`), then
solves both hands at once with DLS-SVD (eqs 12-20, :class:`~dualarm.ik.pose_level.dls.DlsSolver`) over the
planned joints: with the waist free, the 17-DOF model, both hands' rows stacked over the shared
waist. The solve is seeded with the start configuration. A solution counts as a goal when it
converged to the tolerances and is collision-free.

The sampler keeps, per WTA, how many samples it was drawn for, how many of them its hand reached
and how close the hand came, so a planning failure can name the area no IK sample reached.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from dualarm.ik.pose_level.dls import DlsSettings, DlsSolver
from dualarm.plan.collision import CollisionChecker
from dualarm.plan.wta import Wta, sample_hand_pose

#: The goal IK's tolerances: hand position [m] and rotation angle [rad].
GOAL_TOLERANCE = (1e-6, 1e-6)


@dataclass
class AreaStats:
    """What the goal samples did for one WTA.

    Attributes:
        drawn: samples drawn from it.
        reached: samples whose IK put its hand within tolerance of the sampled pose.
        nearest_m: the smallest hand position error any of its samples ended with [m].
    """

    drawn: int = 0
    reached: int = 0
    nearest_m: float = float("inf")


@dataclass
class WtaGoalSampler:
    """Draws goal configurations of ``solver.joint_names`` from the task's WTAs.

    Attributes:
        areas: each hand's WTAs.
        solver: the DLS-SVD solver of both hands over the planned joints.
        checker: the collision checker.
        seed: the configuration the IK starts from [rad].
        rng: the random stream of the WTA samples.
        stats: per WTA name, what its samples did.
        collided: goals rejected for a collision, per colliding pair (the deepest).
        ik_time_s: time spent in IK [s].
        goals: every goal configuration found, in order.
    """

    areas: Mapping[str, Sequence[Wta]]
    solver: DlsSolver
    checker: CollisionChecker
    seed: np.ndarray
    rng: np.random.Generator
    stats: dict[str, AreaStats] = field(default_factory=dict)
    collided: dict[tuple[str, str], int] = field(default_factory=dict)
    ik_time_s: float = 0.0
    goals: list[np.ndarray] = field(default_factory=list)

    @staticmethod
    def ik_solver(robot, base: str, tips: Sequence[str]) -> DlsSolver:
        """The goal IK: DLS-SVD of ``tips`` from ``base`` at :data:`GOAL_TOLERANCE`."""
        return DlsSolver.of(
            robot,
            base,
            tips,
            DlsSettings(
                position_tolerance_m=GOAL_TOLERANCE[0], orientation_tolerance_rad=GOAL_TOLERANCE[1], max_iterations=100
            ),
        )

    def __call__(self) -> np.ndarray | None:
        """One goal sample: a goal configuration [rad], or None.

        None when the IK did not converge or the solution collides.
        """
        drawn = [sample_hand_pose(self.areas[hand], self.rng) for hand in self.areas]
        started = time.perf_counter()
        result = self.solver.solve([pose for _, pose in drawn], self.seed)
        self.ik_time_s += time.perf_counter() - started
        errors = self._hand_errors(result.q, [pose for _, pose in drawn])
        for (area, _), error in zip(drawn, errors, strict=True):
            stats = self.stats.setdefault(area.name, AreaStats())
            stats.drawn += 1
            stats.reached += bool(error <= GOAL_TOLERANCE[0])
            stats.nearest_m = min(stats.nearest_m, error)
        if not result.converged:
            return None
        contacts = self.checker.contacts(result.q)
        if contacts:
            pair = (contacts[0].a, contacts[0].b)
            self.collided[pair] = self.collided.get(pair, 0) + 1
            return None
        self.goals.append(result.q)
        return result.q

    def _hand_errors(self, q: np.ndarray, targets: Sequence[np.ndarray]) -> list[float]:
        """Each hand's position error [m] at ``q`` against its target."""
        dx = self.solver.evaluate(np.concatenate([q, *[T.ravel(order="F") for T in targets]]))[0]
        dx = np.asarray(dx).ravel()
        return [float(np.linalg.norm(dx[6 * k : 6 * k + 3])) for k in range(len(targets))]

    def explain(self) -> str:
        """Why no goal was found: the WTAs no sample reached, the farthest first, else the collisions."""
        worst_first = sorted(
            self.stats.items(), key=lambda item: -item[1].nearest_m
        )  # a far area also drags the other hand off over the shared waist
        unreached = [
            f"WTA '{name}' ({stats.drawn} samples, nearest {stats.nearest_m:.3g} m)"
            for name, stats in worst_first
            if stats.reached == 0
        ]
        if unreached:
            return "no IK sample reached " + "; ".join(unreached)
        if self.collided:
            (a, b), count = max(self.collided.items(), key=lambda item: item[1])
            return f"every IK solution collides ({count} times {a} with {b})"
        return "no goal sample was drawn"
