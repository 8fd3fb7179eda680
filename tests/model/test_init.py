"""``dualarm robot init`` / ``robot poses`` / ``robot check``'s limit refusal, on robots nobody here wrote:
pybullet_data's KUKA iiwa (S-R-S), Franka Panda (not S-R-S) and the dual iiwa of robots/dual_iiwa.

Every number is compared with PyBullet loading the original URDF (or, for the dual iiwa, the URDF
its build script assembles), never with our own output."""

from __future__ import annotations

import importlib.util
import json
import os
import re
import shutil
from pathlib import Path
from unittest import mock

import numpy as np
import pybullet_data
import pytest
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from dualarm.cli import app
from dualarm.describe.init import DEFAULT_VELOCITY_RAD_S, init_robot
from dualarm.model.kinematics import ChainKinematics
from dualarm.model.robot import load_robot
from dualarm.quiet import c_output_silenced
from dualarm.sim.world import load_pybullet_robot, pb
from tests.helpers import HUMANOID, REPO

runner = CliRunner()
DATA = Path(pybullet_data.getDataPath())
IIWA, PANDA = DATA / "kuka_iiwa" / "model.urdf", DATA / "franka_panda" / "panda.urdf"
DUAL_IIWA = REPO / "robots" / "dual_iiwa"


