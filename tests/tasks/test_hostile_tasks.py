"""Hostile task and robot input: every OS-level error on a task, robot or URDF path, every absurd
number, and task files generated from the schema or mutated from the shipped ones, through
``load_task`` and ``dualarm run FILE --stages path``.

What must hold: a run exits 0 with a complete run directory, or exits 2 with exactly one line on
stderr that names the file and the cause, and leaves no run directory that looks complete; never a
traceback, never a hang. The OS's own words for each path error come from calling the OS here
(``os.stat``), the narrowest joint range from the URDF read with ElementTree, and the TOML files
the generator writes are checked against ``tomllib``.
"""

from __future__ import annotations

import copy
import errno
import json
import math
import os
import tempfile
import tomllib
import types
import typing
import xml.etree.ElementTree as ET
from datetime import timedelta
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from pydantic import BaseModel
from tests.helpers import dualarm_subprocess
from typer.testing import CliRunner

from dualarm.cli import app
from dualarm.errors import RobotModelError, TaskFileError
from dualarm.model.robot import load_robot, robot_from_urdf
from dualarm.paths import build_reference
from dualarm.tasks import load_task
from dualarm.tasks.schema import Range, TaskSpec

REPO = Path(__file__).resolve().parents[2]
TASK_FILES = sorted((REPO / "tasks").glob("*.toml"))
ROBOT_DIR = REPO / "robots" / "humanoid"
URDF = ROBOT_DIR / "humanoid.urdf"
#: The most characters an error line may have: the path and user strings are quoted at ~80
#: characters each, lists of names at a dozen names.
MAX_LINE_CHARS = 1000

runner = CliRunner()


# ---------------------------------------------------------------------------------------------
# Writing task files: TOML out of plain data (checked against tomllib below)


def toml_string(text: str) -> str:
    """A TOML basic string: JSON's escapes are TOML's, and TOML also wants DEL escaped."""
    return json.dumps(text, ensure_ascii=False).replace("\x7f", "\\u007f")


def toml_value(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        return ("inf" if value > 0 else "-inf") if math.isinf(value) else repr(value)
    if isinstance(value, str):
        return toml_string(value)
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return (
            "{ " + ", ".join(f"{toml_string(str(k))} = {toml_value(v)}" for k, v in value.items()) + " }"
            if value
            else "{}"
        )
    raise TypeError(type(value))


def to_toml(data: dict) -> str:
    """A TOML document of ``data``: every top-level key one line, tables inline."""
    return "".join(f"{toml_string(str(k))} = {toml_value(v)}\n" for k, v in data.items())


def shipped(path: Path) -> dict:
    """A shipped task file's data, its robot made absolute (copies live elsewhere)."""
    data = tomllib.loads(path.read_text())
    data["robot"] = str(ROBOT_DIR)
    return data


SHIPPED = {p.stem: shipped(p) for p in TASK_FILES}


def shipped_text(name: str, *edits: tuple[str, str]) -> str:
    """tasks/<name>.toml's text, its robot absolute, each (old, new) edit applied to exactly one occurrence."""
    text = (REPO / "tasks" / f"{name}.toml").read_text()
    edits = (('robot = "../robots/humanoid"', f'robot = "{ROBOT_DIR.as_posix()}"'), *edits)
    for old, new in edits:
        assert text.count(old) == 1, f"edit target not unique/absent: {old!r}"
        text = text.replace(old, new)
    return text


def write(directory: Path, text: str, name: str = "t.toml") -> Path:
    path = directory / name
    path.write_text(text, encoding="utf-8")
    return path


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_toml_writer_round_trips_through_tomllib(name: str):
    data = SHIPPED[name]
    assert tomllib.loads(to_toml(data)) == data


def test_toml_writer_escapes_hostile_strings():
    data = {"k\n\x00\x7f": 'é✓\u202e\x00\x1f\x7f"\\', "n": [math.inf, -math.inf, -0.0, 5e-324, 10**30], "t": {}}
    assert tomllib.loads(to_toml(data)) == data


# ---------------------------------------------------------------------------------------------
# Judging a CLI run


def cli_run(task: Path | str, out: Path):
    return runner.invoke(app, ["run", str(task), "--stages", "path", "--out", str(out)])


def error_line(stderr: str) -> str:
    """The one line on stderr of a run that exits 2 (fails if there is not exactly one)."""
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1, stderr[:2000]
    assert lines[0].startswith("error: "), lines[0][:500]
    assert len(lines[0]) <= MAX_LINE_CHARS, len(lines[0])
    return lines[0]


def assert_no_complete_run(out: Path) -> None:
    """No directory under ``out`` looks like a finished run: a manifest saying complete, or metrics."""
    for manifest in out.rglob("manifest.json"):
        assert json.loads(manifest.read_text())["status"] == "failed", manifest
        assert not (manifest.parent / "metrics.json").exists(), manifest.parent


def assert_outcome(result, out: Path) -> None:
    """Exit 0 with a complete run directory, or exit 2 with one line and no complete-looking run; no traceback."""
    assert "Traceback" not in result.stdout and "Traceback" not in result.stderr, result.stderr[:3000]
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)[:2000]
    assert result.exit_code in (0, 2), (result.exit_code, result.stderr[:2000])
    if result.exit_code == 2:
        error_line(result.stderr)
        assert_no_complete_run(out)
        return
    run = Path(result.stdout.strip().splitlines()[-1])
    assert run.is_dir() and run.parent.parent == out, run
    manifest = json.loads((run / "manifest.json").read_text())
    assert manifest["status"] == "complete", manifest.get("error")
    assert (run / "metrics.json").is_file() and (run / "run.mcap").is_file()


