"""Tasks stated in a frame of the robot and scaled by its arm: the paper tasks resolve to the paper's poses on the
humanoid, and to the same shape about the shoulder of the dual iiwa (PyBullet)."""

import tomllib

import numpy as np
import pybullet as pb
import pytest
from scipy.spatial.transform import Rotation
from tests.helpers import HUMANOID, REPO, TASKS, PyBulletURDF, pybullet_urdf
from typer.testing import CliRunner

from dualarm.cli import app

DUAL_IIWA = REPO / "robots" / "dual_iiwa"
runner = CliRunner()

#: The paper tasks' poses in the humanoid's base frame as the files gave them before they were
#: stated relative to the left shoulder (waypoints and arc centres) [m].
HUMANOID_POSITIONS_M = {
    "triangle": {"A": (0.300, 0.270, 1.003), "B": (0.300, 0.0, 1.303), "C": (0.300, 0.0, 1.003)},
    "circle": {"P0": (0.31, 0.24, 1.05)},
    "carry_box": {"grasp": (0.30, 0.12, 1.00)},
}
#: The frame each converted task names.
FRAMES = {"triangle": "left.shoulder", "circle": "left.shoulder", "carry_box": "shoulders"}
HUMANOID_ARC_CENTRES_M = {"circle": [(0.31, 0.09, 1.05)]}


def _as_written_for_the_humanoid(name: str) -> dict:
    """The shipped task's keys with its waypoints and arc centres back in the humanoid's base frame, and no frame, scale
    or transfer."""
    data = tomllib.loads((TASKS / f"{name}.toml").read_text())
    for key in ("frame", "scale", "transfer"):
        data.pop(key, None)
    for wp, position in HUMANOID_POSITIONS_M[name].items():
        data["waypoints"][wp]["position"] = list(position)
    centres = iter(HUMANOID_ARC_CENTRES_M.get(name, []))
    for move in data["moves"]:
        for hand in ("left", "right"):
            if "arc_center" in move.get(hand, {}):
                move[hand]["arc_center"] = list(next(centres))
    return data


@pytest.mark.parametrize("name", sorted(HUMANOID_POSITIONS_M))
def test_converted_tasks_resolve_to_the_papers_poses_on_the_humanoid(name):
    """Every waypoint and every sample of the path (positions to 1e-12 m, rotations to 1e-12) equals that of the task
    written in the base frame."""
    from dualarm.model.poses import pose_matrix
    from dualarm.paths import build_reference
    from dualarm.tasks import load_task
    from dualarm.tasks.load import task_from_dict

    assert tomllib.loads((TASKS / f"{name}.toml").read_text())["frame"] == FRAMES[name]
    converted = load_task(TASKS / f"{name}.toml")
    original = task_from_dict(_as_written_for_the_humanoid(name), robot=HUMANOID)
    for wp, position in HUMANOID_POSITIONS_M[name].items():
        written = tomllib.loads((TASKS / f"{name}.toml").read_text())["waypoints"][wp]
        assert np.abs(converted.waypoint_pose(wp) - pose_matrix(position, written["rpy"])).max() < 1e-12
    a, b = build_reference(converted), build_reference(original)
    assert a.hands.keys() == b.hands.keys()
    for hand in a.hands:
        assert np.abs(a.hands[hand].position - b.hands[hand].position).max() < 1e-12
        assert np.abs(a.hands[hand].rotation - b.hands[hand].rotation).max() < 1e-12
    assert dict(converted.initial_q) == dict(original.initial_q)
    assert converted.spec.gesture == original.spec.gesture


