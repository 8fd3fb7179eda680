"""Tests of dualarm.tasks.load_task: the shipped task files load, malformed ones fail with
``file:key: ...`` messages, and the CLI turns those into one error line and exit code 2."""

from __future__ import annotations

import re
import tomllib
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from dualarm.errors import TaskFileError, UnreachablePoseError
from dualarm.tasks import load_task

REPO = Path(__file__).resolve().parents[2]
TASKS = sorted((REPO / "tasks").glob("*.toml"))
ROBOT_DIR = REPO / "robots" / "humanoid"
URDF = ROBOT_DIR / "humanoid.urdf"
TRIANGLE = REPO / "tasks" / "triangle.toml"

# The humanoid's arm, from robots/humanoid/robot.toml's description: shoulders 1.40 m above the
# floor and 0.40 m apart, upper arm 0.32 m + forearm 0.28 m, wrist centre 0.09 m behind the palm.
LEFT_SHOULDER = np.array([0.0, 0.20, 1.40])
ARM_REACH_M = 0.32 + 0.28
WRIST_TO_HAND_M = 0.09


def urdf_limits(joint: str) -> tuple[float, float]:
    """(lower, upper) of a joint, read straight from the URDF XML."""
    root = ET.parse(URDF).getroot()
    for j in root.iter("joint"):
        if j.get("name") == joint:
            lim = j.find("limit")
            return float(lim.get("lower")), float(lim.get("upper"))
    raise KeyError(joint)


def triangle_text() -> str:
    """triangle.toml's text with its robot path made absolute (copies live in tmp_path)."""
    text = TRIANGLE.read_text()
    old = 'robot = "../robots/humanoid"'
    assert text.count(old) == 1
    return text.replace(old, f'robot = "{ROBOT_DIR.as_posix()}"')


def initial_table() -> str:
    """triangle.toml's ``[initial]`` table (its header line and joint lines): the place where the variants below put an
    ``initial`` of their own.

    It follows the top-level keys, so an ``initial = ...`` line written in its place is a top-level key again.
    """
    found = re.findall(r"^\[initial\][^\n]*\n(?:\w+ = [^\n]*\n)+", TRIANGLE.read_text(), flags=re.MULTILINE)
    assert len(found) == 1, found
    return found[0]


INITIAL = initial_table()


def initial_is(value: str) -> tuple[str, str]:
    """The edit that replaces triangle.toml's ``[initial]`` table by the top-level line ``initial = value``."""
    return (INITIAL, f"initial = {value}\n")


def variant(tmp_path: Path, *edits: tuple[str, str], name: str = "bad.toml") -> Path:
    """Write triangle.toml with each (old, new) edit applied to exactly one occurrence of old."""
    text = triangle_text()
    for old, new in edits:
        assert text.count(old) == 1, f"edit target not unique/absent: {old!r}"
        text = text.replace(old, new)
    path = tmp_path / name
    path.write_text(text)
    return path


# ---------------------------------------------------------------------------------------------
# Shipped task files


def test_at_least_five_task_files():
    assert len(TASKS) >= 5


@pytest.mark.parametrize(
    "path",
    # the bowl grasp's loading builds its environment in a PyBullet world
    [pytest.param(p, marks=pytest.mark.integration) if p.stem == "bowl_grasp" else p for p in TASKS],
    ids=[p.stem for p in TASKS],
)
def test_task_file_loads(path: Path):
    task = load_task(path)
    data = tomllib.loads(path.read_text())
    assert task.name == data["name"]
    assert task.file == path
    assert task.text == path.read_text()
    assert task.spec.control_period_s == data["control_period_s"]
    assert len(task.spec.moves) == len(data.get("moves", []))


def test_unmodified_copy_loads(tmp_path: Path):
    """The baseline for every malformed variant below: the copy itself is fine."""
    task = load_task(variant(tmp_path))
    data = tomllib.loads(TRIANGLE.read_text())
    for name, wp in data["waypoints"].items():
        assert np.allclose(
            task.waypoint_pose(name)[:3, 3], np.add(wp["position"], (0.0, 0.2, 1.4)), atol=1e-15
        )  # frame = "left.shoulder": S at [0, 0.2, 1.4] on the humanoid, scale 1
        assert np.allclose(
            task.waypoint_pose(name)[:3, :3], Rotation.from_euler("xyz", wp["rpy"]).as_matrix(), atol=1e-12
        )
    # the [initial] table as tomllib reads it; the joints it does not name start at zero
    assert data["initial"] and all(task.initial_q[joint] == value for joint, value in data["initial"].items())
    assert all(value == 0.0 for joint, value in task.initial_q.items() if joint not in data["initial"])