# ---------------------------------------------------------------------------------------------
# OS-level errors on a path


def os_reason(path: str) -> str:
    """What the OS says when asked about ``path`` (its strerror), or the kind of file it is."""
    try:
        os.stat(path)
    except OSError as exc:
        assert exc.strerror
        return exc.strerror
    except ValueError:
        return "NUL byte"
    return "directory" if os.path.isdir(path) else "FIFO" if Path(path).is_fifo() else "regular file"


@pytest.fixture
def hostile_paths(tmp_path: Path) -> dict[str, str]:
    """Paths that cannot be read as a file, by what is wrong with them."""
    (tmp_path / "dir.toml").mkdir()
    os.mkfifo(tmp_path / "fifo.toml")
    (tmp_path / "loop_a").symlink_to(tmp_path / "loop_b")
    (tmp_path / "loop_b").symlink_to(tmp_path / "loop_a")
    (tmp_path / "file.txt").write_text("x")
    return {
        "missing": str(tmp_path / "nothing.toml"),
        "directory": str(tmp_path / "dir.toml"),
        "fifo": str(tmp_path / "fifo.toml"),
        "symlink_loop": str(tmp_path / "loop_a"),
        "component_over_255_bytes": str(tmp_path / ("é" * 130 + ".toml")),  # 265 bytes in UTF-8
        "through_a_regular_file": str(tmp_path / "file.txt" / "x.toml"),
        "nul_byte": str(tmp_path / "a\x00b.toml"),
        "10000_characters": str(tmp_path / ("abcdefghi/" * 1000)) + "x.toml",
    }


CASES = [
    "missing",
    "directory",
    "fifo",
    "symlink_loop",
    "component_over_255_bytes",
    "through_a_regular_file",
    "nul_byte",
    "10000_characters",
]


def assert_names(message: str, path: str, reason: str) -> None:
    """``message`` is one line that names ``path`` (quoted at about 80 characters: its start and its end) and
    ``reason``."""
    assert "\n" not in message and len(message) <= MAX_LINE_CHARS, message[:2000]
    assert path[:20] in message, message
    tail = path.rsplit("\x00", 1)[-1][-20:]
    assert tail in message, message
    assert reason in message, message


def test_os_reasons_are_what_the_cases_claim(hostile_paths):
    """The fixture's paths fail the way their names say (the OS's own words)."""
    assert os_reason(hostile_paths["missing"]) == os.strerror(errno.ENOENT)
    assert os_reason(hostile_paths["symlink_loop"]) == os.strerror(errno.ELOOP)
    assert os_reason(hostile_paths["component_over_255_bytes"]) == os.strerror(errno.ENAMETOOLONG)
    assert os_reason(hostile_paths["through_a_regular_file"]) == os.strerror(errno.ENOTDIR)
    assert os_reason(hostile_paths["10000_characters"]) == os.strerror(errno.ENAMETOOLONG)
    assert os_reason(hostile_paths["fifo"]) == "FIFO" and os_reason(hostile_paths["directory"]) == "directory"
    assert os_reason(hostile_paths["nul_byte"]) == "NUL byte"


@pytest.mark.parametrize("case", CASES)
def test_task_path_error_is_one_line(hostile_paths, case: str):
    path = hostile_paths[case]
    with pytest.raises(TaskFileError) as info:
        load_task(path)
    assert_names(str(info.value), path, os_reason(path))


@pytest.mark.parametrize("case", CASES)
def test_urdf_path_error_is_one_line(hostile_paths, case: str):
    path = hostile_paths[case]
    with pytest.raises(RobotModelError) as info:
        robot_from_urdf(path, "torso", "left_hand")
    assert_names(str(info.value), path, os_reason(path))


@pytest.mark.parametrize("case", CASES)
def test_robot_directory_path_error_is_one_line(hostile_paths, case: str):
    """A robot directory that is none of these: the message names the directory and the OS's reason for robot.toml
    beneath it."""
    path = hostile_paths[case]
    with pytest.raises(RobotModelError) as info:
        load_robot(path)
    below = os_reason(os.path.join(path, "robot.toml"))
    reason = "no robot.toml" if below == os.strerror(errno.ENOENT) else below
    assert_names(str(info.value), path, reason)