class _Iiwa(PyBulletURDF):
    """The dual iiwa's URDF in PyBullet (:class:`tests.helpers.PyBulletURDF`, the root at the world origin): link
    frames and the S-R-S points from the joint axes (independent of dualarm's kinematics)."""

    def axis(self, joint: str) -> tuple[np.ndarray, np.ndarray]:
        """(a point, the unit direction) of ``joint``'s axis: the joint's frame is its child link's frame."""
        info = pb.getJointInfo(self.body, self.joint[joint], physicsClientId=self.client)
        T = self.frame(info[12].decode())
        return T[:3, 3], T[:3, :3] @ np.asarray(info[13])

    def meet(self, a: str, b: str) -> np.ndarray:
        """The point where the axes of joints ``a`` and ``b`` meet (the midpoint of their closest points) [m]."""
        (p, u), (r, v) = self.axis(a), self.axis(b)
        s, t = np.linalg.lstsq(np.stack([u, -v], axis=1), r - p, rcond=None)[0]
        assert np.linalg.norm((p + s * u) - (r + t * v)) < 1e-6  # PyBullet's link states are float32
        return (p + s * u + r + t * v) / 2


@pytest.fixture
def iiwa_ready():
    from dualarm.model.robot import load_robot

    ready = load_robot(DUAL_IIWA).homes["ready"]
    with pybullet_urdf(DUAL_IIWA / "dual_iiwa.urdf") as sim:
        iiwa = _Iiwa(sim.client, sim.body, sim.joint, sim.link)
        iiwa.set(list(ready), list(ready.values()))
        yield iiwa


def _shoulder_and_scale(sim: _Iiwa, hand: str) -> tuple[np.ndarray, float]:
    """S of ``hand``'s arm and (|SE| + |EW|) / 0.60 m, from PyBullet's joint axes."""
    j = [f"{hand}_lbr_iiwa_joint_{k}" for k in range(1, 8)]
    S, E, W = sim.meet(j[0], j[1]), sim.meet(j[2], j[3]), sim.meet(j[4], j[5])
    return S, (np.linalg.norm(E - S) + np.linalg.norm(W - E)) / 0.60


@pytest.mark.integration
@pytest.mark.parametrize("name", ["triangle", "circle"])
def test_relative_waypoints_are_about_the_dual_iiwas_left_shoulder(name, iiwa_ready):
    """On the dual iiwa each resolved waypoint, taken back to the left shoulder (PyBullet) and divided by the arm ratio,
    is the file's numbers; the rpy are the file's; arcs likewise; the initial configuration is its `ready`."""
    from dualarm.tasks import load_task

    data = tomllib.loads((TASKS / f"{name}.toml").read_text())
    task = load_task(TASKS / f"{name}.toml", robot=DUAL_IIWA)
    assert dict(task.initial_q) == dict(task.robot.homes["ready"])
    S, scale = _shoulder_and_scale(iiwa_ready, "left")
    assert 1.3 < scale < 1.4  # an iiwa 14's 0.42 + 0.40 m against the humanoid's 0.60 m
    for wp, written in data["waypoints"].items():
        T = task.waypoint_pose(wp)
        assert np.abs((T[:3, 3] - S) / scale - written["position"]).max() < 1e-6
        assert np.abs(T[:3, :3] - Rotation.from_euler("xyz", written["rpy"]).as_matrix()).max() < 1e-12
    for move, resolved in zip(data["moves"], task.spec.moves, strict=True):
        if "arc_center" in move.get("left", {}):
            assert resolved.left is not None and resolved.left.arc_center is not None
            assert np.abs((np.asarray(resolved.left.arc_center) - S) / scale - move["left"]["arc_center"]).max() < 1e-6


@pytest.mark.integration
def test_a_link_frame_turns_and_moves_the_waypoints(tmp_path, iiwa_ready):
    """frame = a link of the iiwa's base (rotated against the robot base): the resolved waypoint in that link's PyBullet
    frame is the file's pose, displacements are turned by the link's rotation."""
    from dualarm.model.poses import pose_matrix
    from dualarm.tasks import load_task

    text = (
        (TASKS / "triangle.toml")
        .read_text()
        .replace('frame = "left.shoulder"', 'frame = "left_lbr_iiwa_link_0"')
        .replace('scale = "arm"', "")
    )
    text = text.replace('robot = "../robots/humanoid"', f'robot = "{DUAL_IIWA}"')
    for old, new in (
        ("[0.300, 0.070, -0.397]", "[0.5, 0.1, 0.2]"),
        ("[0.300, -0.200, -0.097]", "[0.5, -0.1, 0.3]"),
        ("[0.300, -0.200, -0.397]", "[0.5, -0.1, 0.1]"),
    ):
        text = text.replace(old, new)
    file = tmp_path / "triangle.toml"
    file.write_text(text)
    task = load_task(file)
    link = iiwa_ready.frame("left_lbr_iiwa_link_0")
    assert not np.allclose(link[:3, :3], np.eye(3))
    data = tomllib.loads(text)
    for wp, written in data["waypoints"].items():
        local = np.linalg.inv(link) @ task.waypoint_pose(wp)
        assert np.abs(local - pose_matrix(written["position"], written["rpy"])).max() < 1e-6


