"""A fuzz of ``dualarm robot init`` (Hypothesis): the shipped humanoid's URDF, mutated, and meshes that point anywhere.

Each example changes the URDF at random places: an element deleted or doubled, an attribute deleted or set to a hostile
value (NaN, infinities, 1e308, negative, empty, text, a path out of the folder, 10,000 characters, another element's
name), a visual shape made a mesh (an OBJ whose ``mtllib`` and ``map_Kd`` point in or out of the folder, a missing
file, ``/proc/self/environ``). Every example either initialises the robot (exit 0, a ``robot.toml``) or is refused
in one line starting ``error:`` with exit 2 and nothing written, within 30 s: never a traceback, a crash or a hang.
Derandomized (a fixed seed), so a run is repeatable; the examples found are printed with ``pytest -s``.
"""

from __future__ import annotations

import time
import xml.etree.ElementTree as ET

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from dualarm.cli import app
from tests.helpers import HUMANOID

pytestmark = pytest.mark.integration  # init loads PyBullet
runner = CliRunner()
SOURCE = ET.parse(next(HUMANOID.glob("*.urdf")) if HUMANOID.is_dir() else HUMANOID).getroot()
ELEMENTS = len(list(SOURCE.iter()))
VALUES = [
    "", "nan", "inf", "-inf", "-1", "0", "1e308", "-1e308", "x", "1 2", "0 0 0 0", "../../../etc/passwd",
    "/proc/self/environ", "a" * 10_000, "base_link", "left_shoulder_pitch", "package://x/../../y",
]  # fmt: skip
MESHES = [
    "inside.obj", "missing.obj", "/proc/self/environ", "../outside.obj", "file:///etc/hostname", "https://x.org/a.obj",
]  # fmt: skip
MATERIALS = ["mtllib inside.mtl", "mtllib ../outside.mtl", "mtllib /etc/hostname", ""]
TEXTURES = ["map_Kd paint.png", "map_Kd ../outside.png", "map_Kd /etc/hostname", ""]

mutation = st.one_of(
    st.tuples(st.just("delete"), st.integers(1, ELEMENTS - 1)),
    st.tuples(st.just("double"), st.integers(1, ELEMENTS - 1)),
    st.tuples(st.just("unset"), st.integers(0, ELEMENTS - 1)),
    st.tuples(st.just("set"), st.integers(0, ELEMENTS - 1), st.sampled_from(VALUES)),
    st.tuples(st.just("mesh"), st.integers(0, 10**6), st.sampled_from(MESHES)),
)


def _mutate(root: ET.Element, change: tuple) -> None:
    elements = list(root.iter())
    kind, at = change[0], change[1] % len(elements)
    element = elements[at]
    parent = next((p for p in root.iter() if element in list(p)), None)
    if kind == "delete" and parent is not None:
        parent.remove(element)
    elif kind == "double" and parent is not None:
        parent.insert(list(parent).index(element), ET.fromstring(ET.tostring(element)))
    elif kind == "unset" and element.attrib:
        del element.attrib[sorted(element.attrib)[at % len(element.attrib)]]
    elif kind == "set" and element.attrib:
        element.set(sorted(element.attrib)[at % len(element.attrib)], change[2])
    elif kind == "mesh":
        geometries = list(root.iter("geometry"))
        if geometries:
            geometry = geometries[at % len(geometries)]
            for shape in list(geometry):
                geometry.remove(shape)
            ET.SubElement(geometry, "mesh", filename=change[2])


def _folder(tmp_path, material: str, texture: str):
    """The description's folder: an OBJ (a triangle) with ``material``, its MTL with ``texture``; files outside it."""
    folder = tmp_path / "robot"
    folder.mkdir()
    (folder / "inside.obj").write_text(f"{material}\nv 0 0 0\nv 0.01 0 0\nv 0 0.01 0\nf 1 2 3\n")
    (folder / "inside.mtl").write_text(f"newmtl m\nKd 0.5 0.5 0.5\n{texture}\n")
    (folder / "paint.png").write_bytes(b"\x89PNG")
    for name in ("outside.obj", "outside.mtl", "outside.png"):
        (tmp_path / name).write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    return folder


@settings(
    max_examples=100,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(
    changes=st.lists(mutation, min_size=1, max_size=3),
    material=st.sampled_from(MATERIALS),
    texture=st.sampled_from(TEXTURES),
)
def test_robot_init_on_a_mutated_urdf_completes_or_is_one_line(tmp_path_factory, changes, material, texture):
    tmp_path = tmp_path_factory.mktemp("fuzz")
    folder = _folder(tmp_path, material, texture)
    root = ET.fromstring(ET.tostring(SOURCE))
    for change in changes:
        _mutate(root, change)
    (folder / "robot.urdf").write_text(ET.tostring(root, encoding="unicode"))
    out = tmp_path / "out"
    start = time.monotonic()
    done = runner.invoke(app, ["robot", "init", str(folder / "robot.urdf"), "--out", str(out)])
    seconds = time.monotonic() - start
    print(changes, material, texture, done.exit_code, (done.stderr or "").strip()[:160])
    assert seconds < 30, (changes, seconds)
    assert done.exception is None or isinstance(done.exception, SystemExit), (changes, repr(done.exception))
    if done.exit_code == 0:
        assert (out / "robot.toml").is_file(), changes
    else:
        lines = done.stderr.strip().splitlines()
        assert done.exit_code == 2 and len(lines) == 1 and lines[0].startswith("error: "), (changes, done.output)
        assert not out.exists(), changes
