"""The OMPL baseline: RRTConnect from the ``ompl`` package on the same problem as MCIKRRT.

Same joints and limits (a ``RealVectorStateSpace``), the same collision checker as the state
validity checker, the same edge checks (a ``MotionValidator`` written here in place of OMPL's
discrete one: a motion's end state, then its segment's configurations at the checker's resolution
in one batch, as MCIKRRT's Connect checks a step), the same Connect step (``setRange``), and the
same goal configurations: the goals MCIKRRT's goal sampler draws with the same seed, handed to OMPL
as ``GoalStates`` (the time to draw them is part of OMPL's planning time). Shortcutting is OMPL's
own ``PathSimplifier.reduceVertices`` (random vertex pairs joined when the segment is free, the
same number of attempts as MCIKRRT's SmoothSolution).

OMPL's random numbers come from one process-wide seed (``ompl.util.RNG.setSeed``) that can be set
only before its first use; it is set once per process, from the first planning seed, so runs of
the same command repeat, while a trial's OMPL result depends on the trials before it in the
process.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np

from dualarm.errors import StageError
from dualarm.plan.mcikrrt import Checker, PlanResult, TreeSearchSettings, path_length
from dualarm.quiet import c_output_silenced

with c_output_silenced():
    from ompl import base as ob
    from ompl import geometric as og
    from ompl import util as ou

_seeded = False
#: The default settings of :func:`ompl_rrtconnect` (frozen: one instance serves every call).
_DEFAULT_SETTINGS = TreeSearchSettings()


def _seed_once(seed: int) -> None:
    global _seeded
    if not _seeded:
        ou.setLogLevel(ou.LOG_ERROR)
        ou.RNG.setSeed(int(seed) % (2**64 - 1) + 1)  # OMPL takes 1 .. 2**64 - 1; a seed may be any integer >= 0
        _seeded = True


def _vector(state, n: int) -> np.ndarray:
    """An OMPL real-vector state as an array of its ``n`` values."""
    return np.fromiter((state[i] for i in range(n)), float, n)


class _SegmentValidator(ob.MotionValidator):
    """OMPL's motion check by ``checker``: the end state, then the segment's configurations.

    The configurations at the checker's resolution in one batch (the start state is valid already).
    """

    def __init__(self, si, checker: Checker, n: int):
        super().__init__(si)
        self._checker, self._n = checker, n

    def checkMotion(self, s1, s2) -> bool:  # noqa: N802 (OMPL's name)
        a, b = _vector(s1, self._n), _vector(s2, self._n)
        return self._checker.free(b) and self._checker.segment_free(a, b)


def ompl_rrtconnect(
    start: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    checker: Checker,
    goals: Sequence[np.ndarray],
    seed: int,
    settings: TreeSearchSettings = _DEFAULT_SETTINGS,
    goal_time_s: float = 0.0,
) -> PlanResult:
    """Plan from ``start`` [rad] to any of ``goals`` [rad] with OMPL's RRTConnect.

    Within ``lower``/``upper`` [rad]; ``goal_time_s`` [s], the time it took to find the goals, is
    added to the planning time.

    Raises:
        StageError: no goals, or ``start`` in collision.
    """
    if not goals:
        raise StageError("ompl-rrtconnect: no goal configuration to plan to")
    _seed_once(seed)
    started = time.perf_counter()
    checks_before = checker.checks
    n = len(start)
    space = ob.RealVectorStateSpace(n)
    bounds = ob.RealVectorBounds(n)
    for i in range(n):
        bounds.setLow(i, float(lower[i]))
        bounds.setHigh(i, float(upper[i]))
    space.setBounds(bounds)
    si = ob.SpaceInformation(space)
    si.setStateValidityChecker(lambda s: checker.free(_vector(s, n)))
    validator = _SegmentValidator(si, checker, n)  # kept referenced while OMPL uses it
    si.setMotionValidator(validator)
    si.setup()

    def state(q: np.ndarray):
        s = space.allocState()
        for i, v in enumerate(q):
            s[i] = float(v)
        return s

    if not checker.free(start):
        raise StageError("ompl-rrtconnect: the start configuration is in collision")
    problem = ob.ProblemDefinition(si)
    problem.addStartState(state(start))
    goal_states = ob.GoalStates(si)
    for q in goals:
        goal_states.addState(state(q))
    problem.setGoal(goal_states)
    planner = og.RRTConnect(si)
    planner.setProblemDefinition(problem)
    planner.setRange(settings.step_rad)
    planner.setup()
    status = planner.solve(max(settings.timeout_s - goal_time_s, 1e-3))
    data = ob.PlannerData(si)
    planner.getPlannerData(data)
    nodes = data.numVertices()
    exact = str(status) == "Exact solution"
    if not exact:
        return PlanResult(
            False,
            np.empty((0, n)),
            0.0,
            time.perf_counter() - started + goal_time_s,
            nodes,
            len(goals),
            checker.checks - checks_before,
            f"RRTConnect: {status}",
        )
    path = problem.getSolutionPath()

    def waypoints():
        return np.array([[path.getState(k)[i] for i in range(n)] for k in range(path.getStateCount())])

    raw = path_length(waypoints())
    og.PathSimplifier(si).reduceVertices(path, settings.smoothing_iterations, settings.smoothing_iterations)
    return PlanResult(
        True,
        waypoints(),
        raw,
        time.perf_counter() - started + goal_time_s,
        nodes,
        len(goals),
        checker.checks - checks_before,
    )
