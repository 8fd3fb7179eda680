"""MC-Inverse's arm angle: the sweep of feasible psi per branch, the default ``auto`` mode, the profile a run records,
and the joint named when a branch leaves the limits."""

import json
import re

import numpy as np
import pybullet as pb
import pytest

from dualarm.errors import StageError
from dualarm.ik.analytic.mc_inverse import McInverse, mc_inverse, sweep_arm_angle
from dualarm.ik.analytic.mc_path import settings_for, solve_mc_inverse
from dualarm.model.kinematics import to_arm_frame
from dualarm.model.poses import pose_matrix
from dualarm.paths import build_reference
from dualarm.sim.world import load_pybullet_robot
from dualarm.tasks import load_task
from tests.helpers import HUMANOID, TASKS

#: triangle.toml's waypoint A, in the robot base frame.
POSE_A = pose_matrix([0.300, 0.270, 1.003], [-1.572, -0.975, -1.570])


def _pybullet_check(sim, names, q, target) -> tuple[bool, bool]:
    """(the hand reaches ``target`` to 1e-6 in PyBullet, q within PyBullet's joint limits)."""
    sim.set_positions(names, q)
    reached = np.abs(sim.link_pose("left_hand") - target).max() < 1e-6
    index = {
        pb.getJointInfo(sim.body, i, physicsClientId=sim.client)[1].decode(): i
        for i in range(pb.getNumJoints(sim.body, physicsClientId=sim.client))
    }
    info = [pb.getJointInfo(sim.body, index[n], physicsClientId=sim.client) for n in names]
    inside = all(i[8] - 1e-12 <= v <= i[9] + 1e-12 for i, v in zip(info, q, strict=True))
    return reached, inside


@pytest.mark.integration
def test_sweep_intervals_agree_with_single_solves_checked_in_pybullet(humanoid):
    """Waypoint A of the triangle: at sampled psi inside a branch's intervals a single
    mc_inverse solve gives joints that PyBullet puts on the pose within PyBullet's joint limits;
    at grid psi outside every interval of the branch, the candidate misses the pose or the limits."""
    chain = humanoid.hand_chain("left")
    sweep = sweep_arm_angle(McInverse.of(chain), to_arm_frame(humanoid, "left", POSE_A), np.radians(2.0))
    rng = np.random.default_rng(0)
    inside_checked = outside_checked = 0
    with load_pybullet_robot(humanoid.urdf.path) as sim:
        assert np.abs(sim.link_pose("base_link") - np.eye(4)).max() < 1e-12  # the robot frame is PyBullet's world
        for b in range(8):
            intervals = sweep.intervals(b)
            for lo, hi in intervals:
                for psi in (lo, hi, rng.uniform(lo, hi)):
                    psi = float(np.angle(np.exp(1j * psi)))
                    q = mc_inverse(humanoid, "left", POSE_A, psi).q[b]
                    assert _pybullet_check(sim, chain.joint_names, q, POSE_A) == (True, True), (b, psi)
                    inside_checked += 1
            outside = np.flatnonzero(sweep.reason[:, b] != 0)
            for g in rng.choice(outside, min(10, outside.size), replace=False) if outside.size else []:
                q = mc_inverse(humanoid, "left", POSE_A, float(sweep.psi_rad[g])).q[b]
                reached, within = _pybullet_check(sim, chain.joint_names, q, POSE_A)
                assert not (reached and within) or np.isclose(np.sin(q[[1, 3, 5]]), 0, atol=1e-6).any(), (
                    b,
                    sweep.psi_rad[g],
                )
                outside_checked += 1
    assert inside_checked >= 24 and outside_checked >= 10


def test_sweep_from_the_command_line_in_both_frames_agrees(humanoid):
    """``ik srs --sweep --json`` of waypoint A in the robot frame and of the same pose in the chain frame give the same
    intervals, each output naming its frame."""
    from scipy.spatial.transform import Rotation
    from typer.testing import CliRunner

    from dualarm.cli import app

    runner = CliRunner()
    chain_pose = to_arm_frame(humanoid, "left", POSE_A)
    outputs = {}
    for frame, T in (("robot", POSE_A), ("chain", chain_pose)):
        p, rpy = T[:3, 3], Rotation.from_matrix(T[:3, :3]).as_euler("xyz")
        result = runner.invoke(
            app,
            [
                "ik",
                "srs",
                str(HUMANOID),
                "--arm",
                "left",
                "--pose",
                *(repr(float(v)) for v in [*p, *rpy]),
                "--sweep",
                "--step",
                "2",
                "--json",
                "--frame",
                frame,
            ],
        )
        assert result.exit_code == 0, result.output
        outputs[frame] = json.loads(result.stdout)
        assert outputs[frame]["frame"]["kind"] == frame
    assert outputs["robot"]["frame"]["link"] == humanoid.urdf.root and outputs["chain"]["frame"]["link"] == "torso"
    for a, b in zip(outputs["robot"]["branches"], outputs["chain"]["branches"], strict=True):
        assert a["valid_samples"] == b["valid_samples"] and np.allclose(
            a["intervals_rad"] or 0, b["intervals_rad"] or 0
        )