def _build_module():
    spec = importlib.util.spec_from_file_location("dual_iiwa_build", DUAL_IIWA / "build.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """name -> (the source URDF as PyBullet loads it, RobotInit) for the iiwa, the Panda and the dual iiwa (assembled by
    build.py, meshes through ROS_PACKAGE_PATH)."""
    root = tmp_path_factory.mktemp("init")
    dual = root / "src" / "dual_iiwa.urdf"
    dual.parent.mkdir()
    dual.write_text(_build_module().assemble())
    for_pybullet = root / "dual_iiwa_absolute.urdf"  # PyBullet knows no ROS_PACKAGE_PATH
    for_pybullet.write_text(dual.read_text().replace("package://kuka_iiwa/", f"{DATA}/kuka_iiwa/"))
    out = {}
    with mock.patch.dict(os.environ, {"ROS_PACKAGE_PATH": str(DATA)}):
        for name, source, reference in (
            ("iiwa", IIWA, IIWA),
            ("panda", PANDA, PANDA),
            ("dual_iiwa", dual, for_pybullet),
        ):
            out[name] = (reference, init_robot(source, root / name))
    return out


def _pybullet_link_poses(urdf: Path, q: dict[str, float], links: list[str]) -> dict[str, np.ndarray]:
    with load_pybullet_robot(urdf) as sim:
        sim.set_positions(list(q), list(q.values()))
        return {link: sim.link_pose(link) for link in links}


@pytest.mark.integration
@pytest.mark.parametrize("name", ["iiwa", "panda", "dual_iiwa"])
def test_chains_fk_equals_pybullet_on_the_source_urdf(made, name):
    source, result = made[name]
    robot = result.robot
    assert len(robot.hands) == (2 if name == "dual_iiwa" else 1)
    rng = np.random.default_rng(3)
    with mock.patch.dict(os.environ, {"ROS_PACKAGE_PATH": str(DATA)}), load_pybullet_robot(source) as sim:
        for hand in robot.hands:
            arm = robot.hand_chain(hand)
            assert arm.dof == 7
            chain = robot.chain_between(robot.urdf.root, arm.tip)
            lower, upper = robot.lower_upper(chain.joint_names)
            for q in rng.uniform(lower, upper, size=(20, chain.dof)):
                sim.set_positions(chain.joint_names, q)
                T = ChainKinematics.of(chain).pose(q)
                assert np.allclose(T, sim.link_pose(arm.tip), atol=2e-6)


@pytest.mark.integration
def test_chain_choice(made):
    assert [(a.hand, a.base, a.tip) for a in made["iiwa"][1].arms] == [("left", "lbr_iiwa_link_0", "lbr_iiwa_link_7")]
    # the tool frame hung below the hand by a fixed joint, above the prismatic fingers
    assert [(a.hand, a.tip) for a in made["panda"][1].arms] == [("left", "panda_grasptarget")]
    urdf = made["panda"][1].robot.urdf
    assert [(j.parent, j.type) for j in urdf.joints if j.child == "panda_grasptarget"] == [("panda_hand", "fixed")]
    arms = made["dual_iiwa"][1].arms
    assert [(a.hand, a.base, a.tip) for a in arms] == [
        ("left", "torso", "left_lbr_iiwa_link_7"),
        ("right", "torso", "right_lbr_iiwa_link_7"),
    ]
    # left is the arm on +y, as PyBullet places it
    poses = _pybullet_link_poses(made["dual_iiwa"][0], {}, ["left_lbr_iiwa_link_1", "right_lbr_iiwa_link_1"])
    assert poses["left_lbr_iiwa_link_1"][1, 3] > 0 > poses["right_lbr_iiwa_link_1"][1, 3]


def _axis_line(sim, joint: str) -> tuple[np.ndarray, np.ndarray]:
    """A joint's axis as (point, unit direction) in the world, from PyBullet's child link frame."""
    index = sim.joint_index[joint]
    info = pb.getJointInfo(sim.body, index, physicsClientId=sim.client)
    state = pb.getLinkState(sim.body, index, computeForwardKinematics=True, physicsClientId=sim.client)
    R = np.asarray(pb.getMatrixFromQuaternion(state[5])).reshape(3, 3)
    return np.asarray(state[4]), R @ np.asarray(info[13])


def _line_distance(a, b) -> float:
    (p, u), (q, v) = a, b
    n = np.cross(u, v)
    return (
        float(abs(np.dot(q - p, n)) / np.linalg.norm(n))
        if np.linalg.norm(n) > 1e-9
        else float(np.linalg.norm(np.cross(q - p, u)))
    )


@pytest.mark.integration
def test_srs_verdicts(made):
    assert all(a.srs is None for name in ("iiwa", "dual_iiwa") for a in made[name][1].arms)
    (panda,) = made["panda"][1].arms
    assert re.search(
        r"axes of panda_joint5, panda_joint6, panda_joint7 do not meet in one point \(miss 0\.05\d+ m\)", panda.srs
    )
    text = (made["panda"][1].directory / "robot.toml").read_text()
    assert "not S-R-S" in text and "miss 0.05" in text
    # PyBullet's own joint axes: joints 6 and 7 pass d apart, so every point is at least d/2 from one of them;
    # the reported miss (the least-squares point's largest distance to the three axes) lies between d/2 and d
    miss = float(re.search(r"miss ([0-9.]+) m", panda.srs).group(1))
    with mock.patch.dict(os.environ, {"ROS_PACKAGE_PATH": str(DATA)}), load_pybullet_robot(PANDA) as sim:
        sim.set_positions(["panda_joint4", "panda_joint6"], [-1.0, 1.0])
        d = _line_distance(_axis_line(sim, "panda_joint6"), _axis_line(sim, "panda_joint7"))
    assert d > 0.08 and d / 2 <= miss <= d


@pytest.mark.integration
@pytest.mark.parametrize("name", ["iiwa", "panda", "dual_iiwa"])
def test_ready_is_inside_limits_collision_free_and_in_front(made, name):
    source, result = made[name]
    robot = result.robot
    ready = robot.home("ready")
    with mock.patch.dict(os.environ, {"ROS_PACKAGE_PATH": str(DATA)}), c_output_silenced():
        client = pb.connect(pb.DIRECT)
        try:
            body = pb.loadURDF(
                str(source),
                useFixedBase=True,
                flags=pb.URDF_USE_SELF_COLLISION | pb.URDF_USE_SELF_COLLISION_EXCLUDE_ALL_PARENTS,
                physicsClientId=client,
            )
            index = {
                pb.getJointInfo(body, i, physicsClientId=client)[1].decode(): i
                for i in range(pb.getNumJoints(body, physicsClientId=client))
            }

            def position(joint: str) -> np.ndarray:
                """Where PyBullet puts ``joint``'s child link frame now."""
                return np.array(
                    pb.getLinkState(body, index[joint], computeForwardKinematics=True, physicsClientId=client)[4]
                )

            def tip_joint(arm) -> str:
                return next(
                    j for j in index if pb.getJointInfo(body, index[j], physicsClientId=client)[12].decode() == arm.tip
                )

            first = {arm.hand: robot.chains[arm.chain].joint_names[0] for arm in result.arms}

            def stretched_length(arm) -> float:
                """The link frames' distances added up from the first joint's to the tip's, at the zero pose."""
                joints = [j.name for j in robot.chains[arm.chain].joints]
                points = [position(j) for j in joints[joints.index(first[arm.hand]) :]]
                return sum(np.linalg.norm(b - a) for a, b in zip(points, points[1:], strict=False))

            stretched = {arm.hand: stretched_length(arm) for arm in result.arms}  # as robot init measures an arm
            for joint, value in ready.items():
                info = pb.getJointInfo(body, index[joint], physicsClientId=client)
                assert info[8] <= value <= info[9], joint
                pb.resetJointState(body, index[joint], value, physicsClientId=client)
            pb.performCollisionDetection(physicsClientId=client)
            penetrating = [p for p in pb.getContactPoints(body, body, physicsClientId=client) if p[8] < 0]
            # a pair joined through links without geometry (a Panda's hand and link 7) is not an ancestor pair to
            # PyBullet's flag when the link between has none
            touching = {tuple(sorted((a, b))) for a, b in result.touching_pairs} | set(result.disabled_pairs)
            names = {i: pb.getJointInfo(body, i, physicsClientId=client)[12].decode() for i in index.values()}
            assert not [p for p in penetrating if tuple(sorted((names[p[3]], names[p[4]]))) not in touching]
            for arm in result.arms:
                hand, shoulder = position(tip_joint(arm)), position(first[arm.hand])
                assert hand[0] > 0.1, arm.hand
                assert 0.4 - 1e-6 <= np.linalg.norm(hand - shoulder) / stretched[arm.hand] <= 0.8 + 1e-6, (
                    arm.hand
                )  # elbow bent (init.READY_REACH)
                assert abs(hand[1]) - abs(shoulder[1]) <= 0.25 * stretched[arm.hand] + 1e-6, (
                    arm.hand
                )  # not out to the side (init.READY_OUTWARD)
        finally:
            pb.disconnect(physicsClientId=client)


@pytest.mark.integration
@pytest.mark.parametrize("name", ["iiwa", "panda", "dual_iiwa"])
def test_robot_poses_equal_pybullet_link_poses(made, name):
    _, result = made[name]
    robot = result.robot
    done = runner.invoke(app, ["robot", "poses", str(result.directory), "--json"])
    assert done.exit_code == 0, done.output
    rows = json.loads(done.stdout)
    assert {(r["home"], r["hand"]) for r in rows} == {(h, hand) for h in robot.homes for hand in robot.hands}
    for row in rows:
        tip = robot.hand_chain(row["hand"]).tip
        T = _pybullet_link_poses(robot.urdf.path, dict(robot.home(row["home"])), [tip])[tip]
        assert np.allclose(row["position_m"], T[:3, 3], atol=1e-6)
        assert np.allclose(Rotation.from_euler("xyz", row["rpy_rad"]).as_matrix(), T[:3, :3], atol=1e-6)
        srs = all(a.srs is None for a in result.arms)
        assert (row["arm_angle_rad"] is not None) == (
            srs and row["home"] == "ready"
        )  # at zero the iiwa's shoulder-wrist line is vertical or the arm straight
    table = runner.invoke(app, ["robot", "poses", str(result.directory), "--pose", "ready"])
    assert (
        table.exit_code == 0
        and "ready" in table.stdout
        and "zero" not in table.stdout.split("\n", 3)[-1].split("ψ:")[0]
    )


@pytest.mark.integration
def test_init_prints_every_choice_and_assumption(tmp_path):
    done = runner.invoke(app, ["robot", "init", str(IIWA), "--out", str(tmp_path / "kuka"), "--jerk", "80"])
    assert done.exit_code == 0, done.output
    assert "tip 'lbr_iiwa_link_7'" in done.stdout and "S-R-S" in done.stdout and "home ready:" in done.stdout
    assert "assumed acceleration limits for 7 joints: 2.5/s times the velocity limit" in done.stdout
    assert "assumed jerk" not in done.stdout
    import tomllib

    text = (tmp_path / "kuka" / "robot.toml").read_text()
    data = tomllib.loads(text)
    with load_pybullet_robot(IIWA) as sim:  # the URDF's velocity limits, as PyBullet reads them
        velocity = {
            n: pb.getJointInfo(sim.body, i, physicsClientId=sim.client)[11]
            for n, i in sim.joint_index.items()
            if n in data["limits"]["acceleration"]
        }
    assert len(velocity) == 7 and data["limits"]["acceleration"] == {n: 2.5 * v for n, v in velocity.items()}
    assert set(data["limits"]["jerk"].values()) == {80.0} and data["limits"]["assumed"] == ["acceleration"]
    assert text.count("  # assumed") == 7 and "80.0  # assumed" not in text
    robot = load_robot(tmp_path / "kuka")
    assert {robot.limits[n].jerk for n in robot.chain("left_arm").joint_names} == {80.0}
    assert robot.assumed_limits == {"acceleration"} and robot.assumed("jerk") == ""
    assert "an assumed acceleration limit" in robot.assumed("acceleration")
    assert (tmp_path / "kuka" / "meshes" / "link_0.stl").is_file()


@pytest.mark.integration
def test_a_velocity_limit_of_0_or_less_is_assumed_and_said(tmp_path):
    """An iiwa whose URDF gives joints 1 and 2 velocity limits 0 and -1 (init clipped them to 1e-6 rad/s, silently,
    and the run was refused at retime): both are assumed, printed and marked, like a velocity the URDF does not give."""
    shutil.copytree(IIWA.parent / "meshes", tmp_path / "meshes")
    text = IIWA.read_text().replace('velocity="10"', 'velocity="0"', 1).replace('velocity="10"', 'velocity="-1"', 1)
    (tmp_path / "iiwa.urdf").write_text(text)
    done = runner.invoke(app, ["robot", "init", str(tmp_path / "iiwa.urdf"), "--out", str(tmp_path / "out")])
    assert done.exit_code == 0, done.output
    assert "assumed velocity limits for 2 joints" in done.stdout and "or 0 or less" in done.stdout
    robot = load_robot(tmp_path / "out")
    velocity = [robot.limits[n].velocity for n in robot.chain("left_arm").joint_names]
    assert velocity[:2] == [DEFAULT_VELOCITY_RAD_S] * 2 and velocity[2:] == [10.0] * 5
    assert "velocity" in robot.assumed_limits


@pytest.mark.integration
def test_dual_iiwa_loads_and_passes_robot_check():
    robot = load_robot(DUAL_IIWA)
    assert robot.hands == ("left", "right")
    done = runner.invoke(app, ["robot", "check", str(DUAL_IIWA), "--samples", "200"])
    assert done.exit_code == 0, done.output
    assert done.stdout.count("pass") == 2 and done.stdout.count("S-R-S: shoulder") == 2
    # its velocity limits are KUKA's data sheet's (85 deg/s for A1), written into its URDF, not pybullet_data's 10
    # rad/s; its assumed acceleration and jerk limits are 2.5/s and 25/s times them
    with load_pybullet_robot(robot.urdf.path) as sim:
        urdf_velocity = pb.getJointInfo(sim.body, sim.joint_index["left_lbr_iiwa_joint_1"], physicsClientId=sim.client)[
            11
        ]
    with load_pybullet_robot(IIWA) as sim:
        source_velocity = pb.getJointInfo(sim.body, sim.joint_index["lbr_iiwa_joint_1"], physicsClientId=sim.client)[11]
    limits = robot.limits["left_lbr_iiwa_joint_1"]
    assert source_velocity == 10 and urdf_velocity == limits.velocity == pytest.approx(np.radians(85), abs=1e-4)
    assert limits.acceleration == pytest.approx(2.5 * limits.velocity, abs=1e-3)
    assert limits.jerk == pytest.approx(25 * limits.velocity, abs=1e-2)
    assert robot.assumed_limits == {"acceleration", "jerk"}


def _one_line(args, needle):
    done = runner.invoke(app, args)
    assert done.exit_code == 2, done.output
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], lines


