"""``dualarm robot init`` and ``robot check`` on robot descriptions as their makers ship them.

TALOS, the PR2 and the TIAGo dual of ``example-robot-data`` 6.0.0 (PyPI), none of their files edited. The
wheel is downloaded once into a cache (``DUALARM_TEST_CACHE``, default ``~/.cache/dualarm-tests``); without a
package index the tests are skipped, saying so. Every fact is checked with PyBullet on the source URDF or with
the URDF's own joints, never with what init wrote.
"""

from __future__ import annotations

import os
import subprocess
import sys
import zipfile
from pathlib import Path
from unittest import mock

import numpy as np
import pytest
from typer.testing import CliRunner

from dualarm.cli import app
from dualarm.describe.init import init_robot
from dualarm.model.urdf import load_urdf
from dualarm.sim.world import MAX_LINKS, load_pybullet_robot, pb

pytestmark = pytest.mark.integration
runner = CliRunner()
WHEEL = "example-robot-data==6.0.0"
SHARE = "cmeel.prefix/share/example-robot-data/robots"
ROBOTS = {
    "talos": "talos_data/robots/talos_reduced.urdf",
    "pr2": "pr2_description/urdf/pr2.urdf",
    "tiago_dual": "tiago_description/robots/tiago_dual.urdf",
}


@pytest.fixture(scope="session")
def robots_share() -> Path:
    """The ``robots`` folder of example-robot-data 6.0.0 (the three robots' packages), downloaded once."""
    cache = Path(os.environ.get("DUALARM_TEST_CACHE", Path.home() / ".cache" / "dualarm-tests")) / "erd-6.0.0"
    done = cache / "unpacked"
    if not done.exists():
        cache.mkdir(parents=True, exist_ok=True)
        wheels = list(cache.glob("example_robot_data-6.0.0-*.whl"))
        if not wheels:
            result = subprocess.run(
                [sys.executable, "-m", "pip", "download", "--no-deps", "--quiet", "-d", str(cache), WHEEL],
                capture_output=True,
                text=True,
                timeout=600,
            )
            wheels = list(cache.glob("example_robot_data-6.0.0-*.whl"))
            if result.returncode or not wheels:
                pytest.skip(f"{WHEEL} could not be downloaded (no package index?): {result.stderr.strip()[-300:]}")
        packages = {f"{SHARE}/{path.split('/')[0]}/" for path in ROBOTS.values()}
        with zipfile.ZipFile(wheels[0]) as wheel:
            wheel.extractall(cache, [n for n in wheel.namelist() if any(n.startswith(p) for p in packages)])
        done.touch()
    return cache / SHARE


@pytest.fixture(scope="module")
def made(robots_share, tmp_path_factory) -> dict:
    """name -> RobotInit, for each robot (meshes through ROS_PACKAGE_PATH)."""
    root = tmp_path_factory.mktemp("public")
    with mock.patch.dict(os.environ, {"ROS_PACKAGE_PATH": str(robots_share)}):
        return {name: init_robot(robots_share / path, root / name) for name, path in ROBOTS.items()}


def _between(urdf, a: str, b: str) -> list:
    """The joints on the tree path between links ``a`` and ``b``."""
    up_a, up_b = urdf.chain(urdf.root, a), urdf.chain(urdf.root, b)
    shared = 0
    while shared < min(len(up_a), len(up_b)) and up_a[shared].name == up_b[shared].name:
        shared += 1
    return list(up_a[shared:]) + list(up_b[shared:])


@pytest.mark.parametrize(
    ("name", "tips"),
    [
        ("talos", ("gripper_left_base_link", "gripper_right_base_link")),  # above the one-joint gripper
        ("pr2", ("l_gripper_tool_frame", "r_gripper_tool_frame")),  # the tool frame below the palm
        ("tiago_dual", ("hand_left_tool_link", "hand_right_tool_link")),  # not a finger of the five-finger hand
    ],
)
def test_the_arms_end_at_the_hands(made, robots_share, name, tips):
    """Two 7-joint arms, all revolute (or continuous), named as arm joints by their maker, ending at the hands."""
    result = made[name]
    assert tuple(a.tip for a in result.arms) == tips
    source = load_urdf(robots_share / ROBOTS[name])
    for arm in result.arms:
        movable = [j for j in source.chain(arm.base, arm.tip) if j.movable]
        assert len(movable) == 7 and all(j.type in ("revolute", "continuous") for j in movable)
        names = [j.name for j in movable]
        assert all(arm.hand in n or n.startswith(arm.hand[0] + "_") for n in names), names


