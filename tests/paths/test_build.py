"""Tests of dualarm.paths.build_reference against closed-form geometry, finite differences and the
task files' own numbers."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dualarm.errors import TaskFileError, UnreachablePoseError
from dualarm.paths import build_reference
from dualarm.tasks import load_task

REPO = Path(__file__).resolve().parents[2]
TASKS = REPO / "tasks"
ROBOT_DIR = REPO / "robots" / "humanoid"

# The humanoid's left arm, from robots/humanoid/robot.toml's description (waist at zero): shoulder
# centre 1.40 m up and 0.20 m to the left, upper arm 0.32 m + forearm 0.28 m, wrist centre 0.09 m
# behind the hand along the hand's z axis. load.REACH_MARGIN_M is 1e-3.
LEFT_SHOULDER = np.array([0.0, 0.20, 1.40])
ARM_REACH_M = 0.32 + 0.28
WRIST_TO_HAND_M = 0.09
REACH_MARGIN_M = 1e-3


#: Edits that put a shipped task written in a frame of the robot back in the humanoid's base frame
#: (the numbers the files held before; tests/tasks/test_frames.py shows both forms give the same path).
BASE_FRAME_FORM = {
    "triangle": (
        ('frame = "left.shoulder"', ""),
        ('scale = "arm"', ""),
        ("position = [0.300, 0.070, -0.397]", "position = [0.300, 0.270, 1.003]"),
        ("position = [0.300, -0.200, -0.097]", "position = [0.300, 0.0, 1.303]"),
        ("position = [0.300, -0.200, -0.397]", "position = [0.300, 0.0, 1.003]"),
    ),
    "circle": (
        ('frame = "left.shoulder"', ""),
        ('scale = "arm"', ""),
        ("position = [0.31, 0.04, -0.35]", "position = [0.31, 0.24, 1.05]"),
        ("arc_center = [0.31, -0.11, -0.35]", "arc_center = [0.31, 0.09, 1.05]"),
    ),
    "carry_box": (('frame = "shoulders"', ""), ("position = [0.30, 0.12, -0.40]", "position = [0.30, 0.12, 1.00]")),
}


def _base_frame_text(name: str) -> str:
    text = (TASKS / f"{name}.toml").read_text()
    for old, new in BASE_FRAME_FORM.get(name, ()):
        assert text.count(old) == 1, f"edit target not unique/absent: {old!r}"
        text = text.replace(old, new)
    return text


def toml(name: str) -> dict:
    """The task's keys, positions in the robot base frame."""
    return tomllib.loads(_base_frame_text(name))


def rot(rpy) -> np.ndarray:
    return Rotation.from_euler("xyz", rpy).as_matrix()


def hom(position, rpy) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = rot(rpy)
    T[:3, 3] = position
    return T


def poses(hand) -> np.ndarray:
    T = np.zeros((len(hand.position), 4, 4))
    T[:, :3, :3] = hand.rotation
    T[:, :3, 3] = hand.position
    T[:, 3, 3] = 1.0
    return T


def central_velocity(position: np.ndarray, dt: float) -> np.ndarray:
    """(p[k+1] - p[k-1]) / 2dt for the interior samples."""
    return (position[2:] - position[:-2]) / (2 * dt)


def central_angular_velocity(R: np.ndarray, dt: float) -> np.ndarray:
    """Base-frame angular velocity: log(R[k+1] R[k-1]^T) / 2dt for the interior samples."""
    return Rotation.from_matrix(R[2:] @ np.swapaxes(R[:-2], 1, 2)).as_rotvec() / (2 * dt)


