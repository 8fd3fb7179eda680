"""MCIKRRT: Li & Liang's bi-directional RRT with goals sampled from Workspace Target Areas.

The paper's pseudo-code, line by line (``MCIKRRT(Theta_s, B_e)``):

    01  T_a.Init(Theta_s); T_b.Init(NULL)
    02  do {
    03    if (T_b.size() = 0 or rand(0,1) < f_r)  T_b.HR_IK(Theta_goal, B_e)     # a goal root
    04    else { Theta_rand = RandomConfig(); Theta_near,a = T_a.NearNeighbor(Theta_rand)
    05           Theta_reach,a = T_a.Connect(Theta_near,a, Theta_rand)
                 Theta_near,b = T_b.NearNeighbor(Theta_reach,a)
    06           Theta_reach,b = T_b.Connect(Theta_near,b, Theta_reach,a)
    07           if |Theta_reach,b - Theta_reach,a| <= dTheta_min
                     S = BuildSolu(T_a, Theta_reach,a, T_b, Theta_reach,b)
    08               return SmoothSolution(S)
    09           else Swap(T_a, T_b) }
    10  } while (!TimeOut())
    11  return NULL

Read as follows where the text leaves room:

- HR_IK (line 03) adds a goal configuration as a new root of the *goal* tree: it is the tree
  that started empty, whichever of T_a, T_b it is after the swaps (goals grown into the start
  tree would join nothing). A goal is a DLS-SVD IK solution of a WTA sample (:mod:`.goals`); a
  sample whose IK does not converge or whose solution collides adds nothing.
- RandomConfig is uniform within the joint position limits.
- NearNeighbor is the tree node nearest in Euclidean joint distance [rad].
- Connect steps from the near node toward the target, ``step_rad`` (Euclidean) at a time, adding
  each collision-free step as a node, until it reaches the target or a step collides (RRT-Connect's
  CONNECT, Kuffner & LaValle 2000). Each step's configuration is checked, then, when it is free,
  the segment to it at the checker's resolution, its configurations in one batch (checking the
  step and its segment in one batch measured slower: on the bowl grasp, 98 % of the steps that
  collide do so at their end).
- dTheta_min is ``connect_tolerance_rad``; as Connect stops exactly at its target, a successful
  connection has distance 0.
- SmoothSolution is shortcutting: ``smoothing_iterations`` times, two random waypoints of the path
  are joined by a straight segment when it is collision-free, dropping those between.
- TimeOut is ``timeout_s`` of wall time, goal IK included.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from dualarm.arrays import frozen
from dualarm.errors import InvalidArgumentError, StageError
from dualarm.settings import check_positive


class Checker(Protocol):
    """What the planner needs of a collision checker (:class:`.collision.CollisionChecker`)."""

    checks: int

    def free(self, q: np.ndarray) -> bool:
        """Whether configuration ``q`` [rad] is collision-free."""
        ...

    def segment_free(self, a: np.ndarray, b: np.ndarray) -> bool:
        """Whether the straight joint-space segment from ``a`` to ``b`` [rad] is collision-free.

        The ends not checked; its configurations in one batch.
        """
        ...


@dataclass(frozen=True)
class TreeSearchSettings:
    """Settings of the tree search: MCIKRRT's (OMPL's RRTConnect uses the timeout and the step).

    Attributes:
        timeout_s: wall time after which planning gives up [s].
        goal_probability: f_r, the probability of sampling a goal instead of extending [1].
        step_rad: Connect's step, Euclidean over all joints [rad].
        connect_tolerance_rad: dTheta_min, the distance at which the trees count as joined [rad].
        smoothing_iterations: shortcut attempts of SmoothSolution.
    """

    timeout_s: float = 5.0
    goal_probability: float = 0.05
    step_rad: float = 0.5
    connect_tolerance_rad: float = 1e-6
    smoothing_iterations: int = 30

    def __post_init__(self) -> None:
        check_positive(self, "timeout_s", "step_rad")
        check_positive(self, "connect_tolerance_rad", "goal_probability", zero=True)
        check_positive(self, "smoothing_iterations", zero=True, integer=True)
        if self.goal_probability > 1.0:
            raise InvalidArgumentError(
                "goal_probability", f"the goal probability f_r must lie in [0, 1], not {self.goal_probability}"
            )


@dataclass(frozen=True)
class PlanResult:
    """Outcome of one planning query.

    Attributes:
        success: a path was found within the timeout.
        path: the smoothed path's waypoints (K, n) [rad], start first, a goal last; (0, n) on failure.
        raw_path_length_rad: joint-space length of the path before smoothing [rad] (0 on failure).
        planning_time_s: wall time of the query, goal IK and smoothing included [s].
        nodes: nodes of both trees together, goal roots included.
        goals: goal configurations found.
        collision_checks: configurations collision-checked.
        reason: why it failed (empty on success).
    """

    success: bool
    path: np.ndarray
    raw_path_length_rad: float
    planning_time_s: float
    nodes: int
    goals: int
    collision_checks: int
    reason: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "path", frozen(self.path, self.path.shape, "path"))

    @property
    def path_length_rad(self) -> float:
        """Joint-space length of the smoothed path [rad] (0 on failure)."""
        return path_length(self.path)


def path_length(path: np.ndarray) -> float:
    """Sum of the Euclidean lengths of a path's segments [rad]."""
    return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum()) if len(path) > 1 else 0.0


