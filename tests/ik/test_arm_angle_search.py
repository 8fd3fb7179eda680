"""MC-Inverse's ``auto`` arm-angle search against the plain search it replaced: every start followed at once, the grid's
candidates solved one pose and angle at a time in the virtual machine's mapped call.

The search (:func:`dualarm.ik.analytic.mc_path._auto`) bounds each start's profile and follows only the
starts that can still win, on candidates from the compiled grid call; the result must be the same
profile and branch, bit for bit, and the same failure.
"""

from types import SimpleNamespace

import numpy as np
import pytest

from dualarm.contracts.reference import first_repetition_index
from dualarm.errors import StageError
from dualarm.ik.analytic import mc_path
from dualarm.ik.analytic.mc_inverse import VALID, McInverse
from dualarm.paths import build_reference
from dualarm.tasks import load_task
from tests.helpers import HUMANOID, TASKS


def plain_search(solver: McInverse, targets, reference, preferred, q0, spec):
    """The search as first written (session 10's code): all starts followed together in one dense dynamic programme;
    (profile, branch), or the sample where the longest profile ends."""
    W, G = mc_path.AUTO_MAX_CELLS, len(mc_path.AUTO_GRID)
    shifts = np.arange(-W, W + 1)
    first = np.flatnonzero(reference.rep == reference.rep[0])
    n = len(first)
    grid = np.angle(np.exp(1j * (preferred + mc_path.AUTO_GRID)))
    candidates, reasons = solver.solve_many(np.repeat(targets[first], G, axis=0), np.tile(grid, n))
    candidates, reasons = candidates.reshape(n, G, 8, 7), reasons.reshape(n, G, 8)
    margin = np.minimum(candidates - solver.lower, solver.upper - candidates).min(axis=-1)
    margins = np.where((reasons == VALID) | (margin < 0), margin, -np.inf)
    margins = np.where(((grid > spec.range_rad[0]) & (grid < spec.range_rad[1]))[None, :, None], margins, -np.inf)
    closed = bool(np.abs(targets[first[0]] - targets[first[-1]]).max() < 1e-9)
    best, reached = None, 0
    for branch in range(8):
        q = candidates[:, :, branch]
        node = np.where(margins[:, :, branch] >= 0, np.maximum(0.0, spec.margin_rad - margins[:, :, branch]), np.inf)
        start = node[0] + mc_path.START_WEIGHT * (
            np.abs(np.angle(np.exp(1j * (grid - preferred)))) + np.abs(q[0] - q0).max(axis=1)
        )
        with np.errstate(invalid="ignore"):
            change = np.stack([np.abs(q[1:] - np.roll(q[:-1], d, axis=1)).max(axis=2) for d in shifts], axis=2)
        step_cost = np.where(change <= spec.max_joint_step_rad, change, np.inf) + np.abs(shifts) * (2 * np.pi / G)

        def forward(cost, back=None, step_cost=step_cost, node=node):
            for k in range(1, n):
                options = np.stack([np.roll(cost, d, axis=-1) + step_cost[k - 1, :, j] for j, d in enumerate(shifts)])
                if back is not None:
                    back[k] = np.argmin(
                        options, axis=0
                    )  # the first shift among equals, as the search's strict comparison
                cost = options.min(axis=0) + node[k]
                if not np.isfinite(cost).any():
                    return k
            return cost

        starts = np.flatnonzero(np.isfinite(start))[:: mc_path.START_STRIDE]
        if starts.size == 0:
            reached = max(reached, 0)
            continue
        initial = np.full((starts.size, G), np.inf)
        initial[np.arange(starts.size), starts] = start[starts]
        end = forward(initial)
        if isinstance(end, int):
            reached = max(reached, end)
            continue
        total = end[np.arange(starts.size), starts] if closed else end.min(axis=1)
        if not np.isfinite(total).any():
            reached = max(reached, n - 1)
            continue
        i = int(np.argmin(total))
        back = np.zeros((n, G), int)
        end = forward(initial[i], back)
        cells = np.empty(n, int)
        cells[-1] = starts[i] if closed else int(np.argmin(end))
        for k in range(n - 1, 0, -1):
            cells[k - 1] = (cells[k] - shifts[back[k, cells[k]]]) % G
        if best is None or total[i] < best[0]:
            best = (float(total[i]), cells, branch)
    if best is None:
        return first[reached]
    return grid[best[1]][first_repetition_index(reference.t, reference.rep, reference.period_s)], best[2]


def _search_inputs(task, reference):
    spec = mc_path.settings_for(task)
    ((arm, solver, preferred),) = [
        a
        for a in mc_path.arm_solvers(task.robot, reference, task.robot.configuration(task.initial_q, "q0"), spec)
        if a[0].hand == "left"
    ]
    return solver, arm.targets, reference, preferred, arm.q0, spec


def _cut(reference, count):
    """The reference's first ``count`` samples, as the search reads them: a path that does not close."""
    return SimpleNamespace(t=reference.t[:count], rep=reference.rep[:count], period_s=reference.period_s)


@pytest.mark.parametrize("name", ["triangle", "circle", "carry_box"])
def test_the_search_finds_the_plain_searchs_profile_and_branch_on_the_shipped_tasks(name):
    task = load_task(TASKS / f"{name}.toml")
    inputs = _search_inputs(task, build_reference(task))
    profile, branch = mc_path._auto(*inputs, "left")
    expected_profile, expected_branch = plain_search(*inputs)
    assert branch == expected_branch and np.array_equal(profile, expected_profile)


def test_an_open_path_and_a_failing_range_give_the_plain_searchs_answers(tmp_path):
    """The triangle's first 150 samples (the profile ends anywhere), and psi held in (-0.3, 0.3) (no profile: the same
    sample is named)."""
    task = load_task(TASKS / "triangle.toml")
    reference = build_reference(task)
    inputs = _search_inputs(task, reference)
    opened = list(inputs)
    opened[1], opened[2] = inputs[1][:150], _cut(reference, 150)
    profile, branch = mc_path._auto(*opened, "left")
    expected_profile, expected_branch = plain_search(*opened)
    assert branch == expected_branch and np.array_equal(profile, expected_profile)

    text = (TASKS / "triangle.toml").read_text().replace('robot = "../robots/humanoid"', f'robot = "{HUMANOID}"')
    path = tmp_path / "triangle.toml"
    path.write_text(text.replace("range_rad = [-3.141592653589793, 0.0]", "range_rad = [-0.3, 0.3]"))
    narrow = load_task(path)
    inputs = _search_inputs(narrow, build_reference(narrow))
    sample = plain_search(*inputs)
    with pytest.raises(StageError, match=rf"beyond sample {sample} \("):
        mc_path._auto(*inputs, "left")