@pytest.mark.parametrize("name", ["talos", "pr2", "tiago_dual"])
def test_disabled_pairs_are_rigid_or_always_in_contact_by_pybullet(made, robots_share, name):
    """PyBullet on the URDF init wrote (its concave collision meshes cut into convex parts, what every check uses):
    a 'rigid' pair (no chain's joint between them in the source's tree) keeps its relative pose and an 'always' pair
    is in contact at random configurations of every chain joint (seed and count not init's)."""
    result = made[name]
    robot = result.robot
    joints = sorted({n for c in robot.chains.values() for n in c.joint_names})
    held = {k: v for k, v in robot.home("zero").items() if k not in joints}
    with mock.patch.dict(os.environ, {"ROS_PACKAGE_PATH": str(robots_share)}):
        sim = load_pybullet_robot(robot.urdf.path, self_collision=True)
    with sim:
        lower, upper = robot.lower_upper(tuple(joints))
        lower, upper = np.where(np.isfinite(lower), lower, -np.pi), np.where(np.isfinite(upper), upper, np.pi)
        relative: dict[tuple[str, str], list[np.ndarray]] = {}
        for q in np.random.default_rng(12345).uniform(lower, upper, size=(40, len(joints))):
            sim.set_positions([*held, *joints], [*held.values(), *q])
            pb.performCollisionDetection(physicsClientId=sim.client)
            for (a, b), reason in robot.disabled_pairs.items():
                if reason == "rigid":
                    relative.setdefault((a, b), []).append(np.linalg.solve(sim.link_pose(a), sim.link_pose(b)))
                elif reason == "always":
                    ia, ib = sim.link_index[a], sim.link_index[b]
                    points = pb.getClosestPoints(sim.body, sim.body, 0.0, ia, ib, physicsClientId=sim.client)
                    assert points and min(p[8] for p in points) < 0, (a, b, q)
    for (a, b), poses in relative.items():
        assert np.allclose(poses, poses[0], atol=1e-5), (a, b)
    assert "always" in robot.disabled_pairs.values() or name == "tiago_dual"  # its hands' fingers are held: rigid
    source = load_urdf(robots_share / ROBOTS[name])
    for (a, b), reason in robot.disabled_pairs.items():
        assert (reason == "rigid") == all(j.name not in joints for j in _between(source, a, b)), (a, b, reason)


@pytest.mark.parametrize("name", ["talos", "pr2", "tiago_dual"])
def test_robot_check_passes(made, name):
    """FK against adam-robotics (a PR2's joints without <origin>) and PyBullet (the TIAGo dual has more links than
    PyBullet reports: its fixed links merged)."""
    result = runner.invoke(app, ["robot", "check", str(made[name].directory), "--samples", "50"])
    assert result.exit_code == 0, result.output
    assert "Unknown tag" not in result.output and "Unknown attribute" not in result.output


def test_tiago_dual_has_more_links_than_pybullet_reports(robots_share):
    assert len(load_urdf(robots_share / ROBOTS["tiago_dual"]).links) - 1 > MAX_LINKS


def test_allow_adds_a_user_pair_and_unknown_links_are_refused(robots_share, tmp_path):
    source = robots_share / ROBOTS["talos"]
    with mock.patch.dict(os.environ, {"ROS_PACKAGE_PATH": str(robots_share)}):
        pair = "arm_left_4_link,arm_right_4_link"
        result = runner.invoke(app, ["robot", "init", str(source), "--out", str(tmp_path / "t"), "--allow", pair])
        assert result.exit_code == 0, result.output
        assert '["arm_left_4_link", "arm_right_4_link", "user"]' in (tmp_path / "t" / "robot.toml").read_text()
        result = runner.invoke(app, ["robot", "init", str(source), "--out", str(tmp_path / "u"), "--allow", "x,y"])
    assert result.exit_code == 2 and "--allow 'x': no such link" in result.output
    assert not (tmp_path / "u").exists()


def test_the_velocity_methods_start_where_ipopt_from_the_initial_configuration_finds_none(made, robots_share):
    """The circle on the PR2: IPOPT from the task's initial configuration ends infeasible (checked here), so the start
    is searched from more starts; the one found is within the limits and puts the hand on the path's first pose by
    PyBullet's forward kinematics of the source URDF."""
    from dualarm.ik.velocity.stack import reference_stack, stacked_reference, start_configuration
    from dualarm.paths.build import build_reference
    from dualarm.tasks import load_task

    task = load_task("circle", 1, robot=made["pr2"].directory)
    robot, reference = task.robot, build_reference(task)
    stack = reference_stack(robot, reference, dict(task.initial_q), False, "pose")
    lower, upper = robot.lower_upper(stack.joint_names)
    r0 = stacked_reference(stack, reference)[0][0]
    stack.start_solver(x0=stack.initial, p=r0, lbx=lower, ubx=upper, lbg=0, ubg=0)
    assert not stack.start_solver.stats()["success"]

    theta = start_configuration(stack, reference, lower, upper)
    assert ((theta >= lower - 1e-9) & (theta <= upper + 1e-9)).all()
    (hand,) = stack.hands
    asked = np.eye(4)
    asked[:3, :3], asked[:3, 3] = reference.hands[hand].rotation[0], reference.hands[hand].position[0]
    frame = reference.frame_in(robot)
    with mock.patch.dict(os.environ, {"ROS_PACKAGE_PATH": str(robots_share)}):
        with load_pybullet_robot(robots_share / ROBOTS["pr2"]) as sim:
            sim.set_positions(list(task.initial_q), list(task.initial_q.values()))
            sim.set_positions(list(stack.joint_names), list(theta))
            tip = sim.link_pose(robot.hand_chain(hand).tip)
            base = np.eye(4) if frame == robot.urdf.root else sim.link_pose(frame)
    reached = np.linalg.inv(base) @ tip
    assert np.abs(reached[:3, 3] - asked[:3, 3]).max() < 1e-5
    assert np.abs(reached[:3, :3] - asked[:3, :3]).max() < 1e-5