@pytest.mark.integration  # init reads the robot in PyBullet before it makes --out
@pytest.mark.parametrize(
    ("out", "why"), [("/proc/dualarm-x", "No such file or directory"), ("{file}/sub", "Not a dir")]
)
def test_an_out_the_system_refuses_is_one_line(tmp_path, out, why):
    """--out in /proc, or through a file: one line naming it and the system's reason (a 50-line FileNotFoundError)."""
    (tmp_path / "file").write_text("x")
    out = out.format(file=tmp_path / "file")
    _one_line(["robot", "init", str(IIWA), "--out", out], f"--out {out}: cannot create the directory ({why}")


def test_refusals(tmp_path):
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("x")
    (tmp_path / "notes.urdf").write_text("hello")
    _one_line(["robot", "init", str(tmp_path / "notes.urdf"), "--out", str(tmp_path / "a")], "not valid XML")
    _one_line(
        ["robot", "init", str(IIWA), "--out", str(tmp_path / "b"), "--left-tip", "paw"],
        "--left-tip 'paw': no such link",
    )
    _one_line(
        [
            "robot",
            "init",
            str(IIWA),
            "--out",
            str(tmp_path / "c"),
            "--left-tip",
            "lbr_iiwa_link_7",
            "--right-tip",
            "lbr_iiwa_link_3",
        ],
        "not on separate branches below a common root",
    )
    _one_line(["robot", "init", str(IIWA), "--out", str(tmp_path / "full")], "exists and is not empty")
    _one_line(["robot", "init", str(IIWA), "--out", str(tmp_path / "d"), "--jerk", "-1"], "--jerk")
    shutil.copy(PANDA, tmp_path / "panda.urdf")  # without its meshes
    with mock.patch.dict(os.environ, {"ROS_PACKAGE_PATH": ""}):
        _one_line(
            ["robot", "init", str(tmp_path / "panda.urdf"), "--out", str(tmp_path / "e")],
            "mesh 'package://meshes/collision/link0.obj' not found",
        )
    assert not any((tmp_path / n).exists() for n in "abcde")