# ---------------------------------------------------------------------------------------------
# Malformed variants of triangle.toml: (id, edits, key the message must start with)

FIRST_MOVE = 'duration_s = 2.0\nleft = { to = "B" }'

MALFORMED = [
    ("unknown_top_level_key", [('waist = "locked"', 'waist = "locked"\ncolour = "red"')], "colour"),
    ("unknown_key_in_move", [('left = { to = "B" }', 'left = { to = "B", speed = 1.0 }')], "moves[0].left.speed"),
    ("string_control_period", [("control_period_s = 0.01", 'control_period_s = "0.01"')], "control_period_s"),
    (
        "position_two_numbers",
        [("position = [0.300, -0.200, -0.097]", "position = [0.300, 0.0]")],
        "waypoints.B.position",
    ),
    (
        "position_four_numbers",
        [("position = [0.300, -0.200, -0.097]", "position = [0.300, 0.0, 1.303, 0.0]")],
        "waypoints.B.position",
    ),
    ("zero_duration", [(FIRST_MOVE, 'duration_s = 0.0\nleft = { to = "B" }')], "moves[0].duration_s"),
    ("negative_duration", [(FIRST_MOVE, 'duration_s = -2.0\nleft = { to = "B" }')], "moves[0].duration_s"),
    ("zero_control_period", [("control_period_s = 0.01", "control_period_s = 0.0")], "control_period_s"),
    ("negative_control_period", [("control_period_s = 0.01", "control_period_s = -0.01")], "control_period_s"),
    ("missing_start", [('[start]\nleft = "A"\n', "")], "start"),
    ("missing_name", [('name = "triangle"\n', "")], "name"),
    ("zero_repetitions", [("repetitions = 5", "repetitions = 0")], "repetitions"),
    ("bad_waist", [('waist = "locked"', 'waist = "floppy"')], "waist"),
    ("robot_dir_missing", [(f'robot = "{ROBOT_DIR.as_posix()}"', 'robot = "/nonexistent/robots/nobody"')], "robot"),
    ("start_waypoint_missing", [('left = "A"', 'left = "Z"')], "start.left"),
    ("to_waypoint_missing", [('left = { to = "C" }', 'left = { to = "D" }')], "moves[1].left.to"),
    ("hand_without_start", [(FIRST_MOVE, FIRST_MOVE + '\nright = { to = "B" }')], "moves[0].right"),
    ("two_kinds_to_and_by", [('left = { to = "B" }', 'left = { to = "B", by = [0.0, 0.0, 0.1] }')], "moves[0].left"),
    ("hold_and_to", [('left = { to = "B" }', 'left = { to = "B", hold = true }')], "moves[0].left"),
    ("partial_arc", [('left = { to = "B" }', "left = { arc_center = [0.3, 0.1, 1.1] }")], "moves[0].left"),
    ("duration_not_whole_periods", [(FIRST_MOVE, 'duration_s = 2.005\nleft = { to = "B" }')], "moves[0].duration_s"),
    ("initial_home_missing", [initial_is('"sitting"')], "initial"),
    ("initial_unknown_joint", [initial_is("{ left_knee = 0.1 }")], "initial.left_knee"),
    ("initial_joint_above_limit", [initial_is("{ left_elbow = 5.0 }")], "initial.left_elbow"),
    ("initial_joint_below_limit", [initial_is("{ left_elbow = -5.0 }")], "initial.left_elbow"),
    (
        "initial_table_joint_above_limit",
        [(INITIAL, re.sub(r"^left_elbow = .*$", "left_elbow = 5.0", INITIAL, flags=re.MULTILINE))],
        "initial.left_elbow",
    ),
    ("initial_table_unknown_joint", [(INITIAL, INITIAL + "left_knee = 0.1\n")], "initial.left_knee"),
]


