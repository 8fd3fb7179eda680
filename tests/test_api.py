"""``import dualarm``: the documented API, its contracts, and bad input at its entry points.

Numbers are checked against independent computations: PyBullet's forward kinematics for the
frame helpers, the Euler step recomputed from the joint path for the one control period, a task
file against the same task built from a dict.
"""

from __future__ import annotations

import ast
import dataclasses
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

import dualarm
from dualarm.errors import DualarmError, InvalidArgumentError
from tests.helpers import TASKS

STUB = Path(dualarm.__file__).with_suffix(".pyi")


def test_all_is_the_stub_and_every_name_is_documented():
    stub = {
        alias.asname or alias.name
        for node in ast.parse(STUB.read_text()).body
        if isinstance(node, ast.ImportFrom)
        for alias in node.names
    }
    assert set(dualarm.__all__) == stub
    for name in dualarm.__all__:
        value = getattr(dualarm, name)
        if callable(value):
            assert value.__doc__ and value.__doc__.strip(), f"dualarm.{name} has no docstring"


@pytest.mark.integration
def test_import_is_light():
    code = (
        "import sys, dualarm; print(sorted(m for m in ('casadi', 'toppra', 'ruckig', 'pybullet', 'rerun', 'pandas')"
        " if m in sys.modules))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]"


@pytest.mark.integration
@pytest.mark.parametrize("module", ["dualarm.contracts", "dualarm.stages"])
def test_the_contracts_and_the_stages_import_no_heavy_library(module):
    """Stages import what they run on first use; the products passed between them are numpy alone."""
    heavy = ("casadi", "toppra", "ruckig", "pybullet", "matplotlib", "rerun", "pandas", "scipy")
    code = f"import sys, {module}; print(sorted(m for m in {heavy!r} if m in sys.modules))"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]"


def test_every_registry_solver_is_exported_and_agrees_with_its_module():
    from dualarm.ik.pose_level.pointwise import SETTINGS
    from dualarm.plan.problem import PLANNERS

    for m in dualarm.METHODS.values():
        assert m.solve.__name__ in dualarm.__all__ and getattr(dualarm, m.solve.__name__) is m.solve, m.name
        if m.name in SETTINGS:
            assert SETTINGS[m.name] is m.settings_type
    assert PLANNERS == dualarm.methods.PLANNERS


def test_registry_matches_the_cli():
    from dualarm.methods import IK_METHODS, PLANNERS

    assert IK_METHODS == ("tvgdd", "pinv", "mc-inverse", "sew", "trac-ik", "pybullet", "dls-svd", "ikfast-style")
    assert PLANNERS == ("mcikrrt", "ompl-rrtconnect")
    for m in dualarm.METHODS.values():
        assert callable(m.solve) and isinstance(m.settings_for(), m.settings_type)
    assert {n for n, m in dualarm.METHODS.items() if m.needs_srs} == {"mc-inverse", "ikfast-style"}
    assert {n for n, m in dualarm.METHODS.items() if m.needs_sew} == {"sew"}
    assert {n for n, m in dualarm.METHODS.items() if not m.orientation} == {"tvgdd", "pinv"}


@pytest.fixture(scope="module")
def robot():
    return dualarm.load_robot("humanoid")


@pytest.mark.integration
def test_frame_helpers_against_pybullet(robot):
    from dualarm.sim.world import load_pybullet_robot

    q = dict(robot.home("ready"))
    q.update(waist_yaw=0.3, waist_pitch=-0.2)
    with load_pybullet_robot(robot.urdf.path) as sim:
        sim.set_positions(list(q), list(q.values()))
        hand, torso = sim.link_pose(robot.hand_chain("left").tip), sim.link_pose(robot.hand_chain("left").base)
    np.testing.assert_allclose(dualarm.hand_pose(robot, "left", q), hand, atol=1e-6)
    np.testing.assert_allclose(dualarm.to_arm_frame(robot, "left", hand, q), np.linalg.inv(torso) @ hand, atol=1e-6)


@pytest.mark.parametrize(
    ("pose", "message"),
    [
        (np.eye(3), r"^pose: expected shape \(4, 4\), got \(3, 3\)$"),
        (np.full((4, 4), np.nan), r"^pose: is not finite"),
        (np.diag([2.0, 1.0, 1.0, 1.0]), r"^pose: is not a rigid transform"),
        ("left", r"^pose: expected an array of numbers"),
    ],
)
def test_mc_inverse_refuses_bad_poses_naming_the_argument(robot, pose, message):
    with pytest.raises(InvalidArgumentError, match=message) as error:
        dualarm.mc_inverse(robot, "left", pose, psi=0.0)
    assert isinstance(error.value, ValueError) and error.value.argument == "pose"