def test_a_collision_mesh_that_is_no_mesh_is_one_line_naming_the_urdf(tmp_path):
    """An iiwa whose link 0 (its first collision mesh, read before any is cut) collides as a file of text named
    .stl: refused in one line naming the user's URDF and the mesh, and nothing is left behind."""
    (tmp_path / "bad.stl").write_text("this is not a mesh at all")
    shutil.copytree(IIWA.parent / "meshes", tmp_path / "meshes")  # meshes beside the URDF, as a description ships
    text = IIWA.read_text()
    at = text.index('<link name="lbr_iiwa_link_0"')
    start, end = text.index("<collision>", at), text.index("</collision>", at)
    collision = re.sub(r'filename="[^"]+"', f'filename="{tmp_path / "bad.stl"}"', text[start:end])
    (tmp_path / "bad.urdf").write_text(text[:start] + collision + text[end:])
    _one_line(
        ["robot", "init", str(tmp_path / "bad.urdf"), "--out", str(tmp_path / "out")],
        f"{tmp_path / 'bad.urdf'}: collision mesh 'meshes/",
    )
    assert not (tmp_path / "out").exists()


@pytest.mark.integration
def test_mesh_paths_resolve_through_ros_package_path(tmp_path):
    urdf = tmp_path / "one.urdf"
    urdf.write_text(IIWA.read_text().replace('filename="meshes/', 'filename="package://kuka_iiwa/meshes/'))
    with mock.patch.dict(os.environ, {"ROS_PACKAGE_PATH": str(DATA)}):
        result = init_robot(urdf, tmp_path / "out")
    filenames = re.findall(r'filename="([^"]+)"', (tmp_path / "out" / "one.urdf").read_text())
    copied = [f for f in filenames if not f.startswith("meshes/convex/")]  # cut collision meshes: their own test
    assert copied and all(f.startswith("meshes/") and (tmp_path / "out" / f).is_file() for f in filenames)
    assert all((tmp_path / "out" / f).read_bytes() == (DATA / "kuka_iiwa" / f).read_bytes() for f in copied)
    assert result.robot.hands == ("left",)