@pytest.mark.parametrize("case", CASES)
def test_task_whose_robot_key_is_a_hostile_path(tmp_path: Path, hostile_paths, case: str):
    path = write(
        tmp_path,
        shipped_text("triangle").replace(
            f'robot = "{ROBOT_DIR.as_posix()}"', f"robot = {toml_string(hostile_paths[case])}"
        ),
    )
    with pytest.raises(TaskFileError) as info:
        load_task(path)
    message = str(info.value)
    assert message.startswith(f"{path}:robot: "), message[:300]
    assert "\n" not in message and len(message) <= MAX_LINE_CHARS


@pytest.mark.parametrize(
    "case", [c for c in CASES if c != "nul_byte"]
)  # a command line cannot hold a NUL byte (C strings)
def test_cli_run_on_a_hostile_path(tmp_path: Path, hostile_paths, case: str):
    out = tmp_path / "out"
    result = cli_run(hostile_paths[case], out)
    assert result.exit_code == 2, result.output
    assert_names(error_line(result.stderr), hostile_paths[case], os_reason(hostile_paths[case]))
    assert "Traceback" not in result.output
    assert not out.exists() or not any(out.rglob("manifest.json"))


def test_task_on_a_file_without_read_permission(tmp_path: Path, monkeypatch):
    """Permission denied, as the OS reports it when opening (simulated: the tests may run as root, whom no mode
    stops)."""
    path = write(tmp_path, shipped_text("triangle"), "locked.toml")
    real_open = os.open

    def refuse(file, flags, *args, **kwargs):
        if str(file).endswith("locked.toml"):
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(file))
        return real_open(file, flags, *args, **kwargs)

    monkeypatch.setattr(os, "open", refuse)
    with pytest.raises(TaskFileError) as info:
        load_task(path)
    assert_names(str(info.value), str(path), os.strerror(errno.EACCES))


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads a file of mode 000")
def test_task_on_a_file_of_mode_000(tmp_path: Path):
    path = write(tmp_path, shipped_text("triangle"))
    path.chmod(0)
    with pytest.raises(TaskFileError) as info:
        load_task(path)
    assert_names(str(info.value), str(path), os.strerror(errno.EACCES))


def test_task_file_not_utf8(tmp_path: Path):
    path = tmp_path / "latin1.toml"
    path.write_bytes(shipped_text("triangle", ('title = "', 'title = "caf\xe9 ')).encode("latin-1"))
    with pytest.raises(UnicodeDecodeError):
        path.read_bytes().decode("utf-8")
    with pytest.raises(TaskFileError, match=r"latin1\.toml: cannot read the task file: not UTF-8 text"):
        load_task(path)


@pytest.mark.parametrize(
    "value", ["[" * 100_000 + "]" * 100_000, "{ a = " * 5_000 + "1" + " }" * 5_000], ids=["arrays", "tables"]
)
def test_task_file_nested_deeply(tmp_path: Path, value: str):
    path = write(tmp_path, shipped_text("carry_box", ('initial = "ready"\nframe', f"initial = {value}\nframe")))
    with pytest.raises(TaskFileError) as info:
        load_task(path)
    message = str(info.value)
    assert message.startswith(f"{path}:"), message[:300]
    assert "nested too deeply" in message or message.startswith(f"{path}:initial"), message[
        :300
    ]  # by tomllib or by the schema
    assert "\n" not in message and len(message) <= MAX_LINE_CHARS


@pytest.mark.parametrize("command", ["check", "ik"])
def test_urdf_option_naming_a_directory(tmp_path: Path, command: str):
    """``--urdf DIR``: one line, exit 2 (robot_from_urdf refuses it)."""
    if command == "check":
        args = ["robot", "check", "--urdf", str(tmp_path), "--base", "a", "--tip", "b"]
    else:
        args = [
            "ik",
            "srs",
            "--urdf",
            str(tmp_path),
            "--base",
            "a",
            "--tip",
            "b",
            "--pose",
            "0.3",
            "0.2",
            "1.0",
            "0",
            "0",
            "0",
            "--arm-angle",
            "0",
        ]
    result = runner.invoke(app, args)
    assert result.exit_code == 2, result.output
    line = error_line(result.stderr)
    assert str(tmp_path) in line and "directory" in line


@pytest.mark.integration
def test_subprocess_fifo_and_long_path_no_traceback_no_hang(tmp_path: Path, hostile_paths):
    for case in ("fifo", "10000_characters"):
        out = tmp_path / f"out_{case}"
        result = dualarm_subprocess(["run", hostile_paths[case], "--stages", "path", "--out", str(out)])
        assert result.returncode == 2, result.stderr[-3000:]
        assert "Traceback" not in result.stderr
        assert_names(error_line(result.stderr), hostile_paths[case], os_reason(hostile_paths[case]))
        assert not out.exists() or not any(out.rglob("manifest.json"))