def test_a_bad_frame_name_is_one_line_naming_the_key_and_the_frames(tmp_path):
    text = (
        (TASKS / "triangle.toml")
        .read_text()
        .replace('frame = "left.shoulder"', 'frame = "left_elbow_centre"')
        .replace('robot = "../robots/humanoid"', f'robot = "{HUMANOID}"')
    )
    file = tmp_path / "triangle.toml"
    file.write_text(text)
    result = runner.invoke(app, ["task", "check", str(file)])
    assert result.exit_code == 2
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, result.stderr
    assert f"{file}:frame:" in lines[0] and "'left_elbow_centre'" in lines[0]
    assert "left.shoulder" in lines[0] and "shoulders" in lines[0] and "left_hand" in lines[0] and "torso" in lines[0]


@pytest.mark.parametrize("name", ["triangle", "circle"])
def test_task_check_passes_on_the_dual_iiwa(name):
    result = runner.invoke(app, ["task", "check", name, "--robot", "dual_iiwa"])
    assert result.exit_code == 0, result.output
    assert "NOT reachable" not in result.stdout


@pytest.mark.integration
def test_the_triangle_runs_on_the_dual_iiwa_and_its_hand_draws_the_triangle_about_its_shoulder(tmp_path, iiwa_ready):
    """`dualarm run triangle --robot robots/dual_iiwa --ik mc-inverse --stages path,ik` completes; PyBullet's FK of the
    recorded IK joints puts the hand on A, B, C, A (the file's numbers about the PyBullet shoulder, scaled) at 0, 2, 4,
    6 s times the file's [transfer] duration_scale, and on the reference throughout."""
    from dualarm.record.readback import read_run

    result = runner.invoke(
        app,
        [
            "run",
            "triangle",
            "--robot",
            str(DUAL_IIWA),
            "--ik",
            "mc-inverse",
            "--stages",
            "path,ik",
            "--out",
            str(tmp_path),
        ],
    )
    assert result.exit_code == 0, result.output
    assert "verdict: complete" in result.stderr
    run = read_run(result.stdout.strip().splitlines()[-1])
    assert run.manifest["status"] == "complete"
    ik = run["/ik/sample"]
    reference = run["/task/reference/left"]
    S, scale = _shoulder_and_scale(iiwa_ready, "left")
    data = tomllib.loads((TASKS / "triangle.toml").read_text())
    names = [f"left_lbr_iiwa_joint_{k}" for k in range(1, 8)]
    stretch = data["transfer"]["duration_scale"]
    vertices = {
        round(k * 200 * stretch): name for k, name in enumerate("ABCA")
    }  # samples at 0, 2, 4 and 6 s stretched (0.01 s apart)
    assert np.allclose(ik["t"].to_numpy()[list(vertices)], np.array([0.0, 2.0, 4.0, 6.0]) * stretch)
    for i in range(0, len(ik), 25):  # the right arm stays at ready, as the fixture set it
        row = ik.iloc[i]
        for n in names:
            pb.resetJointState(
                iiwa_ready.body, iiwa_ready.joint[n], float(row[f"position.{n}"]), physicsClientId=iiwa_ready.client
            )
        hand = iiwa_ready.frame("left_lbr_iiwa_link_7")
        ref = reference.iloc[i]
        assert np.linalg.norm(hand[:3, 3] - [ref["position.x"], ref["position.y"], ref["position.z"]]) < 1e-6
        R = Rotation.from_quat(
            [ref["orientation.x"], ref["orientation.y"], ref["orientation.z"], ref["orientation.w"]]
        ).as_matrix()
        assert np.abs(hand[:3, :3] - R).max() < 1e-6
        if i in vertices:
            written = data["waypoints"][vertices[i]]
            assert np.linalg.norm(hand[:3, 3] - (S + scale * np.asarray(written["position"]))) < 1e-6
            assert np.abs(hand[:3, :3] - Rotation.from_euler("xyz", written["rpy"]).as_matrix()).max() < 1e-6


