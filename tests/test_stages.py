"""The whole default pipeline, path -> ik -> retime -> smooth -> approach -> execute, checked from its recording.

Every limit check here is computed from the samples read back from ``run.mcap`` (finite
differences of the recorded positions, velocities and accelerations) against the limits in the
robot and task files, not from the stages' own metrics; the executed hands are compared with
PyBullet's forward kinematics of the recorded commands.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from dualarm.cli import app
from dualarm.record.readback import read_run
from dualarm.run import record_run
from dualarm.sim.world import load_pybullet_robot
from dualarm.tasks import load_task
from tests.helpers import HUMANOID, TASKS

pytestmark = pytest.mark.integration

TRIANGLE = TASKS / "triangle.toml"
#: A shipped task that starts at robot.toml's ``ready`` pose, away from its path start (the triangle starts on its
#: path).
CARRY_BOX = TASKS / "carry_box.toml"
SLACK = 1 + 1e-6


@pytest.fixture(scope="module")
def triangle(tmp_path_factory):
    out = tmp_path_factory.mktemp("runs")
    run = record_run(load_task(TRIANGLE, 1), "mc-inverse", out_dir=out).directory
    return load_task(TRIANGLE, 1), run, read_run(run)


@pytest.fixture(scope="module")
def carry_box(tmp_path_factory):
    out = tmp_path_factory.mktemp("approach")
    run = record_run(load_task(CARRY_BOX, 1), "mc-inverse", out_dir=out).directory
    return load_task(CARRY_BOX, 1), run, read_run(run)


def _joints(df, field: str, names) -> np.ndarray:
    return df[[f"{field}.{n}" for n in names]].to_numpy()


def _limits(data, stage: str):
    row = data[f"/{stage}/limits"].iloc[0]
    names = [c.split(".", 1)[1] for c in data[f"/{stage}/limits"].columns if c.startswith("velocity.")]
    return names, {
        kind: np.array([row[f"{kind}.{n}"] for n in names])
        for kind in ("velocity", "acceleration", "jerk")
        if f"{kind}.{names[0]}" in row
    }


def test_every_stage_runs_by_default_and_is_recorded(triangle):
    task, run, data = triangle
    manifest = json.loads((run / "manifest.json").read_text())
    assert manifest["status"] == "complete" and manifest["stages"] == [
        "path",
        "ik",
        "retime",
        "smooth",
        "approach",
        "execute",
    ]
    for topic in ("/retime/sample", "/retime/limits", "/smooth/sample", "/smooth/limits", "/execute/sample"):
        assert len(data[topic]) > 0, topic
    assert "left_hand" in set(data["/tf"]["child_frame_id"])  # the executed robot


def test_the_approach_moves_from_the_initial_configuration_to_the_motion_start_within_the_limits(carry_box):
    """The approach starts at the task's initial configuration (carry_box's ``initial = "ready"``:
    robot.toml's ``ready`` pose, both read here with tomllib) and ends where the smoothed trajectory
    starts, at rest at both ends; its positions' finite differences stay within the velocity,
    acceleration and jerk limits; and it was played: ``/approach/executed`` ends where
    ``/execute/sample`` continues."""
    import tomllib

    _, run, data = carry_box
    assert json.loads((run / "manifest.json").read_text())["status"] == "complete"
    assert tomllib.loads(CARRY_BOX.read_text())["initial"] == "ready"
    approach, smooth = data["/approach/sample"], data["/smooth/sample"]
    names, limits = _limits(data, "approach")
    ready = tomllib.loads((HUMANOID / "robot.toml").read_text())["home"]["ready"]
    q = _joints(approach, "position", names)
    assert np.allclose(q[0], [ready.get(n, 0.0) for n in names], atol=1e-12)
    assert np.allclose(q[-1], _joints(smooth, "position", names)[0], atol=1e-9)
    for field in ("velocity", "acceleration"):
        assert np.abs(_joints(approach, field, names)[[0, -1]]).max() < 1e-9
    dt = np.diff(approach["t"].to_numpy())[:, None]
    velocity = np.diff(q, axis=0) / dt
    acceleration = np.diff(velocity, axis=0) / dt[1:]
    jerk = np.diff(_joints(approach, "acceleration", names), axis=0) / dt
    assert (np.abs(velocity) <= limits["velocity"] * SLACK).all() and (
        np.abs(acceleration) <= limits["acceleration"] * SLACK + 1e-6
    ).all()
    assert (np.abs(jerk) <= limits["jerk"] * SLACK).all()
    assert np.abs(velocity).max(axis=0).max() > 0.1  # it moved
    executed = data["/approach/executed"]
    assert executed["t"].iloc[-1] == pytest.approx(approach["t"].iloc[-1], abs=1e-3)
    assert (
        np.abs(_joints(executed, "position", names)[-1] - _joints(data["/execute/sample"], "position", names)[0]).max()
        < 0.01
    )


def test_the_approach_is_the_straight_jerk_limited_move_ruckig_times_in_phase(carry_box):
    """The approach is timed as the retime stage times a path (a straight piece): every recorded sample lies on the
    line from its first to its last configuration (1e-9 rad), and it lasts as long as Ruckig's time-optimal
    phase-synchronised move between them (every joint on that line) within 99.8 % of each limit (the share the
    timing uses), to 1e-6 s, and at most 0.21 % longer than at the full limits."""
    from ruckig import InputParameter, Result, Ruckig, Synchronization, Trajectory

    _, _, data = carry_box
    names, limits = _limits(data, "approach")
    approach = data["/approach/sample"]
    q = _joints(approach, "position", names)
    line = q[-1] - q[0]
    along = (q - q[0]) @ line / (line @ line)
    assert np.abs(q - q[0] - np.outer(along, line)).max() <= 1e-9
    durations = []
    for share in (0.998, 1.0):
        inp = InputParameter(len(names))
        inp.current_position, inp.target_position = q[0].tolist(), q[-1].tolist()
        inp.max_velocity, inp.max_acceleration, inp.max_jerk = (
            (share * limits[kind]).tolist() for kind in ("velocity", "acceleration", "jerk")
        )
        inp.synchronization = Synchronization.Phase
        plan = Trajectory(len(names))
        assert Ruckig(len(names)).calculate(inp, plan) == Result.Working
        durations.append(plan.duration)
    assert approach["t"].iloc[-1] == pytest.approx(durations[0], abs=1e-6)
    assert durations[1] <= approach["t"].iloc[-1] <= 1.0021 * durations[1]


def test_the_triangle_starts_on_its_path_so_its_approach_barely_moves(triangle):
    """triangle.toml's ``[initial]`` table (read with tomllib; unnamed joints at 0) is MC-Inverse's
    configuration at A rounded to 1e-6 rad: the approach starts there and ends where the smoothed
    trajectory starts, less than 1e-5 rad away in every joint."""
    import tomllib

    _, _, data = triangle
    names, _ = _limits(data, "approach")
    initial = tomllib.loads(TRIANGLE.read_text())["initial"]
    q = _joints(data["/approach/sample"], "position", names)
    assert np.allclose(q[0], [initial.get(n, 0.0) for n in names], atol=1e-12)
    assert np.allclose(q[-1], _joints(data["/smooth/sample"], "position", names)[0], atol=1e-9)
    assert np.abs(q[-1] - q[0]).max() < 1e-5


def test_recorded_limits_are_the_robot_files(triangle):
    task, _, data = triangle
    for stage in ("retime", "smooth"):
        names, limits = _limits(data, stage)
        assert np.array_equal(limits["velocity"], task.robot.limit_array("velocity", tuple(names)))
        assert np.array_equal(limits["acceleration"], [task.robot.limits[n].acceleration for n in names])
    names, limits = _limits(data, "smooth")
    assert np.array_equal(limits["jerk"], [task.robot.limits[n].jerk for n in names])


def test_retimed_samples_stay_within_velocity_and_acceleration_limits(triangle):
    task, run, data = triangle
    names, limits = _limits(data, "retime")
    df = data["/retime/sample"]
    t, q, qd, qdd = (
        df["t"].to_numpy(),
        _joints(df, "position", names),
        _joints(df, "velocity", names),
        _joints(df, "acceleration", names),
    )
    assert (np.abs(qd) / limits["velocity"]).max() <= SLACK
    assert (np.abs(qdd) / limits["acceleration"]).max() <= SLACK
    # the recorded velocities are the positions' derivative: mean velocity over each step within the limit too
    assert (np.abs(np.diff(q, axis=0) / np.diff(t)[:, None]) / limits["velocity"]).max() <= SLACK
    assert np.abs(np.diff(q, axis=0) / np.diff(t)[:, None] - 0.5 * (qd[1:] + qd[:-1])).max() < 1e-3
    assert np.allclose(qd[[0, -1]], 0) and np.allclose(
        q[0], data["/ik/sample"][[f"position.{n}" for n in names]].to_numpy()[0]
    )
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["retime.velocity_ratio_max"] == pytest.approx((np.abs(qd) / limits["velocity"]).max(), rel=1e-9)


def test_retimed_trajectory_passes_the_ik_samples(triangle):
    """Every IK sample lies on the retimed trajectory: within 1e-6 rad of the nearest point of its
    1 ms samples once the step between samples is accounted for (|q̇| dt / 2)."""
    _, run, data = triangle
    names, limits = _limits(data, "retime")
    q = _joints(data["/retime/sample"], "position", names)
    ik = _joints(data["/ik/sample"], "position", names)
    step = np.abs(np.diff(q, axis=0)).max()
    nearest = np.array([np.abs(q - sample).max(axis=1).min() for sample in ik])
    assert nearest.max() <= step / 2 + 1e-6
    assert json.loads((run / "metrics.json").read_text())["retime.path_deviation_max_rad"] <= 1e-6


def test_smoothed_samples_stay_within_velocity_acceleration_and_jerk_limits(triangle):
    _, run, data = triangle
    names, limits = _limits(data, "smooth")
    df = data["/smooth/sample"]
    t, q, qd, qdd = (
        df["t"].to_numpy(),
        _joints(df, "position", names),
        _joints(df, "velocity", names),
        _joints(df, "acceleration", names),
    )
    dt = np.diff(t)[:, None]
    assert (
        np.allclose(dt[:-1], 0.001) and 0.0005 <= dt[-1, 0] < 0.0015
    )  # every control period, the last step to the motion's end
    jerk = np.diff(qdd, axis=0) / dt
    for values, limit in (
        (qd, "velocity"),
        (qdd, "acceleration"),
        (jerk, "jerk"),
        (np.diff(q, axis=0) / dt, "velocity"),
        (np.diff(qd, axis=0) / dt, "acceleration"),
    ):
        assert (np.abs(values) / limits[limit]).max() <= SLACK, limit
    assert np.allclose(qd[[0, -1]], 0) and np.allclose(qdd[[0, -1]], 0)  # rest to rest
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["smooth.jerk_ratio_max"] == pytest.approx((np.abs(jerk) / limits["jerk"]).max(), rel=1e-6)
    # the deviation from the retimed reference, recomputed from both recordings
    retimed = data["/retime/sample"]
    reference = np.stack([np.interp(t, retimed["t"], retimed[f"position.{n}"]) for n in names], axis=1)
    assert metrics["smooth.path_deviation_max_rad"] == pytest.approx(np.abs(q - reference).max(), rel=1e-6, abs=1e-12)


def test_the_default_timing_is_jerk_limited_and_the_smooth_stage_passes_it_through(triangle):
    """The default retime is the jerk-limited timing (within the full velocity, acceleration and jerk limits): by third
    differences of the recorded positions every 1 ms too; the smooth stage records the same samples, deviation 0."""
    _, run, data = triangle
    assert data.setting("retime", "timing") == "jerk-limited" and "pass-through" in str(
        data.setting("smooth", "method")
    )
    names, limits = _limits(data, "retime")
    retimed, smoothed = data["/retime/sample"], data["/smooth/sample"]
    assert np.array_equal(_joints(retimed, "position", names), _joints(smoothed, "position", names))
    q = _joints(retimed, "position", names)[
        :-1
    ]  # every 1 ms (the last step, to the motion's end, is shorter or longer)
    for order, kind in ((1, "velocity"), (2, "acceleration"), (3, "jerk")):
        ratio = (np.abs(np.diff(q, order, axis=0)) / 1e-3**order / limits[kind]).max()
        assert 0.9 < ratio <= SLACK, kind  # within the limit, and near it: near time-optimal
    assert json.loads((run / "metrics.json").read_text())["smooth.path_deviation_max_rad"] == 0


def test_the_motion_stays_on_the_ik_path_within_1e_6_rad_and_10_um_at_the_hands(triangle):
    """Each IK sample's distance to the recorded motion (its 1 ms samples joined by the cubic through their positions
    and velocities, resampled every 0.05 ms, then as a polyline) is at most 1e-6 rad; PyBullet's forward kinematics of
    the nearest point puts the hand within 10 µm of where it puts it for the IK sample."""
    from scipy.interpolate import CubicHermiteSpline

    from tests.retime.test_jerk import _distance_to_polyline

    task, run, data = triangle
    names, _ = _limits(data, "retime")
    retimed = data["/retime/sample"]
    curve = CubicHermiteSpline(
        retimed["t"].to_numpy(), _joints(retimed, "position", names), _joints(retimed, "velocity", names)
    )
    dense = curve(np.arange(0.0, retimed["t"].iloc[-1], 5e-5))
    ik = _joints(data["/ik/sample"], "position", names)
    distance, nearest = _distance_to_polyline(ik, dense, nearest=True)
    assert distance.max() <= 1e-6
    with load_pybullet_robot(HUMANOID / "humanoid.urdf") as sim:
        sim.set_positions(list(task.initial_q), list(task.initial_q.values()))
        hands = []
        for q in (ik, nearest):
            positions = []
            for row in q:
                sim.set_positions(names, row)
                positions.append(sim.link_pose("left_hand")[:3, 3])
            hands.append(np.array(positions))
    assert np.linalg.norm(hands[0] - hands[1], axis=1).max() <= 1e-5
    assert (
        json.loads((run / "metrics.json").read_text())["retime.hand_deviation_max_m"] <= 1e-5
    )  # the stage's own measure agrees


def test_execution_tracks_the_command_within_2_mm_by_pybullet_fk(triangle):
    task, run, data = triangle
    df = data["/execute/sample"]
    names = [c.split(".", 1)[1] for c in df.columns if c.startswith("command.")]
    rows = np.linspace(0, len(df) - 1, 60).astype(int)
    with load_pybullet_robot(HUMANOID / "humanoid.urdf") as sim:
        sim.set_positions(list(task.initial_q), list(task.initial_q.values()))
        for k in rows:
            sim.set_positions(names, df.iloc[k][[f"command.{n}" for n in names]].to_numpy(float))
            commanded = sim.link_pose("left_hand")[:3, 3]
            measured = df.iloc[k][["hand_position.left.x", "hand_position.left.y", "hand_position.left.z"]].to_numpy(
                float
            )
            assert np.linalg.norm(measured - commanded) <= 2e-3, k
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["execute.tracking_error_max_m"] <= 2e-3
    assert metrics["execute.self_collisions"] == 0 == metrics["execute.environment_collisions"]
    assert (df["self_contacts"] == 0).all()


def test_rerun_file_has_an_animated_robot_per_stage(triangle):
    _, run, _ = triangle
    rerun = Path(sys.executable).parent / "rerun"
    printed = subprocess.run(
        [str(rerun), "rrd", "print", str(run / "run.rrd")],
        capture_output=True,
        text=True,
        env={**os.environ, "RERUN_ANALYTICS": "0"},
    ).stdout
    for entity in (
        "/ik/transforms/",
        "/retime/transforms/",
        "/smooth/transforms/",
        "/execute/transforms/",
        "/world/execute/left",
        "/plots/smooth/jerk_ratio/",
    ):
        assert entity in printed, entity


def test_task_timing_too_fast_for_a_tightened_limit_is_one_line_and_a_failed_run(tmp_path):
    """The triangle at its own timing (2 s per edge) with every velocity limit at 0.05 rad/s."""
    text = TRIANGLE.read_text().replace('robot = "../robots/humanoid"', f'robot = "{HUMANOID}"')
    task_file = tmp_path / "triangle.toml"
    task_file.write_text(text + '\n[limits]\nvelocity = 0.05\n\n[retime]\ntiming = "task"\n')
    result = CliRunner().invoke(
        app, ["run", str(task_file), "--ik", "mc-inverse", "--reps", "1", "--out", str(tmp_path / "runs")]
    )
    assert result.exit_code == 1  # a run that failed on valid input (2 is for input refused before running)
    lines = result.output.strip().splitlines()
    (run,) = (tmp_path / "runs" / "triangle").iterdir()
    assert lines[0] == "verdict: failed" and lines[2] == f"the run is kept as failed in {run}", result.output
    assert len(lines) == 3 and "keep_timing" in lines[1] and "velocity limit" in lines[1], result.output
    manifest = json.loads((run / "manifest.json").read_text())
    assert (
        manifest["status"] == "failed" and "velocity limit" in manifest["error"] and not (run / "metrics.json").exists()
    )


def test_stages_subset_stops_after_retime(tmp_path):
    run = record_run(load_task(TRIANGLE, 1), "mc-inverse", stages=["path", "ik", "retime"], out_dir=tmp_path).directory
    data = read_run(run)
    assert (
        "/retime/sample" in data.topics and "/smooth/sample" not in data.topics and "/execute/sample" not in data.topics
    )
    assert not any(key.startswith(("smooth.", "execute.")) for key in data.metrics)


def test_a_task_without_moves_runs_every_stage_at_rest(tmp_path):
    """bowl_grasp has no moves yet (it is planned, not tracked): one IK sample, a trajectory that
    does not move, and an execution that holds the start without contact."""
    run = record_run(TASKS / "bowl_grasp.toml", "dls-svd", out_dir=tmp_path).directory
    data = read_run(run)
    assert data.status == "complete"
    assert data.metrics["retime.duration_s"] == 0 and data.metrics["smooth.velocity_ratio_max"] == 0
    assert data.metrics["execute.self_collisions"] == 0 == data.metrics["execute.environment_collisions"]
    assert data.metrics["execute.tracking_error_max_m"] <= 2e-3


def test_a_method_whose_every_sample_failed_fails_at_its_stage(tmp_path):
    """PyBullet's IK allowed one iteration and a 1e-12 m tolerance (below its single precision) fails every sample of
    the triangle: the run ends failed at ik, naming the count, not violated after every stage."""
    from dualarm.errors import StageError
    from dualarm.ik.pose_level.pointwise import PyBulletIkSettings

    settings = PyBulletIkSettings(max_iterations=1, position_tolerance_m=1e-12)
    with pytest.raises(StageError, match=r"ik \(pybullet\): every one of the 601 samples failed"):
        record_run(load_task(TRIANGLE, 1), "pybullet", settings=settings, out_dir=tmp_path, record="ik")
    (directory,) = (tmp_path / "triangle").iterdir()
    run = read_run(directory)
    assert run.status == "failed" and run.manifest["error"].startswith("ik (pybullet): every one of the 601")
    assert len(run["/ik/sample"]) == 601 and (run["/ik/sample"]["status"] != 0).all()


def test_a_limit_robot_init_assumed_says_so_in_the_message_it_causes(tmp_path):
    """The triangle timed by the task on a humanoid whose robot.toml holds velocity limits of 0.05 rad/s listed as
    assumed (as robot init writes them): the refusal names the limit as assumed; with the task's own [limits] instead,
    nothing is said to be assumed."""
    import shutil

    from dualarm.model.robot import load_robot

    robot_dir = tmp_path / "humanoid"
    shutil.copytree(HUMANOID, robot_dir)
    slow = "\n".join(f"{n} = 0.05" for n in load_robot(HUMANOID).joint_names)
    toml = robot_dir / "robot.toml"
    toml.write_text(
        toml.read_text().replace(
            "[limits.acceleration]",
            f'[limits]\nassumed = ["velocity"]\n\n[limits.velocity]\n{slow}\n\n[limits.acceleration]',
            1,
        )
    )
    text = TRIANGLE.read_text().replace('robot = "../robots/humanoid"', f'robot = "{robot_dir}"')
    for limits, assumed in (("", True), ("[limits]\nvelocity = 0.05\n\n", False)):
        task_file = tmp_path / "triangle.toml"
        task_file.write_text(text + f'\n{limits}[retime]\ntiming = "task"\n')
        result = CliRunner().invoke(
            app, ["run", str(task_file), "--ik", "mc-inverse", "--reps", "1", "--out", str(tmp_path / "runs")]
        )
        assert result.exit_code == 1 and "velocity limit" in result.output, result.output
        said = "an assumed velocity limit: robot init's default, not the robot's data" in result.output
        assert said == assumed, result.output


def test_an_ik_path_through_a_box_is_a_contact_violation_without_the_execute_stage():
    """``--stages path,ik``: a box put where TV-GDD's left hand is at the middle sample makes the run violated, with
    a contact violation of the ik stage naming the box (it was 'complete': collisions were judged only at execute).
    PyBullet, given the IK sample at the time the violation names, finds a link of the robot overlapping the box."""
    from dataclasses import replace

    from dualarm.model.kinematics import ChainKinematics
    from dualarm.run import build_stages, run_stages
    from dualarm.sim.world import add_environment, in_contact, pb
    from dualarm.tasks.schema import EnvironmentObject

    task = load_task(TRIANGLE, 1)
    clean = run_stages(task, build_stages(task, "tvgdd", stages=("path", "ik")))
    assert clean.verdict.status == "complete"
    path = clean.joint_path
    chain = task.hand_chain_from_root("left")
    q = {**path.fixed, **dict(zip(path.joint_names, path.q[len(path.t) // 2], strict=True))}
    hand = ChainKinematics.of(chain).pose(np.array([q[n] for n in chain.joint_names]))[:3, 3]
    box = EnvironmentObject(
        name="box", shape="box", pose={"position": tuple(hand), "rpy": (0.0, 0.0, 0.0)}, size_m=(0.04, 0.04, 0.04)
    )
    boxed = replace(task, spec=task.spec.model_copy(update={"environment": (box,)}))
    verdict = run_stages(boxed, build_stages(boxed, "tvgdd", stages=("path", "ik"))).verdict
    contacts = [v for v in verdict.violations if v.check == "contact"]
    assert verdict.status == "violated" and contacts and all(v.stage == "ik" for v in contacts)
    assert all("box" in v.message for v in contacts), contacts
    at = int(np.flatnonzero(np.isclose(path.t, contacts[0].t_s))[0])
    with load_pybullet_robot(task.robot.urdf.path) as sim:
        (body,) = add_environment(sim, (box,))
        sim.set_positions(path.joint_names, path.q[at])
        pb.performCollisionDetection(physicsClientId=sim.client)
        assert any(in_contact(p) for p in pb.getContactPoints(sim.body, body, physicsClientId=sim.client))