@pytest.mark.integration
@pytest.mark.parametrize(
    "edit",
    [
        ('initial = "ready"\nframe', "initial = " + "[" * 100_000 + "]" * 100_000 + "\nframe"),
        ('waist = "locked"', 'waist = "locked"\n' + toml_string("\x1b[2J\u202e" * 2000) + " = 1"),
    ],
    ids=["nesting_beyond_the_stack", "terminal_codes_in_a_key"],
)
def test_subprocess_hostile_content_no_traceback(tmp_path: Path, edit):
    """Hostile content, on the real stderr: one line, no traceback, no escape sequence or bidi override printed raw (in
    carry_box, whose ``initial`` is the one-line ``"ready"``)."""
    path = write(tmp_path, shipped_text("carry_box", edit))
    result = dualarm_subprocess(["run", str(path), "--stages", "path", "--out", str(tmp_path / "out")])
    assert result.returncode == 2, result.stderr[-3000:]
    assert "Traceback" not in result.stderr
    line = error_line(result.stderr)
    assert line.startswith(f"error: {path}:") and "\x1b" not in line and "\u202e" not in line


def test_task_file_too_large(tmp_path: Path):
    """A (sparse) file of 17 MiB is refused before it is read, naming its size."""
    path = tmp_path / "huge.toml"
    with path.open("wb") as file:
        file.truncate(17 * 1024 * 1024)
    with pytest.raises(
        TaskFileError, match=rf"huge\.toml: cannot read the task file: {17 * 1024 * 1024:,} bytes, more than the"
    ):
        load_task(path)


# ---------------------------------------------------------------------------------------------
# Absurd numbers: refused at load, naming the key and the allowed range


def urdf_joint_ranges() -> dict[str, float]:
    """upper - lower of every limited joint, read from the URDF with ElementTree [rad]."""
    ranges = {}
    for joint in ET.parse(URDF).getroot().iter("joint"):
        limit = joint.find("limit")
        if joint.get("type") == "revolute" and limit is not None:
            ranges[joint.get("name")] = float(limit.get("upper")) - float(limit.get("lower"))
    return ranges


FIRST_MOVE = 'duration_s = 2.0\nleft = { to = "B" }'
ARM_ANGLE = "range_rad = [-3.141592653589793, 0.0]"