class _Tree:
    """Nodes (grown arrays) with parent indices; a root has parent -1."""

    def __init__(self, n: int) -> None:
        self.q = np.empty((64, n))
        self.parent = np.empty(64, dtype=int)
        self.size = 0

    def add(self, q: np.ndarray, parent: int) -> int:
        if self.size == len(self.q):
            self.q = np.concatenate([self.q, np.empty_like(self.q)])
            self.parent = np.concatenate([self.parent, np.empty_like(self.parent)])
        self.q[self.size], self.parent[self.size] = q, parent
        self.size += 1
        return self.size - 1

    def nearest(self, q: np.ndarray) -> int:
        return int(np.argmin(((self.q[: self.size] - q) ** 2).sum(axis=1)))

    def branch(self, node: int) -> list[np.ndarray]:
        """The configurations from ``node`` up to its root."""
        out = []
        while node != -1:
            out.append(self.q[node].copy())
            node = self.parent[node]
        return out


def _connect(tree: _Tree, near: int, target: np.ndarray, checker: Checker, step: float) -> int:
    """Grow ``tree`` from node ``near`` toward ``target``; the last node added (or ``near``)."""
    node = near
    while True:
        q = tree.q[node]
        gap = target - q
        distance = float(np.linalg.norm(gap))
        if distance == 0.0:
            return node
        new = target if distance <= step else q + gap * (step / distance)
        if not (checker.free(new) and checker.segment_free(q, new)):
            return node
        node = tree.add(new, node)


def shortcut(path: list[np.ndarray], checker: Checker, iterations: int, rng: np.random.Generator) -> list[np.ndarray]:
    """SmoothSolution: ``iterations`` times, join two random waypoints directly.

    When the segment between them is collision-free.
    """
    path = list(path)
    for _ in range(iterations):
        if len(path) < 3:
            break
        i, j = sorted(rng.choice(len(path), 2, replace=False))
        if j - i > 1 and checker.segment_free(path[i], path[j]):
            path = path[: i + 1] + path[j:]
    return path


def mcikrrt(
    start: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    checker: Checker,
    sample_goal: Callable[[], np.ndarray | None],
    rng: np.random.Generator,
    settings: TreeSearchSettings = TreeSearchSettings(),
) -> PlanResult:
    """Plan from ``start`` [rad] to a configuration ``sample_goal`` provides (None: the sample gave none).

    Within ``lower``/``upper`` [rad], every node and edge free by ``checker``.

    Raises:
        StageError: ``start`` is not collision-free.
    """
    started = time.perf_counter()
    checks_before = checker.checks
    start = np.asarray(start, dtype=float)
    if not checker.free(start):
        raise StageError("planner: the start configuration is in collision")
    trees = [_Tree(len(start)), _Tree(len(start))]
    trees[0].add(start, -1)  # 01
    a, b = 0, 1  # T_a, T_b as indices; tree 1 is the goal tree
    goals = 0
    path: list[np.ndarray] | None = None
    while time.perf_counter() - started < settings.timeout_s:  # 02, 10
        if trees[1].size == 0 or rng.random() < settings.goal_probability:  # 03
            goal = sample_goal()
            if goal is not None:
                trees[1].add(goal, -1)
                goals += 1
            continue
        target = rng.uniform(lower, upper)  # 04
        reach_a = _connect(trees[a], trees[a].nearest(target), target, checker, settings.step_rad)  # 05
        q_a = trees[a].q[reach_a]
        reach_b = _connect(trees[b], trees[b].nearest(q_a), q_a, checker, settings.step_rad)  # 06
        if np.linalg.norm(trees[b].q[reach_b] - q_a) <= settings.connect_tolerance_rad:  # 07
            start_side, goal_side = (reach_a, reach_b) if a == 0 else (reach_b, reach_a)
            path = trees[0].branch(start_side)[::-1] + trees[1].branch(goal_side)[1:]  # BuildSolu
            break
        a, b = b, a  # 09
    nodes = trees[0].size + trees[1].size
    if path is None:
        return PlanResult(
            False,
            np.empty((0, len(start))),
            0.0,
            time.perf_counter() - started,
            nodes,
            goals,
            checker.checks - checks_before,
            f"no path within the timeout of {settings.timeout_s:g} s",
        )
    raw = path_length(np.array(path))
    smoothed = np.array(shortcut(path, checker, settings.smoothing_iterations, rng))  # 08
    return PlanResult(True, smoothed, raw, time.perf_counter() - started, nodes, goals, checker.checks - checks_before)