def test_mc_inverse_refuses_a_nan_arm_angle_and_a_bad_seed(robot):
    pose = dualarm.hand_pose(robot, "left", "ready")
    with pytest.raises(InvalidArgumentError, match="^psi: is not finite"):
        dualarm.mc_inverse(robot, "left", pose, psi=float("nan"))
    solution = dualarm.mc_inverse(robot, "left", pose, psi=0.0)
    with pytest.raises(InvalidArgumentError, match=r"^seed: expected shape \(7,\)"):
        solution.nearest(np.zeros(6))
    with pytest.raises(InvalidArgumentError, match="^seed: has no value for joint"):
        solution.nearest({"waist_yaw": 0.0})


def test_mc_inverse_one_pose_is_the_path_solvers_branch(robot):
    """The helper's nearest candidate is the joint the path solver keeps at the same pose, and reaches it."""
    ready = robot.home("ready")
    pose = dualarm.load_task("triangle").waypoint_pose("A")
    solution = dualarm.mc_inverse(robot, "left", pose, -1.0)
    q = solution.nearest(ready)
    settings = dualarm.ArmAngle(mode="constant", value_rad={"left": -1.0})
    path = dualarm.solve_mc_inverse(
        robot, dualarm.CartesianReference.from_poses(0.01, {"left": pose[None]}), ready, settings
    )
    np.testing.assert_array_equal(path.q[0], q)
    np.testing.assert_allclose(
        dualarm.hand_pose(robot, "left", {**ready, **dict(zip(solution.joint_names, q, strict=True))}), pose, atol=1e-9
    )


def test_reference_checks_its_arguments():
    good = np.repeat(np.eye(4)[None], 3, axis=0)
    with pytest.raises(InvalidArgumentError, match="^period_s: must be a positive number"):
        dualarm.CartesianReference.from_poses(0.0, {"left": good})
    bad = good.copy()
    bad[1, 0, 3] = np.nan
    with pytest.raises(InvalidArgumentError, match=r"^poses\[left\]: is not finite at index \(1, 0, 3\)"):
        dualarm.CartesianReference.from_poses(0.01, {"left": bad})
    with pytest.raises(InvalidArgumentError, match="^hands"):
        dualarm.CartesianReference.from_poses(0.01, {"left": good, "right": good[:2]})
    ref = dualarm.CartesianReference.from_poses(0.01, {"left": good})
    with pytest.raises(InvalidArgumentError, match="^t: sample times must be arange"):
        dataclasses.replace(ref, t=ref.t * 2)


def test_solvers_refuse_an_unknown_hand_and_joint(robot):
    ref = dualarm.CartesianReference.from_poses(0.01, {"middle": np.eye(4)[None]})
    with pytest.raises(InvalidArgumentError, match="^reference.hands: robot 'humanoid' has no hand 'middle'"):
        dualarm.solve_tvgdd(robot, ref)
    ref = dualarm.CartesianReference.from_poses(0.01, {"left": dualarm.hand_pose(robot, "left", "ready")[None]})
    with pytest.raises(InvalidArgumentError, match=r"^q0.elbow: no such joint"):
        dualarm.solve_mc_inverse(robot, ref, {"elbow": 1.0})
    with pytest.raises(InvalidArgumentError, match="^q0: robot 'humanoid' has no home pose 'sitting'"):
        dualarm.solve_pinv(robot, ref, "sitting")
    with pytest.raises(InvalidArgumentError, match="^scheme: unknown TV-GDD scheme 'fast'"):
        dualarm.TvgddSettings(scheme="fast")


def test_tvgdd_steps_at_the_references_period(robot):
    """The period is the reference's alone: the settings have none, and q advances by period * qd."""
    assert "period_s" not in {f.name for f in dataclasses.fields(dualarm.TvgddSettings)}
    start = dualarm.hand_pose(robot, "left", "ready")
    poses = np.repeat(start[None], 41, axis=0)
    poses[:, 2, 3] += 0.02 * np.sin(np.linspace(0.0, np.pi, 41)) ** 2
    for period in (0.01, 0.02):
        path = dualarm.solve_tvgdd(robot, dualarm.CartesianReference.from_poses(period, {"left": poses}), "ready")
        np.testing.assert_allclose(np.diff(path.q, axis=0), period * path.qd[:-1], atol=1e-12)
        np.testing.assert_allclose(np.diff(path.t), period)