def test_a_waypoint_scaled_beyond_the_coordinate_range_is_one_line_naming_it():
    """On the dual iiwa (scale 1.367) a waypoint 99 m from the shoulder lands beyond the 100 m every coordinate is
    bounded by: refused naming the waypoint, not a traceback."""
    from dualarm.errors import TaskFileError
    from dualarm.tasks.load import task_from_dict

    with pytest.raises(
        TaskFileError, match=r"^<dict>:waypoints\.far: in the robot base frame its position .* outside \[-100, 100\] m$"
    ):
        task_from_dict(
            name="far",
            robot=DUAL_IIWA,
            control_period_s=0.01,
            initial="ready",
            start={},
            frame="left.shoulder",
            scale="arm",
            waypoints={"far": {"position": [99.0, 0.0, 0.0]}},
        )


@pytest.mark.integration
def test_the_ball_game_runs_on_the_dual_iiwa_through_every_stage_from_its_ready_pose_at_its_own_limits(
    tmp_path, iiwa_ready
):
    """`dualarm run ball_game --robot dual_iiwa --ik tvgdd` completes through execution; the IK starts at robot.toml's
    ready (PyBullet FK of both hands), the first stroke lifts both hands by 0.10 m times the arm's scale (from
    PyBullet's joint axes), and the joints are held to KUKA's data-sheet velocities, not the paper's 6 rad/s."""
    import math

    from dualarm.record.readback import read_run

    result = runner.invoke(app, ["run", "ball_game", "--robot", "dual_iiwa", "--ik", "tvgdd", "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    run = read_run(result.stdout.strip().splitlines()[-1])
    assert run.manifest["status"] == "complete"
    assert set(run.stages) == {"path", "ik", "retime", "smooth", "approach", "execute"}
    ik = run["/ik/sample"]
    _, scale = _shoulder_and_scale(iiwa_ready, "left")
    start = {h: iiwa_ready.frame(f"{h}_lbr_iiwa_link_7")[:3, 3] for h in ("left", "right")}
    after_stroke = ik.iloc[int(np.argmin(np.abs(ik["t"].to_numpy() - 3.0)))]
    for n in iiwa_ready.joint:
        if f"position.{n}" in ik:
            pb.resetJointState(
                iiwa_ready.body,
                iiwa_ready.joint[n],
                float(after_stroke[f"position.{n}"]),
                physicsClientId=iiwa_ready.client,
            )
    for hand in ("left", "right"):
        lifted = iiwa_ready.frame(f"{hand}_lbr_iiwa_link_7")[:3, 3] - start[hand]
        assert (
            np.linalg.norm(lifted - [0.0, 0.0, 0.10 * scale]) < 1e-3
        )  # TV-GDD tracks to its feedback error, well under a millimetre
    first = ik.iloc[0]
    from dualarm.model.robot import load_robot

    ready = load_robot(DUAL_IIWA).homes["ready"]
    assert max(abs(first[f"position.{n}"] - v) for n, v in ready.items()) < 1e-9
    limits = run["/ik/limits"].iloc[0]
    for k, deg_s in enumerate((85, 85, 100, 75, 130, 135, 135), start=1):  # KUKA's LBR iiwa 14 R820 data sheet
        assert limits[f"velocity.left_lbr_iiwa_joint_{k}"] == pytest.approx(math.radians(deg_s), abs=1e-4)


def test_the_circle_takes_its_transfer_duration_on_another_robot():
    """circle.toml's [transfer] duration_scale = 1.5: one circle takes 4 s on the humanoid and 6 s on the dual iiwa (the
    reference's own clock)."""
    from dualarm.paths import build_reference
    from dualarm.tasks import load_task

    data = tomllib.loads((TASKS / "circle.toml").read_text())
    assert data["transfer"]["duration_scale"] == 1.5
    humanoid, iiwa = (build_reference(load_task(TASKS / "circle.toml", robot=r)) for r in (None, DUAL_IIWA))
    reps = data["repetitions"]
    assert humanoid.duration_s == pytest.approx(reps * 4.0)
    assert iiwa.duration_s == pytest.approx(reps * 6.0)


@pytest.mark.parametrize("robot_dir", [HUMANOID, REPO / "robots" / "dual_iiwa"])
def test_the_shoulder_and_length_of_any_arm_are_the_srs_ones_on_an_srs_arm(robot_dir):
    """The fallback for an arm of no family (nearest points of the first and the last two axes, the polyline between)
    gives an S-R-S arm's closed-form S and L2 + L3 (:func:`dualarm.model.srs.srs_geometry`)."""
    from dualarm.model.robot import load_robot
    from dualarm.model.srs import srs_geometry
    from dualarm.tasks.frames import _nearest_axes

    robot = load_robot(robot_dir)
    for hand in robot.hands:
        arm = robot.hand_chain(hand)
        shoulder, length = _nearest_axes(arm)
        geometry = srs_geometry(arm)
        assert np.allclose(shoulder, geometry.shoulder, atol=1e-9) and length == pytest.approx(geometry.reach, abs=1e-9)


@pytest.mark.integration
def test_the_triangle_transfers_to_an_arm_of_no_family(tmp_path):
    """The offset humanoid with its left wrist axis moved off the forearm (no SEW family, ``scale = "arm"`` and the
    ``left.shoulder`` frame refused before): waypoint A lies at S + s p, S where PyBullet's joint 1 and 2 axes come
    nearest, s the polyline from S through joints 2-6 to the wrist over 0.60 m."""
    from tests.helpers import wrist_offset_robot

    from dualarm.tasks.load import load_task_unmoved

    robot_dir = wrist_offset_robot(tmp_path)
    task = load_task_unmoved(TASKS / "triangle.toml", robot=robot_dir)  # its C is out of this wrist's reach
    names = task.robot.hand_chain("left").joint_names
    with pybullet_urdf(robot_dir / "offset_wrist.urdf") as sim:
        sim.set(list(task.initial_q), list(task.initial_q.values()))
        sim.set(names, [0.0] * len(names))  # the shoulder is found at the arm's zero pose, in its base frame

        def axis(joint: str) -> tuple[np.ndarray, np.ndarray]:
            index, client = sim.joint[joint], sim.client
            info = pb.getJointInfo(sim.body, index, physicsClientId=client)
            state = pb.getLinkState(sim.body, index, computeForwardKinematics=True, physicsClientId=client)
            R = np.asarray(pb.getMatrixFromQuaternion(state[5])).reshape(3, 3)
            return np.asarray(state[4]), R @ np.asarray(info[13])

        def nearest(a, b) -> np.ndarray:  # the foot on line a of the common perpendicular (least squares)
            (p, d), (r, e) = a, b
            t = np.linalg.lstsq(np.stack([d, -e], axis=1), r - p, rcond=None)[0]
            return p + t[0] * d

        lines = [axis(n) for n in names]
    shoulder, wrist = nearest(lines[0], lines[1]), nearest(lines[-1], lines[-2])
    points = [shoulder, *(p for p, _ in lines[1:-1]), wrist]
    scale = sum(np.linalg.norm(b - a) for a, b in zip(points, points[1:], strict=False)) / 0.60
    written = tomllib.loads((TASKS / "triangle.toml").read_text())["waypoints"]["A"]["position"]
    A = task.waypoint_pose("A")[:3, 3]
    assert np.allclose(A, shoulder + scale * np.asarray(written), atol=2e-6)  # PyBullet's single precision