@pytest.mark.parametrize("edits, key", [(e, k) for _, e, k in MALFORMED], ids=[i for i, _, _ in MALFORMED])
def test_malformed_task_raises(tmp_path: Path, edits, key: str):
    path = variant(tmp_path, *edits)
    with pytest.raises(TaskFileError) as info:
        load_task(path)
    message = str(info.value)
    assert message.startswith(f"{path}:"), message
    after = message[len(f"{path}:") :]
    # the key comes right after "file:", followed by ':' / '.' / '[' (never a longer key name)
    assert re.match(re.escape(key) + r"(:|\.|\[)", after), message
    assert "\n" not in message


def test_malformed_list_is_large_enough():
    assert len(MALFORMED) >= 12


def test_elbow_limits_used_above_are_outside_the_urdf_range():
    lower, upper = urdf_limits("left_elbow")
    assert lower < 0 < upper
    assert 5.0 > upper and -5.0 < lower


def test_initial_joint_just_inside_its_limit_loads(tmp_path: Path):
    lower, upper = urdf_limits("left_elbow")
    value = upper - 1e-3
    task = load_task(variant(tmp_path, initial_is(f"{{ left_elbow = {value!r} }}")))
    assert task.initial_q["left_elbow"] == value
    # joints not named start at zero
    assert task.initial_q["right_elbow"] == 0.0
    value = lower + 1e-3
    task = load_task(variant(tmp_path, initial_is(f"{{ left_elbow = {value!r} }}"), name="ok2.toml"))
    assert task.initial_q["left_elbow"] == value


def test_duration_that_is_a_whole_number_of_periods_loads(tmp_path: Path):
    task = load_task(variant(tmp_path, (FIRST_MOVE, 'duration_s = 2.01\nleft = { to = "B" }')))
    assert task.spec.moves[0].duration_s == 2.01


def test_out_of_reach_waypoint(tmp_path: Path):
    data = tomllib.loads(TRIANGLE.read_text())
    B = np.array([1.5, 0.0, 1.3])
    # independently: B's wrist centre lies far beyond the arm's reach from the left shoulder
    R = Rotation.from_euler("xyz", data["waypoints"]["B"]["rpy"]).as_matrix()
    wrist = B - WRIST_TO_HAND_M * R[:, 2]
    assert np.linalg.norm(wrist - LEFT_SHOULDER) > ARM_REACH_M + 0.5
    path = variant(tmp_path, ("position = [0.300, -0.200, -0.097]", "position = [1.5, 0.0, 1.3]"))
    with pytest.raises(UnreachablePoseError) as info:
        load_task(path)
    assert isinstance(info.value, TaskFileError)
    assert str(info.value).startswith(f"{path}:waypoints.B:"), str(info.value)


def test_shipped_waypoints_are_within_reach_by_geometry():
    """Sanity of the geometry constants above: triangle's waypoints are reachable by them."""
    data = tomllib.loads(TRIANGLE.read_text())
    for wp in data["waypoints"].values():
        R = Rotation.from_euler("xyz", wp["rpy"]).as_matrix()
        wrist = (
            LEFT_SHOULDER + np.asarray(wp["position"]) - WRIST_TO_HAND_M * R[:, 2]
        )  # frame = "left.shoulder", scale 1 on the humanoid
        assert abs(0.32 - 0.28) < np.linalg.norm(wrist - LEFT_SHOULDER) < ARM_REACH_M


def test_invalid_toml(tmp_path: Path):
    text = triangle_text()
    lines = text.splitlines()
    index = next(i for i, line in enumerate(lines) if line.startswith("repetitions ="))
    lines[index] = "repetitions = [5"
    path = tmp_path / "syntax.toml"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(TaskFileError) as info:
        load_task(path)
    message = str(info.value)
    assert message.startswith(f"{path}:"), message
    assert "TOML" in message
    assert f"line {index + 1}" in message or f"line {index + 2}" in message, message


def test_infinite_duration_is_a_task_file_error(tmp_path: Path):
    path = variant(tmp_path, (FIRST_MOVE, 'duration_s = inf\nleft = { to = "B" }'))
    with pytest.raises(TaskFileError) as info:
        load_task(path)
    assert str(info.value).startswith(f"{path}:moves[0].duration_s"), str(info.value)


