"""Verdicts: a run that collides, breaks a limit or misses the pose never reports success.

Every fact is computed apart from the checks under test: limit ratios in closed form, collisions
by a fresh PyBullet client queried at the reported time, failed samples by construction.
"""

import json
import math
import tomllib

import numpy as np
import pytest
from typer.testing import CliRunner

from dualarm.cli import app
from dualarm.contracts.joint_path import JointPath
from dualarm.contracts.trajectory import JointTrajectory
from dualarm.contracts.verdict import EXIT_CODES, Checks, Verdict, Violation
from dualarm.errors import StageError
from dualarm.execute.simulate import ExecutionSettings
from dualarm.record.readback import read_run
from dualarm.record.sink import NullSink
from dualarm.run import run_task
from dualarm.sim.world import load_pybullet_robot, pb
from dualarm.stages import ExecuteStage
from dualarm.tasks import load_task
from dualarm.tasks.load import task_from_dict
from dualarm.violations import ik_violations
from tests.helpers import still_path_fields

#: The right hand draws a square across the chest; DLS-SVD swings the right upper arm into the
#: torso (found with `dualarm run ... --ik dls-svd --execute-anyway`).
SQUARE = """
name = "square"
robot = "humanoid"
control_period_s = 0.01
initial = "ready"

[waypoints.P0]
position = [0.25, -0.10, 1.00]
rpy = [1.571, 1.571, 1.571]

[start]
right = "P0"

[[moves]]
duration_s = 2.0
right = { by = [0.0, 0.20, 0.0] }

[[moves]]
duration_s = 2.0
right = { by = [0.0, 0.0, 0.20] }

[[moves]]
duration_s = 2.0
right = { by = [0.0, -0.20, 0.0] }

[[moves]]
duration_s = 2.0
right = { by = [0.0, 0.0, -0.20] }
"""

#: Both hands move 0.30 m sideways, through each other.
CROSSING = """
name = "crossing"
robot = "humanoid"
control_period_s = 0.01
initial = "ready"

[waypoints.L]
position = [0.35, 0.15, 1.05]
rpy = [-1.571, 1.571, -1.571]

[waypoints.R]
position = [0.35, -0.15, 1.05]
rpy = [1.571, 1.571, 1.571]

[start]
left = "L"
right = "R"

[[moves]]
duration_s = 2.0
left = { by = [0.0, -0.30, 0.0] }
right = { by = [0.0, 0.30, 0.0] }
"""


def _distance(task, q: dict[str, float], a: str, b: str) -> float:
    """Signed distance [m] between robot links ``a`` and ``b`` at ``q``, by a fresh PyBullet client (no margin, no
    filter)."""
    with load_pybullet_robot(task.robot.urdf.path) as sim:
        sim.set_positions(list(q), list(q.values()))
        pb.performCollisionDetection(physicsClientId=sim.client)
        points = pb.getClosestPoints(
            sim.body, sim.body, 0.5, sim.link_index[a], sim.link_index[b], physicsClientId=sim.client
        )
        return min(p[8] for p in points)


# --- limits: refused before execution ------------------------------------------------------------


@pytest.fixture(scope="module")
def too_fast():
    """The triangle's task at rest at 'ready', but the left elbow swings q0 + A (1 - cos(pi t / T)):
    its speed A pi / T sin(pi t / T) peaks at t = T / 2 at 1.5 times the elbow's velocity limit."""
    task = load_task("triangle", 1)
    names = tuple(task.robot.hand_chain("left").joint_names)
    j = names.index("left_elbow")
    limit = task.robot.limits["left_elbow"].velocity
    A = 0.3
    T = A * math.pi / (1.5 * limit)
    t = np.arange(0, T + 1e-12, 0.001)
    q = np.tile([task.initial_q[n] for n in names], (len(t), 1))
    qd, qdd = np.zeros_like(q), np.zeros_like(q)
    q[:, j] += A * (1 - np.cos(np.pi * t / T))
    qd[:, j] = A * np.pi / T * np.sin(np.pi * t / T)
    qdd[:, j] = A * (np.pi / T) ** 2 * np.cos(np.pi * t / T)
    fixed = {n: v for n, v in task.initial_q.items() if n not in names}
    return task, JointTrajectory("smooth", names, t, q, qd, qdd, np.zeros(len(t), int), fixed), T


