"""A URDF that is not a tree of links is refused by dualarm's reader, in one line, before PyBullet sees it (issue 37,
findings 6, 7 and 9).

Each case is a small valid arm (three links, two revolute joints) with one defect. PyBullet's ``loadURDF`` crashed
(signal 11, no message) on the first three; a loop made ``robot init``'s chain search run forever; the others were
tracebacks from PyBullet or Python. ``robot init`` exits 2 with the same line, in a fresh process, and writes nothing.
"""

from __future__ import annotations

import time

import pytest

from dualarm.errors import RobotModelError
from dualarm.model.urdf import MAX_LINKS, load_urdf
from tests.helpers import dualarm_subprocess


def _joint(name: str, parent: str, child: str, lower: str = "-1", xyz: str = "0 0 0.1") -> str:
    return (
        f'<joint name="{name}" type="revolute"><parent link="{parent}"/><child link="{child}"/>'
        f'<origin xyz="{xyz}"/><axis xyz="0 0 1"/>'
        f'<limit lower="{lower}" upper="1" effort="1" velocity="1"/></joint>'
    )


def _robot(links: list[str], joints: list[str], name: str = "arm") -> str:
    body = "".join(f'<link name="{link}"/>' for link in links) + "".join(joints)
    return f'<?xml version="1.0"?><robot name="{name}">{body}</robot>'


ARM = (["a", "b", "c"], [_joint("j1", "a", "b"), _joint("j2", "b", "c")])
CASES = {
    "parent is its child": (_robot(ARM[0], [_joint("j1", "a", "b"), _joint("j2", "c", "c")]), "same link 'c'"),
    "duplicate joint name": (_robot(ARM[0], [_joint("j1", "a", "b"), _joint("j1", "b", "c")]), "two joints are named"),
    "5 MB robot name": (_robot(*ARM, name="r" * 5_000_000), "robot name 'rrrr"),
    "loop": (
        _robot(["a", "b", "c", "d"], [_joint("j1", "a", "b"), _joint("j2", "b", "c"), _joint("j3", "d", "c")]),
        "already the child of joint 'j2'",
    ),
    "cycle without root": (
        _robot(["a", "b"], [_joint("j1", "a", "b"), _joint("j2", "b", "a")]),
        "0 root links",
    ),
    "duplicate link name": (_robot(["a", "b", "b", "c"], ARM[1]), "two links are named 'b'"),
    "undeclared link": (_robot(["a", "b"], ARM[1]), "its child link 'c' is not declared"),
    "origin 1e308": (
        _robot(ARM[0], [_joint("j1", "a", "b", xyz="1e308 0 0"), ARM[1][1]]),
        "origin coordinate of 1e+308",
    ),
    "too many links": (
        _robot(
            [f"l{i}" for i in range(MAX_LINKS + 1)], [_joint(f"j{i}", f"l{i}", f"l{i + 1}") for i in range(MAX_LINKS)]
        ),
        f"{MAX_LINKS + 1} links",
    ),
}


@pytest.mark.parametrize("case", CASES)
def test_a_urdf_that_is_not_a_tree_is_one_line(tmp_path, case):
    text, needle = CASES[case]
    (tmp_path / "bad.urdf").write_text(text)
    with pytest.raises(RobotModelError) as raised:
        load_urdf(tmp_path / "bad.urdf")
    assert needle in str(raised.value) and "\n" not in str(raised.value) and len(str(raised.value)) < 400


def test_the_arm_itself_is_read_and_a_limit_beyond_1e6_is_none(tmp_path):
    """Limits of +-1e308 (an OverflowError in robot init) and Gazebo's 1e16 "no limit" (example-robot-data's iris):
    read as unbounded."""
    (tmp_path / "arm.urdf").write_text(_robot(*ARM))
    assert load_urdf(tmp_path / "arm.urdf").root == "a"
    (tmp_path / "wide.urdf").write_text(_robot(ARM[0], [_joint("j1", "a", "b", lower="-1e308"), ARM[1][1]]))
    assert load_urdf(tmp_path / "wide.urdf").joints[0].lower == -float("inf")


@pytest.mark.integration  # a process of its own: PyBullet's crash took the whole command down
@pytest.mark.parametrize("case", ["parent is its child", "duplicate joint name", "5 MB robot name", "loop"])
def test_robot_init_refuses_them_in_one_line_and_writes_nothing(tmp_path, case):
    text, needle = CASES[case]
    (tmp_path / "bad.urdf").write_text(text)
    start = time.monotonic()
    done = dualarm_subprocess(["robot", "init", str(tmp_path / "bad.urdf"), "--out", str(tmp_path / "out")], 120)
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1 and needle in done.stderr
    assert not (tmp_path / "out").exists() and time.monotonic() - start < 30


def crashes_loading(urdf: str) -> int:
    """A PyBullet load that crashes in C (reads address 0), as its loader did on malformed trees."""
    import ctypes

    ctypes.string_at(0)
    return 0


@pytest.mark.integration  # robot init, and a process of its own
def test_a_crash_of_pybullets_loader_is_one_line_and_leaves_nothing(tmp_path, monkeypatch):
    """The load robot init checks in a process of its own crashes (signal 11): one line naming the user's URDF and
    the signal, exit 2, and no half-written directory (it was left behind, and a re-run refused as not empty)."""
    from typer.testing import CliRunner

    from dualarm.cli import app

    monkeypatch.setattr("dualarm.describe.init.loads", crashes_loading)
    (tmp_path / "arm.urdf").write_text(_robot(*ARM))
    done = CliRunner().invoke(app, ["robot", "init", str(tmp_path / "arm.urdf"), "--out", str(tmp_path / "out")])
    assert done.exit_code == 2, done.output
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "arm.urdf: PyBullet crashed loading it (signal 11 (SIGSEGV))" in lines[0], lines
    assert not (tmp_path / "out").exists()