def test_wrong_type_for_union_key_names_the_key(tmp_path: Path):
    path = variant(tmp_path, initial_is("5"))
    with pytest.raises(TaskFileError) as info:
        load_task(path)
    assert str(info.value).startswith(f"{path}:initial:"), str(info.value)


@pytest.mark.parametrize(
    ("edit", "key"),
    [
        (("control_period_s = 0.01", "control_period_s = inf"), "control_period_s"),
        (("control_period_s = 0.01", "control_period_s = 1e-300"), "control_period_s"),
        (("control_period_s = 0.01", "control_period_s = 5.0"), "control_period_s"),
        (("control_period_s = 0.01", "control_period_s = 0.3"), "moves[0].duration_s"),
        (initial_is('{ left_elbow = "bent" }'), "initial.left_elbow"),
    ],
)
def test_extreme_or_mistyped_values_name_their_key(tmp_path: Path, edit, key):
    path = variant(tmp_path, edit)
    with pytest.raises(TaskFileError) as info:
        load_task(path)
    assert str(info.value).startswith(f"{path}:{key}:"), str(info.value)


def test_missing_file(tmp_path: Path):
    path = tmp_path / "nothing.toml"
    with pytest.raises(TaskFileError) as info:
        load_task(path)
    assert str(info.value).startswith(f"{path}:")


def test_relative_robot_path_resolves_against_the_task_file(tmp_path: Path, monkeypatch):
    """robot = "../robots/humanoid" is relative to the task file, not the working directory."""
    monkeypatch.chdir(tmp_path)
    task = load_task(TRIANGLE)
    assert task.robot.directory.resolve() == ROBOT_DIR.resolve()


# ---------------------------------------------------------------------------------------------
# CLI


CLI_CASES = [
    ("unknown_top_level_key", [('waist = "locked"', 'waist = "locked"\ncolour = "red"')]),
    ("out_of_reach", [("position = [0.300, -0.200, -0.097]", "position = [1.5, 0.0, 1.3]")]),
    ("robot_dir_missing", [(f'robot = "{ROBOT_DIR.as_posix()}"', 'robot = "/nonexistent/robots/nobody"')]),
]


@pytest.mark.parametrize("edits", [e for _, e in CLI_CASES], ids=[i for i, _ in CLI_CASES])
def test_cli_run_bad_task(tmp_path: Path, edits):
    from dualarm.cli import app

    path = variant(tmp_path, *edits)
    out_dir = tmp_path / "recordings"
    result = CliRunner().invoke(app, ["run", str(path), "--out", str(out_dir)])
    assert result.exit_code == 2, result.output
    try:
        stderr = result.stderr
    except (ValueError, AttributeError):  # older click: stderr not captured separately
        stderr = result.output
    for text in {result.output, stderr}:
        lines = [line for line in text.splitlines() if line.strip()]
        assert len(lines) == 1, text
        assert "error:" in lines[0]
        assert str(path) in lines[0]
        assert "Traceback" not in text
    assert result.exception is None or isinstance(result.exception, SystemExit)
    assert not out_dir.exists() or not any(out_dir.rglob("*")), list(out_dir.rglob("*"))


def test_bound_feedforward_refused_when_the_bounds_would_cross(tmp_path: Path):
    """With the feedforward, the band of eq (19) (relative shrink rate up to 1/c_tuning) must not
    close faster than nu: nu * c_tuning = 2 * 0.4 <= 1 is refused, naming the gesture table."""
    text = (
        (REPO / "tasks" / "ball_game.toml")
        .read_text()
        .replace('robot = "../robots/humanoid"', f'robot = "{ROBOT_DIR.as_posix()}"')
    )
    path = tmp_path / "ball_game.toml"
    path.write_text(text.replace("c_tuning = 1.0", "c_tuning = 0.4"))
    with pytest.raises(TaskFileError, match=r"ball_game\.toml:gesture: .*nu \* c_tuning > 1 \(here 0\.8\)"):
        load_task(path)
    path.write_text(
        text.replace("c_tuning = 1.0", "c_tuning = 0.4").replace(
            "bound_feedforward = true", "bound_feedforward = false"
        )
    )
    assert load_task(path).spec.gesture.c_tuning == 0.4