def variant(tmp_path: Path, task: str, *edits: tuple[str, str]) -> Path:
    """A copy of tasks/<task>.toml in the base frame (:data:`BASE_FRAME_FORM`) with the robot path made absolute and
    (old, new) edits applied to exactly one occurrence each."""
    text = _base_frame_text(task)
    edits = (('robot = "../robots/humanoid"', f'robot = "{ROBOT_DIR.as_posix()}"'),) + edits
    for old, new in edits:
        assert text.count(old) == 1, f"edit target not unique/absent: {old!r}"
        text = text.replace(old, new)
    path = tmp_path / f"{task}.toml"  # a short name: messages quote at most ~80 characters of a path
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def triangle():
    return build_reference(load_task(TASKS / "triangle.toml"))


@pytest.fixture(scope="module")
def circle():
    return build_reference(load_task(TASKS / "circle.toml"))


@pytest.fixture(scope="module")
def ball_game():
    return build_reference(load_task(TASKS / "ball_game.toml"))


@pytest.fixture(scope="module")
def carry_box():
    return build_reference(load_task(TASKS / "carry_box.toml"))


# ---------------------------------------------------------------------------------------------
# triangle


def test_triangle_timing(triangle):
    data = toml("triangle")
    dt = data["control_period_s"]
    steps = [round(m["duration_s"] / dt) for m in data["moves"]]
    n = 1 + data["repetitions"] * sum(steps)
    assert len(triangle) == n
    assert triangle.t[0] == 0.0
    assert np.allclose(np.diff(triangle.t), dt, rtol=0, atol=1e-12)
    assert triangle.t[-1] == pytest.approx(data["repetitions"] * sum(m["duration_s"] for m in data["moves"]), abs=1e-9)
    assert triangle.rep[0] == 0 and triangle.rep[-1] == data["repetitions"] - 1
    assert set(np.unique(triangle.rep)) == set(range(data["repetitions"]))
    assert np.all(np.diff(triangle.rep) >= 0)
    assert set(triangle.hands) == {"left"}


def _triangle_boundaries():
    data = toml("triangle")
    dt = data["control_period_s"]
    steps = [round(m["duration_s"] / dt) for m in data["moves"]]
    names = [data["start"]["left"]]
    indices = [0]
    k = 0
    for _ in range(data["repetitions"]):
        for move, n in zip(data["moves"], steps, strict=True):
            k += n
            indices.append(k)
            names.append(move["left"]["to"])
    return data, indices, names


def test_triangle_visits_the_waypoints(triangle):
    data, indices, names = _triangle_boundaries()
    assert names[:4] == ["A", "B", "C", "A"]
    hand = triangle.hands["left"]
    for k, name in zip(indices, names, strict=True):
        wp = data["waypoints"][name]
        np.testing.assert_allclose(hand.position[k], wp["position"], rtol=0, atol=1e-12)
        np.testing.assert_allclose(hand.rotation[k], rot(wp["rpy"]), rtol=0, atol=1e-9)