def _humanoid_copy(tmp_path: Path, edit) -> Path:
    for f in HUMANOID.iterdir():
        shutil.copy(f, tmp_path / f.name)
    (tmp_path / "robot.toml").write_text(edit((HUMANOID / "robot.toml").read_text()))
    return tmp_path


def test_robot_check_refuses_a_chain_joint_without_jerk(tmp_path):
    robot_dir = _humanoid_copy(tmp_path, lambda t: t.replace("left_elbow = 120.0\n", ""))
    _one_line(
        ["robot", "check", str(robot_dir)],
        "joint 'left_elbow' of chain 'left_arm' has no jerk limit: add it to [limits.jerk]",
    )


@pytest.mark.integration
def test_robot_toml_overrides_velocity(tmp_path):
    robot_dir = _humanoid_copy(tmp_path, lambda t: t + "\n[limits.velocity]\nleft_elbow = 0.5\n")
    robot = load_robot(robot_dir)
    with load_pybullet_robot(robot.urdf.path) as sim:
        urdf_velocity = pb.getJointInfo(sim.body, sim.joint_index["right_elbow"], physicsClientId=sim.client)[11]
    assert robot.limits["left_elbow"].velocity == 0.5 and robot.limits["right_elbow"].velocity == pytest.approx(
        urdf_velocity
    )
    bad = _humanoid_copy(tmp_path, lambda t: t + "\n[limits.velocity]\nleft_elbow = 0.0\n")
    with pytest.raises(Exception, match=re.escape("limits.velocity.left_elbow: 0 is outside the allowed range")):
        load_robot(bad)