def test_task_from_a_dict_is_the_task_from_its_file():
    data = tomllib.loads((TASKS / "triangle.toml").read_text())
    from_dict = dualarm.task_from_dict(data, base_dir=TASKS, repetitions=2)
    from_file = dualarm.load_task(TASKS / "triangle.toml", 2)
    a, b = dualarm.build_reference(from_dict), dualarm.build_reference(from_file)
    np.testing.assert_array_equal(a.hands["left"].poses, b.hands["left"].poses)
    assert from_dict.file is None and from_dict.source_name == "triangle.json"
    with pytest.raises(DualarmError, match=r"^<dict>:moves\[0\].left.to: no waypoint 'D'"):
        dualarm.task_from_dict({**data, "moves": [{"duration_s": 1.0, "left": {"to": "D"}}]}, base_dir=TASKS)
    robot = dualarm.load_robot("humanoid")
    assert (
        dualarm.task_from_dict(
            {k: v for k, v in data.items() if k not in ("robot", "title", "source")}, robot=robot
        ).robot.name
        == "humanoid"
    )


@pytest.mark.integration
def test_run_in_memory_writes_nothing_and_every_sink_sees_the_same(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    task = dualarm.load_task("triangle", 2)
    sink = dualarm.MetricsSink()
    result = dualarm.run_task(task, "pinv", stages=("path", "ik"), sink=sink)
    assert not list(tmp_path.iterdir())
    assert sink.values == result.metrics and set(sink.stage_seconds) == {"path", "ik"}
    assert result.joint_path is not None and result.retimed is None and result.directory is None
    assert isinstance(sink, dualarm.Sink) and isinstance(dualarm.NullSink(), dualarm.Sink)
    recorded = dualarm.record_run(task, "pinv", stages=("path", "ik"), out_dir=tmp_path / "runs")
    assert recorded.metrics == pytest.approx(
        result.metrics | {k: recorded.metrics[k] for k in result.metrics if k.startswith("ik.solve_time")}
    )
    assert dualarm.read_run(recorded.directory).metrics.keys() == result.metrics.keys()


def test_every_stage_has_the_one_shape():
    from dualarm.run import build_stages

    task = dualarm.load_task("triangle", 1)
    stages = build_stages(task, "mc-inverse")
    assert [s.name for s in stages] == ["path", "ik", "retime", "smooth", "approach", "execute"]
    for stage in stages:
        assert callable(stage) and isinstance(stage.settings_record(), dict)
    with pytest.raises(DualarmError, match="mc-inverse takes ArmAngle settings, not TvgddSettings"):
        build_stages(task, "mc-inverse", settings=dualarm.TvgddSettings())


def test_a_reference_of_ones_own_with_repetitions_is_laid_out_as_a_tasks(robot):
    """The triangle's reference over two repetitions, rebuilt with from_poses and its own rep, is solved by MC-Inverse
    (auto) into joints that repeat; repetition_deviation is the largest |q_r - q_0| at the same places, computed here
    from the joints; a layout whose repetitions are as long as the first (which also holds the start pose) is refused
    naming rep (it raised IndexError deep in the arm-angle search)."""
    task = dualarm.load_task("triangle", 2)
    reference = dualarm.build_reference(task)
    poses = {h: reference.hands[h].poses for h in reference.hands}
    own = dualarm.CartesianReference.from_poses(reference.period_s, poses, rep=reference.rep)
    path = dualarm.solve_mc_inverse(robot, own, task.initial_q, dualarm.ArmAngle(mode="auto"))
    first, second = np.flatnonzero(own.rep == 0), np.flatnonzero(own.rep == 1)
    assert len(second) == len(first) - 1
    expected = np.abs(path.q[second] - path.q[first[1:]]).max()
    assert dualarm.repetition_deviation(path, own) == pytest.approx(expected, abs=0.0)
    once = dualarm.CartesianReference.from_poses(reference.period_s, {h: T[first] for h, T in poses.items()})
    single = dualarm.solve_mc_inverse(robot, once, task.initial_q, dualarm.ArmAngle(mode="auto"))
    assert np.isnan(dualarm.repetition_deviation(single, once))  # one repetition: nothing to compare
    naive = np.r_[np.zeros(len(first) - 1, int), np.ones(len(first), int)]  # the start pose not in the first
    with pytest.raises(InvalidArgumentError, match="^rep: repetition 1 has .* one sample fewer than the first"):
        dualarm.CartesianReference.from_poses(reference.period_s, poses, rep=naive)
    with pytest.raises(InvalidArgumentError, match="^rep: repetition 0 is followed by 2: no gaps"):
        dualarm.CartesianReference.from_poses(reference.period_s, poses, rep=np.where(own.rep == 1, 2, 0))