@pytest.mark.integration
def test_a_trajectory_over_a_velocity_limit_is_refused_before_execution(too_fast):
    task, trajectory, T = too_fast
    with pytest.raises(StageError, match=r"refused to play the trajectory") as refused:
        ExecuteStage(task, ExecutionSettings())(trajectory, NullSink())
    assert refused.value.stage == "execute"
    log, _ = ExecuteStage(task, ExecutionSettings(execute_anyway=True))(trajectory, NullSink())
    found = ExecuteStage(task, ExecutionSettings(execute_anyway=True)).violations(log)
    (velocity,) = [v for v in found if "velocity of left_elbow" in v.message]
    ratio = float(velocity.message.split(" at ")[1].split("x")[0])
    assert ratio == pytest.approx(1.5, rel=1e-4)  # the closed form's peak
    assert velocity.t_s == pytest.approx(T / 2, abs=1e-3) and velocity.check == "limit"
    assert str(refused.value).startswith("execute: refused to play the trajectory: smooth: ")
    assert Verdict.of(found).status == "violated" and Verdict.of(found).exit_code == 3


# --- collisions: the square and the crossing hands ---------------------------------------------------


@pytest.fixture(scope="module")
def square_runs(tmp_path_factory):
    """``dualarm run square.toml --ik pinv``, refused and then played with --execute-anyway.

    (DLS-SVD's path jumps on this square: :func:`test_the_square_by_dls_svd_is_refused_where_its_path_jumps`.)"""
    tmp = tmp_path_factory.mktemp("square")
    (tmp / "square.toml").write_text(SQUARE)
    runner = CliRunner()
    refused = runner.invoke(app, ["run", str(tmp / "square.toml"), "--ik", "pinv", "--out", str(tmp / "refused")])
    played = runner.invoke(
        app, ["run", str(tmp / "square.toml"), "--ik", "pinv", "--out", str(tmp / "played"), "--execute-anyway"]
    )
    return load_task(tmp / "square.toml"), tmp, refused, played


@pytest.mark.integration
def test_the_colliding_square_is_refused_naming_the_pair(square_runs):
    task, tmp, refused, _ = square_runs
    assert refused.exit_code == EXIT_CODES["failed"] == 1, refused.output
    lines = refused.output.strip().splitlines()
    assert lines[0] == "verdict: failed" and lines[1].startswith("error: execute: refused to play the trajectory: ")
    (run,) = (tmp / "refused" / "square").iterdir()
    assert lines[-1] == f"the run is kept as failed in {run}"
    manifest = json.loads((run / "manifest.json").read_text())
    assert manifest["status"] == "failed" and "refused" in manifest["error"]
    refusal = [v["message"] for v in manifest["violations"] if v["check"] == "contact"]
    assert any("right_upper_arm" in m and "torso" in m for m in refusal), manifest["violations"]


@pytest.mark.integration
def test_the_colliding_square_played_anyway_is_violated_with_the_pair_time_and_depth(square_runs):
    """The upper arm against the torso, at the time the preflight names: a fresh PyBullet client
    finds the two links overlapping at the smoothed trajectory's configuration at that time."""
    task, tmp, _, played = square_runs
    assert played.exit_code == EXIT_CODES["violated"] == 3, played.output
    assert "verdict: violated" in played.output
    (run,) = (tmp / "played" / "square").iterdir()
    data = read_run(run)
    manifest = json.loads((run / "manifest.json").read_text())
    assert manifest["status"] == "violated" and (run / "metrics.json").exists()
    collisions = [v for v in manifest["violations"] if v["check"] == "contact" and v["stage"] == "smooth"]
    upper_arm = [v for v in collisions if "right_upper_arm" in v["message"] and "torso" in v["message"]]
    assert upper_arm, manifest["violations"]
    smooth = data["/smooth/sample"]
    k = int(np.argmin(np.abs(smooth["t"].to_numpy() - upper_arm[0]["t_s"])))
    q = {c.split(".", 1)[1]: float(smooth[c].iloc[k]) for c in smooth.columns if c.startswith("position.")}
    depth_mm = float(upper_arm[0]["message"].split(", ")[1].split(" mm")[0])
    assert _distance(task, {**task.initial_q, **q}, "right_upper_arm", "torso") < 0 and depth_mm > 0
    # executed: the contacts are recorded per step and pair, with their depth
    contacts = data["/execute/contacts"]
    assert {"first", "second", "depth_m", "t"} <= set(contacts.columns) and len(contacts) > 0
    assert (
        (contacts["first"] == "right_forearm")
        | (contacts["second"] == "right_forearm")
        | (contacts["first"] == "right_upper_arm")
    ).any()
    assert data.metrics["execute.self_collisions"] > 0