@pytest.mark.integration
def test_committed_dual_iiwa_is_what_build_py_makes(made):
    """robots/dual_iiwa holds build.py's outputs: init on the URDF it assembles writes the same robot.toml and the
    same meshes."""
    built = made["dual_iiwa"][1].directory
    assert (DUAL_IIWA / "robot.toml").read_text() == (built / "robot.toml").read_text()
    assert (DUAL_IIWA / "dual_iiwa.urdf").read_text() == (built / "dual_iiwa.urdf").read_text()
    assert sorted(p.name for p in (DUAL_IIWA / "meshes").iterdir()) == sorted(
        p.name for p in (built / "meshes").iterdir()
    )


@pytest.mark.integration
def test_an_arm_of_eight_joints_starts_at_its_seven_nearest_the_hand(tmp_path):
    """pybullet_data's iiwa hung from a 'clavicle' joint: 8 movable joints from the root. The 7 nearest the hand are
    the iiwa (S-R-S: PyBullet's axes of joints 1-3 meet), so the arm starts at the iiwa's base and the clavicle is
    held; --left-base above it keeps all 8."""
    shutil.copytree(IIWA.parent / "meshes", tmp_path / "meshes")  # meshes beside the URDF, as a description ships
    text = IIWA.read_text()
    clavicle = (
        '<link name="torso"/>\n'
        '<joint name="clavicle" type="revolute"><parent link="torso"/><child link="lbr_iiwa_link_0"/>'
        '<origin xyz="0 0.2 0.5" rpy="0 0 0"/><axis xyz="1 0 0"/>'
        '<limit lower="-0.5" upper="0.5" effort="10" velocity="1"/></joint>\n'
    )
    at = text.index('<link name="lbr_iiwa_link_0">')
    (tmp_path / "clavicle.urdf").write_text(text[:at] + clavicle + text[at:])
    result = init_robot(tmp_path / "clavicle.urdf", tmp_path / "out")
    assert [(a.base, a.tip, a.srs) for a in result.arms] == [("lbr_iiwa_link_0", "lbr_iiwa_link_7", None)]
    assert dict(result.locked) == {"clavicle": 0.0}
    assert any("the 7 nearest the hand are S-R-S" in n and "clavicle are held" in n for n in result.notes)
    with load_pybullet_robot(tmp_path / "clavicle.urdf") as sim:  # axes 1-3 of the arm meet (PyBullet's frames)
        lines = [_axis_line(sim, f"lbr_iiwa_joint_{i}") for i in (1, 2, 3)]
    (p0, d0), (p1, d1), (p2, d2) = lines
    for (pa, da), (pb_, db) in (((p0, d0), (p1, d1)), ((p1, d1), (p2, d2))):
        n = np.cross(da, db)
        assert abs(np.dot(pb_ - pa, n)) / np.linalg.norm(n) < 1e-6
    whole = init_robot(tmp_path / "clavicle.urdf", tmp_path / "all", left_tip="lbr_iiwa_link_7", left_base="torso")
    assert whole.arms[0].base == "torso" and whole.robot.chains["left_arm"].dof == 8