ABSURD = [
    (
        "margin_1e300",
        "triangle",
        (ARM_ANGLE, ARM_ANGLE + "\nmargin_rad = 1e300"),
        "arm_angle.margin_rad",
        "[0, 3.14159] rad",
    ),
    (
        "period_1e-12",
        "triangle",
        ("control_period_s = 0.01", "control_period_s = 1e-12"),
        "control_period_s",
        "[0.0001, 1] s",
    ),
    (
        "period_10",
        "triangle",
        ("control_period_s = 0.01", "control_period_s = 10.0"),
        "control_period_s",
        "[0.0001, 1] s",
    ),
    ("repetitions_1e7", "triangle", ("repetitions = 5", "repetitions = 10000000"), "repetitions", "[1, 1000]"),
    ("repetitions_2e80", "triangle", ("repetitions = 5", "repetitions = 1" + "0" * 80), "repetitions", "[1, 1000]"),
    (
        "duration_1e9_samples",
        "triangle",
        (FIRST_MOVE, 'duration_s = 1e7\nleft = { to = "B" }'),
        "moves[0].duration_s",
        "(0, 86400] s",
    ),
    (
        "arc_axis_1e200",
        "circle",
        ("arc_axis = [1.0, 0.0, 0.0]", "arc_axis = [1e200, 0.0, 0.0]"),
        "moves[0].left.arc_axis[0]",
        "[-1e+06, 1e+06]",
    ),
    (
        "arc_angle_1e300",
        "circle",
        ("arc_angle_rad = 6.283185307179586", "arc_angle_rad = 1e300"),
        "moves[0].left.arc_angle_rad",
        "[-12.5664, 12.5664] rad",
    ),
    (
        "obstacle_1e300",
        "bowl_grasp",
        ("size_m = [0.50, 1.00, 0.04]", "size_m = [1e300, 1.00, 0.04]"),
        "environment[0].size_m[0]",
        "[0.0001, 100] m",
    ),
    (
        "obstacle_far",
        "bowl_grasp",
        ("pose = { position = [0.55, 0.0, 0.88] }", "pose = { position = [1e300, 0.0, 0.88] }"),
        "environment[0].pose.position[0]",
        "[-100, 100] m",
    ),
    (
        "radius_1e-300",
        "bowl_grasp",
        ("radius_m = 0.07", "radius_m = 1e-300"),
        "environment[1].radius_m",
        "[0.0001, 100] m",
    ),
    (
        "max_joint_step_huge",
        "triangle",
        (ARM_ANGLE, ARM_ANGLE + "\nmax_joint_step_rad = 1e300"),
        "arm_angle.max_joint_step_rad",
        "(0, 6.28319] rad",
    ),
    (
        "vertical_1e200",
        "triangle",
        (ARM_ANGLE, ARM_ANGLE + "\nvertical = [1e200, 0.0, 0.0]"),
        "arm_angle.vertical[0]",
        "[-1e+06, 1e+06]",
    ),
    (
        "waypoint_1e300",
        "triangle",
        ("position = [0.300, -0.200, -0.097]", "position = [0.300, 0.0, 1e300]"),
        "waypoints.B.position[2]",
        "[-100, 100] m",
    ),
    (
        "rpy_1e300",
        "triangle",
        ("rpy = [-0.517, -1.380, 2.390]", "rpy = [-0.517, -1.380, 1e300]"),
        "waypoints.B.rpy[2]",
        "[-6.28319, 6.28319] rad",
    ),
    (
        "by_1e300",
        "carry_box",
        ("left = { by = [0.0, 0.0, 0.20] }", "left = { by = [0.0, 0.0, 1e300] }"),
        "moves[0].left.by[2]",
        "[-100, 100] m",
    ),
    (
        "box_1e-300",
        "carry_box",
        ("size_m = [0.15, 0.24, 0.15]", "size_m = [0.15, 0.24, 1e-300]"),
        "object.size_m[2]",
        "[0.0001, 100] m",
    ),
    (
        "velocity_limit_tiny",
        "ball_game",
        ("velocity = 6.0", "velocity = 1e-300"),
        "limits.velocity",
        "[0.01, 100] rad/s",
    ),
    (
        "velocity_limit_huge",
        "ball_game",
        ("velocity = 6.0", "velocity = 1e300"),
        "limits.velocity",
        "[0.01, 100] rad/s",
    ),
    ("gesture_nu", "ball_game", ("nu = 2.0", "nu = 1e300"), "gesture.nu", "(0, 1000] 1/s"),
    (
        "gesture_gain",
        "ball_game",
        ("feedback_gain = 50.0", "feedback_gain = 1e300"),
        "gesture.feedback_gain",
        "(0, 1000] 1/s",
    ),
    ("gesture_t_sp", "ball_game", ("t_sp_s = 0.75", "t_sp_s = 1e300"), "gesture.t_sp_s", "(0, 86400] s"),
    ("gesture_c_tuning", "ball_game", ("c_tuning = 1.0", "c_tuning = 1e-300"), "gesture.c_tuning", "[0.0001, 1] s"),
    (
        "retime_fraction",
        "ball_game",
        ('timing = "task"', 'timing = "task"\nvelocity_fraction = 1e-300'),
        "retime.velocity_fraction",
        "[0.01, 1]",
    ),
    (
        "wta_bound",
        "bowl_grasp",
        (
            "bounds = [[-0.02, 0.02], [0.0, 0.0], [-0.01, 0.03], [0.0, 0.0], [0.0, 0.0], [-0.4, 0.4]]\n\n[[wta]]",
            "bounds = [[-1e300, 0.02], [0.0, 0.0], [-0.01, 0.03], [0.0, 0.0], [0.0, 0.0], [-0.4, 0.4]]\n\n[[wta]]",
        ),
        "wta[0].bounds[0][0]",
        "[-100, 100] m",
    ),
    (
        "wta_weight",
        "bowl_grasp",
        ('name = "bowl_right"', 'name = "bowl_right"\nweight = 1e300'),
        "wta[1].weight",
        "[1e-06, 1e+06]",
    ),
    (
        "initial_joint_1e300",
        "carry_box",
        ('initial = "ready"\nframe', "initial = { left_elbow = 1e300 }\nframe"),
        "initial.left_elbow",
        "[-100, 100]",
    ),
]


@pytest.mark.parametrize(
    ("edit", "key", "allowed"), [(e, k, a) for _, _, e, k, a in ABSURD], ids=[i for i, *_ in ABSURD]
)
def test_absurd_number_refused_with_key_and_range(tmp_path: Path, edit, key: str, allowed: str):
    task = next(t for i, t, e, *_ in ABSURD if e == edit)
    path = write(tmp_path, shipped_text(task, edit))
    with pytest.raises(TaskFileError) as info:
        load_task(path)
    message = str(info.value)
    assert message.startswith(f"{path}:{key}: "), message
    assert f"allowed range {allowed}" in message, message
    assert "\n" not in message and len(message) <= MAX_LINE_CHARS


def test_margin_at_half_the_narrowest_arm_joint_range(tmp_path: Path):
    """margin_rad must stay below half the narrowest range of the driven (left) arm's joints, taken from the URDF."""
    left = {n: r for n, r in urdf_joint_ranges().items() if n.startswith("left_")}
    half = min(left.values()) / 2
    ok = load_task(
        write(tmp_path, shipped_text("triangle", (ARM_ANGLE, f"{ARM_ANGLE}\nmargin_rad = {half - 1e-3!r}")), "ok.toml")
    )
    assert ok.spec.arm_angle.margin_rad == pytest.approx(half - 1e-3)
    path = write(tmp_path, shipped_text("triangle", (ARM_ANGLE, f"{ARM_ANGLE}\nmargin_rad = {half + 1e-3!r}")))
    with pytest.raises(TaskFileError) as info:
        load_task(path)
    message = str(info.value)
    assert message.startswith(f"{path}:arm_angle.margin_rad: "), message
    bound = float(message.split("allowed range [0, ")[1].split(")")[0])
    assert bound == pytest.approx(half, abs=1e-3)