def test_triangle_rep_and_segment_indices(triangle):
    data, indices, _ = _triangle_boundaries()
    per_rep = len(data["moves"])
    for j in range(len(indices) - 1):
        lo, hi = indices[j] + 1, indices[j + 1] + 1  # samples after a boundary up to the next one
        assert np.all(triangle.rep[lo:hi] == j // per_rep)
        assert np.all(triangle.segment[lo:hi] == j % per_rep)


def test_triangle_stops_at_every_boundary(triangle):
    _, indices, _ = _triangle_boundaries()
    hand = triangle.hands["left"]
    for k in indices:
        np.testing.assert_allclose(hand.linear_velocity[k], 0.0, rtol=0, atol=1e-12)
        np.testing.assert_allclose(hand.angular_velocity[k], 0.0, rtol=0, atol=1e-12)


def test_triangle_moves_in_straight_lines(triangle):
    """Each edge's samples lie on the segment between its two vertices."""
    data, indices, names = _triangle_boundaries()
    hand = triangle.hands["left"]
    for j in range(len(indices) - 1):
        p0 = np.asarray(data["waypoints"][names[j]]["position"])
        p1 = np.asarray(data["waypoints"][names[j + 1]]["position"])
        d = (p1 - p0) / np.linalg.norm(p1 - p0)
        seg = hand.position[indices[j] : indices[j + 1] + 1] - p0
        along = seg @ d
        np.testing.assert_allclose(seg - along[:, None] * d, 0.0, rtol=0, atol=1e-12)
        assert np.all(np.diff(along) >= -1e-15)  # monotonic progress along the edge


def test_triangle_linear_velocity_matches_finite_difference(triangle):
    hand = triangle.hands["left"]
    dt = triangle.period_s
    fd = central_velocity(hand.position, dt)
    vmax = np.linalg.norm(hand.linear_velocity, axis=1).max()
    assert vmax > 0.1
    np.testing.assert_allclose(hand.linear_velocity[1:-1], fd, rtol=0, atol=1e-3 * vmax)


def test_triangle_peak_speed_is_the_quintic_peak(triangle):
    """Quintic time scaling: peak speed = 15/8 * edge length / duration."""
    data, _, names = _triangle_boundaries()
    T = data["moves"][0]["duration_s"]
    lengths = [
        np.linalg.norm(np.subtract(data["waypoints"][a]["position"], data["waypoints"][b]["position"]))
        for a, b in zip(names[:3], names[1:4], strict=True)
    ]
    vmax = np.linalg.norm(triangle.hands["left"].linear_velocity, axis=1).max()
    assert vmax == pytest.approx(15 / 8 * max(lengths) / T, rel=1e-3)


def test_triangle_angular_velocity_matches_finite_difference(triangle):
    hand = triangle.hands["left"]
    dt = triangle.period_s
    fd = central_angular_velocity(hand.rotation, dt)
    wmax = np.linalg.norm(hand.angular_velocity, axis=1).max()
    assert wmax > 0.1
    np.testing.assert_allclose(hand.angular_velocity[1:-1], fd, rtol=0, atol=1e-3 * wmax)


def test_triangle_rotations_are_proper(triangle):
    R = triangle.hands["left"].rotation
    np.testing.assert_allclose(R @ np.swapaxes(R, 1, 2), np.broadcast_to(np.eye(3), R.shape), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, rtol=0, atol=1e-12)


# ---------------------------------------------------------------------------------------------
# circle


def test_circle_geometry(circle):
    data = toml("circle")
    move = data["moves"][0]["left"]
    centre = np.asarray(move["arc_center"])
    wp = data["waypoints"][data["start"]["left"]]
    radius = np.linalg.norm(np.subtract(wp["position"], centre))
    assert radius == pytest.approx(0.15, abs=1e-12)
    hand = circle.hands["left"]
    np.testing.assert_allclose(np.linalg.norm(hand.position - centre, axis=1), 0.15, rtol=0, atol=1e-12)
    np.testing.assert_allclose(hand.position[:, 0], centre[0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(hand.rotation, np.broadcast_to(rot(wp["rpy"]), hand.rotation.shape), rtol=0, atol=1e-12)
    np.testing.assert_allclose(hand.angular_velocity, 0.0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(hand.position[-1], hand.position[0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(hand.position[0], wp["position"], rtol=0, atol=1e-12)


def test_circle_turns_the_right_way_and_closes_each_repetition(circle):
    data = toml("circle")
    dt = data["control_period_s"]
    n = round(data["moves"][0]["duration_s"] / dt)
    assert len(circle) == 1 + data["repetitions"] * n
    hand = circle.hands["left"]
    centre = np.asarray(data["moves"][0]["left"]["arc_center"])
    for r in range(data["repetitions"] + 1):
        np.testing.assert_allclose(hand.position[r * n], data["waypoints"]["P0"]["position"], rtol=0, atol=1e-12)
    # the quintic scaling is symmetric (s(1/2) = 1/2), so at half-time the hand has turned by pi
    # and is diametrically opposite the +y start; the angle about +x grows monotonically
    half = hand.position[n // 2]
    np.testing.assert_allclose(half, centre + [0.0, -0.15, 0.0], rtol=0, atol=1e-12)
    angle = np.unwrap(np.arctan2(hand.position[: n + 1, 2] - centre[2], hand.position[: n + 1, 1] - centre[1]))
    assert np.all(np.diff(angle) >= -1e-12)
    assert angle[-1] - angle[0] == pytest.approx(data["moves"][0]["left"]["arc_angle_rad"], abs=1e-9)


def test_circle_velocity_matches_finite_difference(circle):
    hand = circle.hands["left"]
    fd = central_velocity(hand.position, circle.period_s)
    vmax = np.linalg.norm(hand.linear_velocity, axis=1).max()
    np.testing.assert_allclose(hand.linear_velocity[1:-1], fd, rtol=0, atol=1e-3 * vmax)
    # tangent to the circle
    centre = np.asarray(toml("circle")["moves"][0]["left"]["arc_center"])
    np.testing.assert_allclose(
        np.einsum("ij,ij->i", hand.linear_velocity, hand.position - centre), 0.0, rtol=0, atol=1e-12
    )


# ---------------------------------------------------------------------------------------------
# ball_game


def test_ball_game_hands_move_together(ball_game):
    data = toml("ball_game")
    assert set(ball_game.hands) == {"left", "right"}
    left, right = ball_game.hands["left"], ball_game.hands["right"]
    np.testing.assert_allclose(left.linear_velocity, right.linear_velocity, rtol=0, atol=1e-12)
    total = data["repetitions"] * sum(m["duration_s"] for m in data["moves"])
    assert total == 18.0
    assert ball_game.duration_s == pytest.approx(total, abs=1e-9)
    # orientation kept by `by` moves
    for hand in (left, right):
        np.testing.assert_allclose(
            hand.rotation, np.broadcast_to(hand.rotation[0], hand.rotation.shape), rtol=0, atol=1e-12
        )
        np.testing.assert_allclose(hand.angular_velocity, 0.0, rtol=0, atol=1e-12)
    # the hands keep their separation
    np.testing.assert_allclose(
        left.position - right.position,
        np.broadcast_to(left.position[0] - right.position[0], left.position.shape),
        rtol=0,
        atol=1e-12,
    )


def test_ball_game_displacements(ball_game):
    data = toml("ball_game")
    dt = data["control_period_s"]
    k = 0
    for move in data["moves"]:
        n = round(move["duration_s"] / dt)
        assert n == 300
        for hand in ("left", "right"):
            pos = ball_game.hands[hand].position
            np.testing.assert_allclose(pos[k + n] - pos[k], move[hand]["by"], rtol=0, atol=1e-12)
        k += n
    assert k + 1 == len(ball_game)
    for hand in ("left", "right"):
        pos = ball_game.hands[hand].position
        np.testing.assert_allclose(pos[-1], pos[0], rtol=0, atol=1e-12)  # the moves sum to zero


def test_ball_game_starts_at_the_initial_hand_pose(ball_game):
    task = load_task(TASKS / "ball_game.toml")
    for hand in ("left", "right"):
        T0 = task.initial_hand_pose(hand)
        np.testing.assert_allclose(ball_game.hands[hand].position[0], T0[:3, 3], rtol=0, atol=1e-12)
        np.testing.assert_allclose(ball_game.hands[hand].rotation[0], T0[:3, :3], rtol=0, atol=1e-12)
    # 'initial' puts both hands 0.26 m apart (task notes), mirror images about y = 0
    left, right = ball_game.hands["left"].position[0], ball_game.hands["right"].position[0]
    assert np.linalg.norm(left - right) == pytest.approx(0.26, abs=2e-3)
    assert left[1] == pytest.approx(-right[1], abs=1e-6)


# ---------------------------------------------------------------------------------------------
# carry_box


def test_carry_box_closed_chain(carry_box):
    data = toml("carry_box")
    obj = data["object"]
    assert (obj["master"], obj["slave"]) == ("left", "right")
    Tl_obj = hom(obj["master_to_object"]["position"], obj["master_to_object"]["rpy"])
    Tr_obj = hom(obj["slave_to_object"]["position"], obj["slave_to_object"]["rpy"])
    left, right = poses(carry_box.hands["left"]), poses(carry_box.hands["right"])
    np.testing.assert_allclose(left @ Tl_obj, right @ Tr_obj, rtol=0, atol=1e-9)


def test_carry_box_grasp_geometry(carry_box):
    """Both palms on opposite faces of the box, 0.24 m apart (its y size), facing each other."""
    data = toml("carry_box")
    left, right = carry_box.hands["left"], carry_box.hands["right"]
    np.testing.assert_allclose(left.position[0], data["waypoints"]["grasp"]["position"], rtol=0, atol=1e-12)
    gap = left.position - right.position
    np.testing.assert_allclose(
        gap, np.broadcast_to([0.0, data["object"]["size_m"][1], 0.0], gap.shape), rtol=0, atol=1e-9
    )
    np.testing.assert_allclose(
        np.einsum("ij,ij->i", left.rotation[:, :, 2], right.rotation[:, :, 2]), -1.0, rtol=0, atol=1e-9
    )


def test_carry_box_master_motion(carry_box):
    data = toml("carry_box")
    dt = data["control_period_s"]
    n = [round(m["duration_s"] / dt) for m in data["moves"]]
    left = carry_box.hands["left"].position
    grasp = np.asarray(data["waypoints"]["grasp"]["position"])
    k = 0
    for _ in range(data["repetitions"]):
        for move, steps in zip(data["moves"], n, strict=True):
            np.testing.assert_allclose(left[k + steps] - left[k], move["left"]["by"], rtol=0, atol=1e-12)
            k += steps
    assert k + 1 == len(carry_box)
    top = grasp + data["moves"][0]["left"]["by"]
    assert left[:, 2].max() == pytest.approx(top[2], abs=1e-12)
    assert left[:, 2].min() == pytest.approx(grasp[2], abs=1e-12)


def test_carry_box_slave_velocity_matches_finite_difference(carry_box):
    right = carry_box.hands["right"]
    dt = carry_box.period_s
    vmax = np.linalg.norm(right.linear_velocity, axis=1).max()
    assert vmax > 0.05
    np.testing.assert_allclose(
        right.linear_velocity[1:-1], central_velocity(right.position, dt), rtol=0, atol=1e-3 * vmax
    )
    np.testing.assert_allclose(
        right.angular_velocity[1:-1], central_angular_velocity(right.rotation, dt), rtol=0, atol=1e-3 * vmax
    )


# ---------------------------------------------------------------------------------------------
# errors


def test_repeated_path_that_does_not_close(tmp_path: Path):
    path = variant(
        tmp_path, "triangle", ('duration_s = 2.0\nleft = { to = "A" }', 'duration_s = 2.0\nleft = { to = "C" }')
    )
    task = load_task(path)
    assert task.spec.repetitions == 5
    with pytest.raises(TaskFileError) as info:
        build_reference(task)
    assert not isinstance(info.value, UnreachablePoseError)
    message = str(info.value)
    assert message.startswith(f"{path}:moves"), message
    assert "moves" in message


def test_non_closing_path_is_fine_without_repetitions(tmp_path: Path):
    path = variant(
        tmp_path,
        "triangle",
        ('duration_s = 2.0\nleft = { to = "A" }', 'duration_s = 2.0\nleft = { to = "C" }'),
        ("repetitions = 5", "repetitions = 1"),
    )
    ref = build_reference(load_task(path))
    data = toml("triangle")
    np.testing.assert_allclose(ref.hands["left"].position[-1], data["waypoints"]["C"]["position"], rtol=0, atol=1e-12)


# An arc of radius 0.20 m about the circle task's centre, starting at its +y point (level with the
# shoulder) and turning about +x: up, across to -y, then down, where it leaves the workspace.
BIG_CENTRE = np.array([0.293, 0.0, 1.05])
BIG_START = np.array([0.293, 0.20, 1.05])
BIG_ANGLE = 2 * np.pi
BIG_DURATION = 4.0


def _wrist_distance(position: np.ndarray, rpy) -> np.ndarray:
    """|W - S| for hand positions (N, 3) with the fixed orientation rpy."""
    wrist = position - WRIST_TO_HAND_M * rot(rpy)[:, 2]
    return np.linalg.norm(wrist - LEFT_SHOULDER, axis=-1)


def _big_arc_position(t: np.ndarray) -> np.ndarray:
    """The arc's closed form: quintic s(t/T), angle s * BIG_ANGLE about +x."""
    tau = t / BIG_DURATION
    theta = (10 * tau**3 - 15 * tau**4 + 6 * tau**5) * BIG_ANGLE
    r = np.linalg.norm(BIG_START - BIG_CENTRE)
    return BIG_CENTRE + np.stack([np.zeros_like(theta), r * np.cos(theta), r * np.sin(theta)], axis=-1)


def test_arc_leaving_the_workspace(tmp_path: Path):
    data = toml("circle")
    rpy = data["waypoints"]["P0"]["rpy"]
    limit = ARM_REACH_M - REACH_MARGIN_M
    # independently: the start is comfortably reachable, the bottom of the arc is not
    assert _wrist_distance(BIG_START, rpy) < limit - 0.1
    bottom = BIG_CENTRE + [0.0, 0.0, -0.20]
    assert _wrist_distance(bottom, rpy) > limit + 0.01
    path = variant(
        tmp_path,
        "circle",
        ("position = [0.31, 0.24, 1.05]", f"position = [{BIG_START[0]}, {BIG_START[1]}, {BIG_START[2]}]"),
        ("arc_center = [0.31, 0.09, 1.05]", f"arc_center = [{BIG_CENTRE[0]}, {BIG_CENTRE[1]}, {BIG_CENTRE[2]}]"),
        ("repetitions = 5", "repetitions = 1"),
    )
    task = load_task(path)  # the start waypoint itself is within reach
    with pytest.raises(UnreachablePoseError) as info:
        build_reference(task)
    message = str(info.value)
    assert message.startswith(f"{path}:moves[0]"), message
    match = re.search(r"t = ([0-9.]+) s", message)
    assert match, message
    t_fail = float(match.group(1))
    dt = data["control_period_s"]
    assert 0 < t_fail <= BIG_DURATION
    # the reported time is the first sample whose wrist centre is out of reach
    k = round(t_fail / dt)
    assert abs(k * dt - t_fail) < 1e-9
    t_all = np.arange(k + 1) * dt
    d = _wrist_distance(_big_arc_position(t_all), rpy)
    assert d[k] > limit
    assert np.all(d[:k] <= limit)
    # the arc is reachable up to the -y point (angle pi, reached at half-time): it leaves the
    # workspace on the way down from there
    assert t_fail > BIG_DURATION / 2


def test_big_arc_closed_form_matches_reference(tmp_path: Path):
    """The same arc, shrunk to stay reachable (radius 0.15 m from a +y start: the paper's circle),
    matches its closed form: checks _big_arc_position's conventions used above against a reachable case."""
    data = toml("circle")
    edits = (
        ("position = [0.31, 0.24, 1.05]", "position = [0.293, 0.15, 1.05]"),
        ("arc_center = [0.31, 0.09, 1.05]", "arc_center = [0.293, 0.0, 1.05]"),
        ("repetitions = 5", "repetitions = 1"),
    )
    ref = build_reference(load_task(variant(tmp_path, "circle", *edits)))
    tau = ref.t / data["moves"][0]["duration_s"]
    theta = (10 * tau**3 - 15 * tau**4 + 6 * tau**5) * data["moves"][0]["left"]["arc_angle_rad"]
    expected = BIG_CENTRE + np.stack([np.zeros_like(theta), 0.15 * np.cos(theta), 0.15 * np.sin(theta)], axis=-1)
    np.testing.assert_allclose(ref.hands["left"].position, expected, rtol=0, atol=1e-12)


def test_carry_box_rotating_master_slave_velocity(tmp_path: Path):
    """With the master turning, the slave's velocity includes omega x offset: checked against a
    finite difference, and eq (11) still holds at every sample."""
    path = variant(
        tmp_path,
        "carry_box",
        ("[start]", "[waypoints.tilt]\nposition = [0.30, 0.12, 1.10]\nrpy = [1.5707963267948966, 0.0, 0.4]\n\n[start]"),
        ("left = { by = [0.0, 0.0, 0.20] }", 'left = { to = "tilt" }'),
        ("left = { by = [0.0, 0.0, -0.20] }", 'left = { to = "grasp" }'),
    )
    ref = build_reference(load_task(path))
    data = toml("carry_box")
    obj = data["object"]
    Tl_obj = hom(obj["master_to_object"]["position"], obj["master_to_object"]["rpy"])
    Tr_obj = hom(obj["slave_to_object"]["position"], obj["slave_to_object"]["rpy"])
    left, right = ref.hands["left"], ref.hands["right"]
    np.testing.assert_allclose(poses(left) @ Tl_obj, poses(right) @ Tr_obj, rtol=0, atol=1e-9)
    dt = ref.period_s
    wmax = np.linalg.norm(left.angular_velocity, axis=1).max()
    assert wmax > 0.1
    vmax = np.linalg.norm(right.linear_velocity, axis=1).max()
    # the rotation matters: the slave moves differently from the master
    assert np.abs(right.linear_velocity - left.linear_velocity).max() > 0.05 * vmax
    np.testing.assert_allclose(
        right.linear_velocity[1:-1], central_velocity(right.position, dt), rtol=0, atol=1e-3 * vmax
    )
    np.testing.assert_allclose(
        right.angular_velocity[1:-1], central_angular_velocity(right.rotation, dt), rtol=0, atol=1e-3 * wmax
    )
    np.testing.assert_allclose(
        left.angular_velocity[1:-1], central_angular_velocity(left.rotation, dt), rtol=0, atol=1e-3 * wmax
    )


@pytest.mark.parametrize("name", ["circle", "carry_box"])
def test_every_repetition_is_the_one_repetition_path_bit_for_bit(name):
    """The path repeated R times is the path of the task with one repetition, its moves then again R - 1 times: the same
    targets, not merely within rounding."""
    many = build_reference(load_task(TASKS / f"{name}.toml"))
    once = build_reference(load_task(TASKS / f"{name}.toml", repetitions=1))
    R, n = int(many.rep.max()) + 1, len(once) - 1
    assert R > 1 and len(many) == 1 + R * n
    for hand in many.hands:
        for field in ("position", "rotation", "linear_velocity", "angular_velocity"):
            ours, first = getattr(many.hands[hand], field), getattr(once.hands[hand], field)
            assert np.array_equal(ours[0], first[0])
            for r in range(R):
                assert np.array_equal(ours[1 + r * n : 1 + (r + 1) * n], first[1:]), (hand, field, r)
    assert np.array_equal(many.rep, np.r_[0, np.repeat(np.arange(R), n)]) and np.array_equal(
        many.segment[1:], np.tile(once.segment[1:], R)
    )


@pytest.mark.integration
def test_a_task_without_moves_is_its_start_alone():
    """The bowl grasp is planned, not drawn: its reference is the start pose of each hand, one sample."""
    task = load_task(TASKS / "bowl_grasp.toml")
    assert not task.spec.moves
    reference = build_reference(task)
    assert len(reference) == 1 and list(reference.rep) == [0] and list(reference.segment) == [0]
    for hand, ref in reference.hands.items():
        assert np.array_equal(ref.poses[0], task.start_pose(hand))