def _fcl_link(urdf_path: Path, link: str) -> list:
    """``link``'s collision meshes of ``urdf_path`` as FCL triangle models, with their origins in the link (4, 4)."""
    import xml.etree.ElementTree as ET

    import fcl
    import trimesh
    from scipy.spatial.transform import Rotation

    from dualarm.describe.meshes import resolve_mesh

    out = []
    for node in (n for n in ET.parse(urdf_path).getroot().iter("link") if n.get("name") == link):
        for collision in node.iter("collision"):
            origin, T = collision.find("origin"), np.eye(4)
            if origin is not None:
                T[:3, :3] = Rotation.from_euler(
                    "xyz", [float(v) for v in origin.get("rpy", "0 0 0").split()]
                ).as_matrix()
                T[:3, 3] = [float(v) for v in origin.get("xyz", "0 0 0").split()]
            mesh = trimesh.load_mesh(resolve_mesh(collision.find(".//mesh").get("filename"), urdf_path)[0])
            model = fcl.BVHModel()
            model.beginModel(len(mesh.vertices), len(mesh.faces))
            model.addSubModel(mesh.vertices, mesh.faces)
            model.endModel()
            out.append((model, T))
    return out


def test_concave_collision_meshes_are_cut_so_pybullet_collides_what_the_maker_drew(made, robots_share):
    """The PR2's elbow flexed towards its limit: PyBullet on the source URDF (each mesh its convex hull) finds the
    forearm inside the upper arm; FCL on the meshes' triangles (as MoveIt checks them) finds them apart; PyBullet
    on the robot init wrote (CoACD's convex parts) agrees with FCL. Every vertex of each cut mesh lies inside one
    of its parts within 1 mm (scipy's hulls), so no material is lost."""
    import fcl
    import trimesh
    from scipy.spatial import ConvexHull

    robot = made["pr2"].robot
    source = robots_share / ROBOTS["pr2"]
    a, b = "l_forearm_link", "l_upper_arm_link"
    meshes = {link: _fcl_link(source, link) for link in (a, b)}
    (low,), _ = robot.lower_upper(("l_elbow_flex_joint",))
    ready = dict(robot.home("ready"))

    def depth(sim) -> float:
        points = pb.getClosestPoints(
            sim.body, sim.body, 0.0, sim.link_index[a], sim.link_index[b], physicsClientId=sim.client
        )
        return -min((p[8] for p in points), default=0.0)

    hull_hits = 0
    with mock.patch.dict(os.environ, {"ROS_PACKAGE_PATH": str(robots_share)}):
        with load_pybullet_robot(source) as hulls, load_pybullet_robot(robot.urdf.path) as parts:
            for elbow in np.linspace(low, low + 0.6, 4):
                for roll in np.linspace(-np.pi, np.pi, 5):
                    q = {**ready, "l_elbow_flex_joint": elbow, "l_forearm_roll_joint": roll}
                    for sim in (hulls, parts):
                        sim.set_positions(list(q), list(q.values()))
                    if depth(hulls) <= 1e-3:
                        continue
                    hull_hits += 1
                    placed = {
                        link: [
                            fcl.CollisionObject(m, _fcl_transform(hulls.link_pose(link) @ T)) for m, T in meshes[link]
                        ]
                        for link in (a, b)
                    }
                    apart = min(
                        fcl.distance(x, y, fcl.DistanceRequest(), fcl.DistanceResult())
                        for x in placed[a]
                        for y in placed[b]
                    )
                    assert apart > 5e-3, (elbow, roll, apart)
                    assert depth(parts) == 0.0, (elbow, roll, depth(parts))
    assert hull_hits >= 10  # the setup: the hulls collide over much of the flexed range

    directory = robot.urdf.path.parent
    cut = sorted((directory / "meshes" / "convex").rglob("*.obj"))
    assert {"upper_arm_v0/upper_arm.obj", "forearm_v0/forearm.obj"} <= {
        p.relative_to(directory / "meshes" / "convex").as_posix() for p in cut
    }
    for obj in cut:
        drawn = trimesh.load_mesh(
            directory / "meshes" / obj.relative_to(directory / "meshes" / "convex").with_suffix(".stl")
        )
        parts = [
            ConvexHull([[float(v) for v in line.split()[1:]] for line in part.splitlines() if line.startswith("v ")])
            for part in obj.read_text().split("\no ")
        ]
        outside = np.min(
            [(drawn.vertices @ h.equations[:, :3].T + h.equations[:, 3]).max(axis=1) for h in parts], axis=0
        )
        assert outside.max() < 1e-3, (obj, outside.max())


def _fcl_transform(T: np.ndarray):
    import fcl

    return fcl.Transform(T[:3, :3], T[:3, 3])