@pytest.mark.integration
def test_cli_margin_1e300_exits_2_at_once(tmp_path: Path):
    """The case that hung the IK stage past 60 s: now refused at load, before any stage, through the CLI in a fresh
    process."""
    path = write(tmp_path, shipped_text("triangle", (ARM_ANGLE, ARM_ANGLE + "\nmargin_rad = 1e300")))
    out = tmp_path / "out"
    result = dualarm_subprocess(["run", str(path), "--ik", "mc-inverse", "--out", str(out)])
    assert result.returncode == 2, result.stderr[-3000:]
    assert "Traceback" not in result.stderr
    line = error_line(result.stderr)
    assert "arm_angle.margin_rad" in line and "allowed range" in line
    assert not out.exists() or not any(out.rglob("manifest.json"))


SAMPLES_PER_TRIANGLE_REPETITION = round(3 * 2.0 / 0.01)  # three 2 s edges at 0.01 s


def test_sample_budget(tmp_path: Path):
    """The path's samples, 1 + repetitions * periods per repetition, are bounded: 166 repetitions of the triangle fit in
    100,000, 167 do not."""
    fits = 1 + 166 * SAMPLES_PER_TRIANGLE_REPETITION
    over = 1 + 167 * SAMPLES_PER_TRIANGLE_REPETITION
    assert fits <= 100_000 < over
    assert (
        load_task(
            write(tmp_path, shipped_text("triangle", ("repetitions = 5", "repetitions = 166")), "ok.toml")
        ).spec.repetitions
        == 166
    )
    path = write(tmp_path, shipped_text("triangle", ("repetitions = 5", "repetitions = 167")))
    with pytest.raises(TaskFileError) as info:
        load_task(path)
    message = str(info.value)
    assert message.startswith(f"{path}:moves: "), message
    assert f"{over:,} samples" in message and "100,000" in message


def test_repetitions_override_is_bounded(tmp_path: Path):
    path = write(tmp_path, shipped_text("triangle"))
    for reps in (10**7, 0, -1):
        with pytest.raises(TaskFileError, match=r"repetitions: the override must be an integer in \[1, 1000\]"):
            load_task(path, reps)
    with pytest.raises(TaskFileError, match=rf"{1 + 167 * SAMPLES_PER_TRIANGLE_REPETITION:,} samples"):
        load_task(path, 167)
    result = runner.invoke(app, ["run", str(path), "--reps", "10000000", "--out", str(tmp_path / "out")])
    assert result.exit_code == 2
    assert "[1, 1000]" in error_line(result.stderr)


def test_arc_axis_of_any_length_gives_the_same_circle(tmp_path: Path):
    """arc_axis is normalised without overflow: [1e6, 0, 0] and [1e-5, 0, 0] draw the circle [1, 0, 0] does, radius 0.15
    m about [0.31, 0.09, 1.05]."""
    references = {}
    for axis in ("1.0", "1e6", "1e-5"):
        text = shipped_text(
            "circle",
            ("arc_axis = [1.0, 0.0, 0.0]", f"arc_axis = [{axis}, 0.0, 0.0]"),
            ("repetitions = 5", "repetitions = 1"),
        )
        references[axis] = build_reference(load_task(write(tmp_path, text, f"a{axis}.toml"))).hands["left"].position
    p = references["1.0"]
    assert np.allclose(np.linalg.norm(p - [0.31, 0.09, 1.05], axis=1), 0.15, atol=1e-12)
    assert np.ptp(p[:, 1]) == pytest.approx(0.30, abs=1e-4) and np.ptp(p[:, 2]) == pytest.approx(0.30, abs=1e-4)
    for axis in ("1e6", "1e-5"):
        assert np.allclose(references[axis], p, atol=1e-12)


def test_zero_or_tiny_directions_refused(tmp_path: Path):
    for edit, key in (
        (("arc_axis = [1.0, 0.0, 0.0]", "arc_axis = [0.0, 0.0, 0.0]"), "moves[0].left"),
        (("arc_axis = [1.0, 0.0, 0.0]", "arc_axis = [1e-300, 0.0, 0.0]"), "moves[0].left"),
        (('mode = "auto"', 'mode = "auto"\nvertical = [0.0, 0.0, 0.0]'), "arm_angle"),
    ):
        path = write(tmp_path, shipped_text("circle", edit))
        with pytest.raises(TaskFileError) as info:
            load_task(path)
        assert str(info.value).startswith(f"{path}:{key}: ") and "length of at least 1e-06" in str(info.value), str(
            info.value
        )


@pytest.mark.integration
def test_a_huge_obstacle_around_the_robot_overlaps_its_base(tmp_path: Path):
    """Within the size range, a 100 m box centred on the robot is refused by PyBullet's overlap check (it holds the
    base)."""
    path = write(
        tmp_path,
        shipped_text(
            "bowl_grasp",
            ("size_m = [0.50, 1.00, 0.04]", "size_m = [100.0, 100.0, 100.0]"),
            ("pose = { position = [0.55, 0.0, 0.88] }", "pose = { position = [0.0, 0.0, 0.0] }"),
        ),
    )
    with pytest.raises(TaskFileError, match=r":environment\[0\]: 'table' overlaps the robot's base link"):
        load_task(path)