@pytest.mark.integration
def test_the_square_by_dls_svd_is_refused_where_its_path_jumps(tmp_path):
    """DLS-SVD holds the right shoulder pitch at its limit, then lets it go by 0.21 rad in one 10 ms sample (issue 36's
    right-hand square, which the timing's IPOPT failed on): the run fails at retime, in one line naming the joint and
    the samples of the first step beyond ten times the velocity limit, computed here from the IK's own path."""
    (tmp_path / "square.toml").write_text(SQUARE)
    result = CliRunner().invoke(app, ["run", str(tmp_path / "square.toml"), "--ik", "dls-svd", "--out", str(tmp_path)])
    assert result.exit_code == EXIT_CODES["failed"], result.output
    task = load_task(tmp_path / "square.toml")
    path = run_task(task, "dls-svd", stages=("path", "ik")).joint_path
    step = np.abs(np.diff(path.q, axis=0))
    speed = step / np.diff(path.t)[:, None] / task.robot.limit_array("velocity", path.joint_names)
    k, j = np.argwhere((speed > 10) & (step > 1e-3))[0]  # the first step beyond ten times the velocity limit
    (error,) = [line for line in result.output.splitlines() if line.startswith("error: ")]
    assert error.startswith(f"error: retime: the joint path jumps: {path.joint_names[j]} moves ")
    assert f"between samples {k} and {k + 1}" in error


@pytest.mark.integration
def test_crossing_hands_played_anyway_name_the_arms_that_touch():
    result = run_task(
        task_from_dict(tomllib.loads(CROSSING)), "dls-svd", execution=ExecutionSettings(execute_anyway=True)
    )
    assert result.verdict.status == "violated"
    pairs = [v.message for v in result.verdict.violations if v.check == "contact" and v.stage == "execute"]
    assert pairs and all("touched" in p for p in pairs)
    assert result.execution is not None and any(not c.expected for c in result.execution.contacts)


# --- IK: failed samples and missed poses ----------------------------------------------------------


def _path(status, error_m) -> JointPath:
    n = len(status)
    return JointPath(
        **still_path_fields(
            n, method="m", status=np.array(status), hand_error_m=np.array(error_m, dtype=float).reshape(n, 1)
        )
    )


class _Limits:
    """A one-joint robot stand-in for the position-limit lookup."""

    def lower_upper(self, names):
        return np.array([-1.0]), np.array([1.0])

    def limit_array(self, kind, names):
        return np.array([1.0])


def test_failed_samples_and_a_missed_position_are_violations_naming_the_first_time():
    found = ik_violations(_path([0, 1, 1, 0, 0], [0, 0, 0, 2e-3, 0]), _Limits(), Checks(), retimed=True)
    failed, missed = found
    assert "2 of 5 samples failed, the first at t = 0.010 s (rep 0)" in failed.message and failed.t_s == pytest.approx(
        0.01
    )
    assert "left hand 2 mm off the asked position at t = 0.030 s" in missed.message and missed.t_s == pytest.approx(
        0.03
    )
    assert ik_violations(_path([0, 0], [0, 9e-4]), _Limits(), Checks(), retimed=True) == []


def test_verdict_lines_and_exit_codes():
    v = Violation("limit", "smooth", "smooth: velocity of j at 2x its limit at t = 1.000 s", 1.0)
    assert Verdict.of([]).lines() == ["verdict: complete"] and Verdict.of([]).exit_code == 0
    assert Verdict.of([v, v]).violations == (v,)  # one message once
    assert Verdict.of([v]).lines() == ["verdict: violated (1 violation)", f"  {v.message}"]
    assert Verdict.failure("boom").exit_code == 1 and Verdict.failure("boom").first == "boom"


def test_a_position_limit_is_timed_at_its_own_sample_after_a_failed_one():
    """Samples 0 failed, 2 beyond the [-1, 1] rad limit by 0.5 rad: the violation is at t = 0.02 s."""
    path = JointPath(**still_path_fields(3, method="m", status=np.array([1, 0, 0]), q=np.array([[0.0], [0.0], [1.5]])))
    limit = [v for v in ik_violations(path, _Limits(), Checks(), retimed=True) if v.check == "limit"]
    assert (
        len(limit) == 1
        and limit[0].t_s == pytest.approx(0.02)
        and "position of a 0.5 rad beyond its limits [-1, 1]" in limit[0].message
    )
