"""``dualarm bench tvgdd``: the TV-GDD step, per backend and CasADi conic plugin.

Never used by the test suite: wall-clock numbers depend on the machine.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from dualarm.quiet import c_output_silenced

#: TV-GDD section 4.2: average computing time per sampling interval and total, on the ball game [s].
PAPER_T_AVE_S = 0.001
PAPER_T_SUM_S = 1.12


@dataclass(frozen=True)
class BenchRow:
    """One measured solver.

    Attributes:
        name: what was measured.
        median_s: median time per step [s].
        p99_s: 99th percentile per step [s].
        total_s: time for the whole task [s].
        steps: control steps.
        velocity_gap_rad_s: largest difference of its joint velocities from the first row's along
            the task [rad/s].
        failure: why the run stopped (then the figures are NaN), or empty.
    """

    name: str
    median_s: float
    p99_s: float
    total_s: float
    steps: int
    velocity_gap_rad_s: float
    failure: str = ""


def bench_tvgdd(
    task_file: str | Path, repeats: int = 5, plugins: tuple[str, ...] = (), progress=None
) -> list[BenchRow]:
    """TV-GDD on a task, in rows, for each QP solver.

    The ``casadi`` backend (DAQP) per step, the paper's LVI solver per step, the ``casadi`` backend
    with each conic plugin in ``plugins`` (e.g. qpoases, osqp, proxqp, qrqp) per step, and the DAQP
    QP as one mapaccum rollout (best of ``repeats``).
    """
    from dualarm.errors import StageError
    from dualarm.ik.velocity.stack import reference_stack, stacked_reference
    from dualarm.ik.velocity.tvgdd import build_problem, joint_bounds, settings_for, solve_tvgdd
    from dualarm.paths import build_reference
    from dualarm.tasks import load_task

    task = load_task(task_file)
    reference = build_reference(task)
    settings = settings_for(task)
    rows, first = [], None
    runs = [(f"casadi {settings.qp_plugin}, per step", settings), ("lvi, per step", replace(settings, backend="lvi"))]
    runs += [(f"casadi {plugin}, per step", replace(settings, qp_plugin=plugin)) for plugin in plugins]
    for name, run_settings in runs:
        if progress:
            progress(f"TV-GDD, {name}")
        try:
            with c_output_silenced():  # qpOASES prints its licence from C
                path = solve_tvgdd(task.robot, reference, task.initial_q, run_settings)
        except StageError as exc:
            nan = float("nan")
            rows.append(BenchRow(name, nan, nan, nan, len(reference), nan, str(exc)))
            continue
        first = path.qd if first is None else first
        times = path.solve_time_s
        rows.append(
            BenchRow(
                name,
                float(np.median(times)),
                float(np.percentile(times, 99)),
                float(times.sum()),
                len(times),
                float(np.abs(path.qd - first).max()),
            )
        )
    if progress:
        progress("TV-GDD, casadi backend, whole path in one call")
    stack = reference_stack(task.robot, reference, task.initial_q, settings.free_waist)
    problem = build_problem(stack, joint_bounds(task.robot, stack, settings), settings, reference.period_s)
    R, V = stacked_reference(stack, reference)
    theta0 = stack.initial
    rollout = problem.rollout(len(reference))
    U = np.vstack([reference.t, R.T, V.T])
    best, thetadot = np.inf, None
    for _ in range(repeats):
        start = time.perf_counter()
        _, thetadot = rollout(theta0, U, theta0)
        best = min(best, time.perf_counter() - start)
    n = len(reference)
    rows.append(
        BenchRow(
            f"casadi {settings.qp_plugin}, one call",
            best / n,
            best / n,
            best,
            n,
            float(np.abs(np.asarray(thetadot).T - first).max()),
        )
    )
    return rows