def test_gesture_goal_outside_the_joint_limits(tmp_path: Path):
    """A goal beyond the joint's URDF limits would move eq (19)'s bounds outside them."""
    upper = next(
        float(j.find("limit").get("upper"))
        for j in ET.parse(URDF).getroot().iter("joint")
        if j.get("name") == "left_shoulder_yaw"
    )
    path = write(
        tmp_path, shipped_text("ball_game", ("left_shoulder_yaw = 1.1439", f"left_shoulder_yaw = {upper + 0.01!r}"))
    )
    with pytest.raises(TaskFileError) as info:
        load_task(path)
    assert str(info.value).startswith(f"{path}:gesture.goal_upper.left_shoulder_yaw: "), str(info.value)
    assert f"{upper:g}]" in str(info.value)


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (('name = "triangle"', 'name = "' + "n" * 65 + '"'), "name: String should have at most 64 characters"),
        (('waist = "locked"', 'waist = "locked"\n' + toml_string("é✓\u202e" * 5000) + " = 1"), "unknown key"),
        (('left = "A"', 'left = "' + "Z" * 10_000 + '"'), "no waypoint 'ZZZ"),
    ],
    ids=["long_name", "huge_unicode_key", "huge_waypoint_name"],
)
def test_long_user_strings_are_quoted_short(tmp_path: Path, edit, message: str):
    path = write(tmp_path, shipped_text("triangle", edit))
    with pytest.raises(TaskFileError) as info:
        load_task(path)
    assert message in str(info.value) and len(str(info.value)) <= 400, str(info.value)[:1000]
    assert "\u202e" not in str(info.value)


# ---------------------------------------------------------------------------------------------
# Property-based: task files from the schema and mutations of the shipped ones, through the CLI

#: Names the generator uses for strings, so that references resolve now and then.
NAMES = [
    "A",
    "B",
    "C",
    "P0",
    "grasp",
    "initial",
    "ready",
    "zero",
    "left",
    "right",
    "left_elbow",
    "right_elbow",
    "waist_yaw",
    "box",
    "table",
    "left_palm",
    "humanoid",
    "triangle",
]


def nested(depth: int) -> list:
    value: list = []
    for _ in range(depth):
        value = [value]
    return value


HOSTILE = [
    0,
    -1,
    1,
    10**7,
    2**63,
    -(2**63),
    10**30,
    1e300,
    -1e300,
    1e-12,
    5e-324,
    -0.0,
    math.nan,
    math.inf,
    -math.inf,
    True,
    False,
]
HOSTILE += [
    "",
    "nan",
    "inf",
    "1e300",
    "0.01",
    "é✓\u202e\x00\n",
    "x" * 10_000,
    [],
    {},
    [1e300, 0.0, 0.0],
    [0.0, 0.0, 0.0],
    {"left": 1e300},
    {"": {}},
]
hostile_values = st.one_of(
    st.sampled_from(HOSTILE).map(copy.deepcopy),
    st.floats(),
    st.integers(min_value=-(2**80), max_value=2**80),
    st.text(max_size=20),
    st.integers(1, 300).map(nested),
)


def locations(node: object, prefix: tuple = ()):
    """Every key path into ``node`` (dict keys and list indices), the root's ``()`` first."""
    yield prefix
    if isinstance(node, dict):
        for key, value in node.items():
            yield from locations(value, (*prefix, key))
    elif isinstance(node, list):
        for index, value in enumerate(node):
            yield from locations(value, (*prefix, index))


def at(data: object, path: tuple) -> object:
    for part in path:
        data = data[part]  # type: ignore[index]
    return data


@st.composite
def mutated_tasks(draw) -> dict:
    """A shipped task with one to three mutations: a value replaced (by a hostile value or the old one scaled to an
    extreme), a key deleted, a key or item added."""
    data = copy.deepcopy(SHIPPED[draw(st.sampled_from(sorted(SHIPPED)))])
    for _ in range(draw(st.integers(1, 3))):
        where = draw(st.sampled_from(list(locations(data))))
        old = at(data, where)
        kind = draw(st.sampled_from(["replace", "scale", "delete", "add"] if where else ["add"]))
        if kind == "add" or (kind == "scale" and not isinstance(old, (int, float))):
            if isinstance(old, dict):
                old[draw(st.sampled_from(NAMES) | st.text(max_size=12))] = draw(hostile_values)
            elif isinstance(old, list):
                old.append(draw(hostile_values))
            continue
        parent, last = at(data, where[:-1]), where[-1]
        if kind == "delete":
            del parent[last]  # type: ignore[attr-defined]
        elif kind == "scale" and isinstance(old, bool):
            parent[last] = not old  # type: ignore[index]
        elif kind == "scale" and isinstance(old, int):
            parent[last] = old * draw(st.sampled_from([0, -1, 10**3, 10**7, 10**12, 10**400]))  # type: ignore[index]
        elif kind == "scale":
            parent[last] = old * draw(st.sampled_from([0.0, -1.0, 1e-12, 1e-6, 1e3, 1e7, 1e12, 1e300]))  # type: ignore[index,operator]
        else:
            parent[last] = draw(hostile_values)  # type: ignore[index]
    return data