def _triangle(tmp_path, edit=lambda t: t):
    text = (TASKS / "triangle.toml").read_text().replace('robot = "../robots/humanoid"', f'robot = "{HUMANOID}"')
    path = tmp_path / "triangle.toml"
    path.write_text(edit(text))
    return load_task(path, 1)


def test_the_default_mode_is_auto_and_chooses_what_auto_chooses(tmp_path):
    """The triangle with its ``mode = "auto"`` line removed (the default) gives the joints of the shipped file's
    explicit auto, to the bit."""
    explicit = load_task(TASKS / "triangle.toml", 1)
    default = _triangle(tmp_path, lambda t: t.replace('mode = "auto"\n', ""))
    assert 'mode = "auto"' not in default.text and default.spec.arm_angle.mode == "auto"
    a = solve_mc_inverse(explicit.robot, build_reference(explicit), explicit.initial_q, settings_for(explicit))
    b = solve_mc_inverse(default.robot, build_reference(default), default.initial_q, settings_for(default))
    assert np.array_equal(a.q, b.q)


@pytest.mark.integration
def test_a_run_records_the_profile_in_its_manifest_and_metrics(tmp_path):
    """The manifest's ik settings and metrics.json hold the branch and the psi; checked against
    eq (1) from PyBullet's frames of the recorded joints, and the branch against a single solve."""
    from dualarm.record.readback import read_run
    from dualarm.run import record_run
    from tests.reproduce.test_reproduce import pybullet_arm_angle

    run_dir = record_run(
        load_task(TASKS / "triangle.toml", 1), "mc-inverse", stages=("path", "ik"), out_dir=tmp_path
    ).directory
    manifest = json.loads((run_dir / "manifest.json").read_text())
    metrics = json.loads((run_dir / "metrics.json").read_text())
    profile = manifest["settings"]["ik"]["arm_angle_profile"]["left"]
    assert profile["mode"] == "auto" and profile["branch"] == metrics["ik.arm_angle_branch.left"]
    run = read_run(run_dir)
    sample = run["/ik/sample"]
    names = [c.split(".", 1)[1] for c in sample.columns if c.startswith("position.left")]
    q = sample.iloc[0][[f"position.{n}" for n in names]].to_numpy(float)
    with load_pybullet_robot(HUMANOID / "humanoid.urdf") as sim:
        sim.set_positions(names, q)
        psi = pybullet_arm_angle(sim, "left")
        hand = sim.link_pose("left_hand")
    low, high = metrics["ik.arm_angle_min_rad.left"], metrics["ik.arm_angle_max_rad.left"]
    assert low - 1e-6 <= psi <= high + 1e-6
    if "value_rad" in profile:
        assert profile["value_rad"] == pytest.approx(psi, abs=1e-6)
    candidates = mc_inverse(load_task(TASKS / "triangle.toml", 1).robot, "left", hand, psi).q
    assert np.abs(candidates[profile["branch"] - 1] - q).max() < 1e-6


def test_a_branch_leaving_the_limits_names_the_joint_the_sample_and_the_way_out(tmp_path, humanoid):
    """carry_box with the left arm angle held at 2.5 rad: the kept branch leaves a limit; the error names that joint
    (checked against the robot's limits), the sample, the time, and suggests auto."""
    text = (TASKS / "carry_box.toml").read_text().replace('robot = "../robots/humanoid"', f'robot = "{HUMANOID}"')
    path = tmp_path / "carry_box.toml"
    path.write_text(text.replace('mode = "initial"', 'mode = "constant"\nvalue_rad = { left = 2.5, right = 0.0 }'))
    task = load_task(path, 1)
    ref = build_reference(task)
    with pytest.raises(StageError) as failure:
        solve_mc_inverse(task.robot, ref, task.initial_q, settings_for(task))
    message = str(failure.value)
    match = re.search(
        r"sample (\d+) \(t = ([\d.]+) s.*: (left_\w+) at (-?[\d.]+) rad is ([\d.]+) rad \(.* deg\)"
        r" (above its upper|below its lower) limit",
        message,
    )
    assert match, message
    assert 'mode = "auto"' in message and "range_rad" in message
    joint, value, excess = match.group(3), float(match.group(4)), float(match.group(5))
    assert failure.value.joint == joint and failure.value.sample == int(match.group(1))
    lim = humanoid.limits[joint]
    assert excess == pytest.approx(value - lim.upper if "above" in match.group(6) else lim.lower - value, abs=2e-4)
    assert float(match.group(2)) == pytest.approx(ref.t[int(match.group(1))], abs=1e-3)