@pytest.mark.integration
def test_a_y_up_root_is_refused_naming_the_axis_and_turned_z_up_with_up(tmp_path):
    """The humanoid's URDF hung from a y-up root (its z turned to y, its y to -z): init refuses, naming y; with
    --up y, the copy's new root is z-up with the left arm on +y, and every link sits where PyBullet puts it in the
    original humanoid at the zero pose (the turn undone exactly)."""
    text = (HUMANOID / "humanoid.urdf").read_text()
    at = text.index('<link name="base_link"/>')
    turned = (
        '<link name="y_up"/>\n<joint name="y_up_joint" type="fixed"><parent link="y_up"/><child link="base_link"/>'
        '<origin xyz="0 0 0" rpy="-1.5707963267948966 0 0"/></joint>\n'
    )
    (tmp_path / "y_up.urdf").write_text(text[:at] + turned + text[at:])
    done = runner.invoke(app, ["robot", "init", str(tmp_path / "y_up.urdf"), "--out", str(tmp_path / "refused")])
    assert done.exit_code == 2 and "does not look z-up" in done.stderr and "give --up y" in done.stderr, done.output
    assert not (tmp_path / "refused").exists()
    result = init_robot(tmp_path / "y_up.urdf", tmp_path / "turned", up="y")
    robot = result.robot
    assert robot.urdf.root == "dualarm_base" and [a.hand for a in result.arms] == ["left", "right"]
    links = ["left_hand", "right_hand", "torso", "head"]
    original = _pybullet_link_poses(HUMANOID / "humanoid.urdf", {}, links)
    for link in links:
        chain = robot.chain_between(robot.urdf.root, link)
        assert np.allclose(ChainKinematics.of(chain).pose(np.zeros(chain.dof)), original[link], atol=1e-6), link