def mostly(valid: st.SearchStrategy, other: st.SearchStrategy) -> st.SearchStrategy:
    """``valid`` 19 times in 20, else ``other``: a task of many values then often has all of them valid, and gets past
    the schema to the checks against the robot and to the path stage."""
    return st.integers(0, 19).flatmap(lambda i: other if i == 0 else valid)


def strategy_for(annotation: object, metadata: tuple = ()) -> st.SearchStrategy:
    """Values for a schema annotation: mostly of its type and within its :class:`Range`, sometimes at or beyond the
    range's ends or hostile."""
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if origin is typing.Annotated:
        return strategy_for(args[0], (*metadata, *annotation.__metadata__))  # type: ignore[attr-defined]
    if origin in (typing.Union, types.UnionType):
        return st.one_of([strategy_for(a) for a in args if a is not type(None)])
    if origin is typing.Literal:
        return st.sampled_from(args)
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return st.lists(strategy_for(args[0]), max_size=3)
        return st.tuples(*(strategy_for(a) for a in args)).map(list)
    if origin is dict:  # a TOML key is a string: a hostile key (a list, a number) is written as its text
        return st.dictionaries(strategy_for(args[0]).map(str), strategy_for(args[1]), max_size=3)
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return model_strategy(annotation)
    if annotation is bool:
        return mostly(st.booleans(), hostile_values)
    if annotation is str:
        return mostly(st.sampled_from(NAMES), st.text(max_size=12) | hostile_values)
    if annotation in (int, float):
        ranges = [m for m in metadata if isinstance(m, Range)]
        if not ranges:
            return st.floats(-10, 10) if annotation is float else st.integers(-10, 10)
        r = ranges[0]
        inside = (
            st.floats(r.low, r.high, exclude_min=r.low_open)
            if annotation is float
            else st.integers(int(r.low), int(r.high))
        )
        edges = st.sampled_from([r.low, r.high, r.high * 1.5 + 1, r.low - 1, -r.high])
        return mostly(inside, st.one_of(edges, hostile_values))
    raise NotImplementedError(annotation)


def model_strategy(model: type[BaseModel]) -> st.SearchStrategy:
    """A table of ``model``'s fields: the required ones always, the others now and then."""
    required, optional = {}, {}
    for name, field in model.model_fields.items():
        strategy = strategy_for(field.annotation, tuple(field.metadata))
        (required if field.is_required() else optional)[name] = strategy
    return st.fixed_dictionaries(required, optional=optional)


@st.composite
def schema_tasks(draw) -> dict:
    """A task generated from :class:`TaskSpec`'s annotations, usually on the humanoid."""
    data = draw(model_strategy(TaskSpec))
    if draw(st.integers(0, 9)):
        data["robot"] = str(ROBOT_DIR)
    return data


PROPERTY = settings(
    max_examples=150,
    derandomize=True,
    database=None,
    deadline=timedelta(seconds=120),
    suppress_health_check=[
        HealthCheck.too_slow,
        HealthCheck.data_too_large,
        HealthCheck.filter_too_much,
        HealthCheck.large_base_example,
    ],
)


@pytest.fixture(scope="module")
def scratch(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("hostile")


def run_generated(scratch: Path, data: dict) -> None:
    case = Path(tempfile.mkdtemp(dir=scratch))
    path = write(case, to_toml(data))
    out = case / "out"
    result = cli_run(path, out)
    event(f"exit {result.exit_code}")  # the mix shows with --hypothesis-show-statistics
    assert_outcome(result, out)


@pytest.mark.integration
@PROPERTY
@given(data=mutated_tasks())
def test_mutated_shipped_tasks_complete_or_fail_in_one_line(scratch: Path, data: dict):
    run_generated(scratch, data)


@pytest.mark.integration
@PROPERTY
@given(data=schema_tasks())
def test_schema_generated_tasks_complete_or_fail_in_one_line(scratch: Path, data: dict):
    run_generated(scratch, data)


@pytest.mark.integration
def test_generators_reach_both_outcomes(scratch: Path):
    """The mutations are not all refused: a sample of them, drawn as the property test draws, has complete runs and
    refusals."""
    codes = []

    @settings(max_examples=40, derandomize=True, database=None, deadline=None, suppress_health_check=list(HealthCheck))
    @given(data=mutated_tasks())
    def sample(data):
        path = write(Path(tempfile.mkdtemp(dir=scratch)), to_toml(data))
        try:
            load_task(path)
            codes.append(0)
        except TaskFileError:
            codes.append(2)

    sample()
    assert 0 in codes and 2 in codes, codes
