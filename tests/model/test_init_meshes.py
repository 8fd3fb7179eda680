"""``dualarm robot init`` copies a description's own mesh and material files, and nothing else (issue 37, finding 1).

pybullet_data's KUKA iiwa, copied into a description folder, with one reference turned hostile: an OBJ's ``mtllib``
or an MTL's ``map_Kd`` that climbs out of the folder or names an absolute file, a mesh that does, a link that leads
out, a ``package://`` path that climbs out of its package, a URL. Each is refused in one line naming the reference,
exit 2, before anything is written, and the file it named is nowhere in the output. References that stay inside
(a texture in a sibling folder of the package, a package through ROS_PACKAGE_PATH) are still copied.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from unittest import mock

import pybullet_data
import pytest
from typer.testing import CliRunner

from dualarm.cli import app

pytestmark = pytest.mark.integration  # init reads the robot in PyBullet before it looks at meshes
runner = CliRunner()
IIWA = Path(pybullet_data.getDataPath()) / "kuka_iiwa"
SECRET = "ssh-ed25519 AAAA-not-for-sharing"


@pytest.fixture
def description(tmp_path):
    """A description package ``tmp_path/pkg`` (package.xml, urdf/, meshes/) and a secret file beside it."""
    package = tmp_path / "pkg"
    shutil.copytree(IIWA / "meshes", package / "meshes")
    (package / "urdf").mkdir()
    (package / "package.xml").write_text("<package><name>pkg</name></package>")
    (package / "urdf" / "iiwa.urdf").write_text(
        (IIWA / "model.urdf").read_text().replace('filename="meshes/', 'filename="../meshes/')
    )
    (tmp_path / "secret").write_text(SECRET)
    return package


def _init(package: Path, out: Path):
    return runner.invoke(app, ["robot", "init", str(package / "urdf" / "iiwa.urdf"), "--out", str(out)])


def _nowhere(root: Path) -> bool:
    return not root.exists() or not any(
        p.is_file() and SECRET in p.read_text(errors="replace") for p in root.rglob("*")
    )


def _refused(package: Path, out: Path, needle: str) -> None:
    done = _init(package, out)
    assert done.exit_code == 2, done.output
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0] and "refused" in lines[0], lines
    assert not out.exists() and _nowhere(out)


def _edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))


@pytest.mark.parametrize("reference", ["../../secret", "{tmp}/secret"])
def test_an_obj_mtllib_out_of_the_description_is_refused(description, tmp_path, reference):
    line = "mtllib " + reference.format(tmp=tmp_path)
    _edit(description / "meshes" / "link_0.obj", "mtllib link_0.mtl", line)
    _refused(description, tmp_path / "out", f"names '{line}', which leads out of {description}")


@pytest.mark.parametrize("reference", ["../../secret", "{tmp}/secret"])
def test_an_mtl_texture_out_of_the_description_is_refused(description, tmp_path, reference):
    line = "map_Kd " + reference.format(tmp=tmp_path)
    _edit(description / "meshes" / "link_0.mtl", "illum 2", "illum 2\n" + line)
    _refused(description, tmp_path / "out", f"names '{line}', which leads out of")


@pytest.mark.parametrize("filename", ["../../secret", "{tmp}/secret", "file://{tmp}/secret"])
def test_a_mesh_out_of_the_description_is_refused(description, tmp_path, filename):
    filename = filename.format(tmp=tmp_path)
    _edit(description / "urdf" / "iiwa.urdf", 'filename="../meshes/link_0.obj"', f'filename="{filename}"')
    _refused(description, tmp_path / "out", f"mesh '{filename}' leads out of {description}")


def test_a_link_out_of_the_description_is_refused(description, tmp_path):
    (description / "meshes" / "link_0.obj").unlink()
    (description / "meshes" / "link_0.obj").symlink_to(tmp_path / "secret")
    _refused(description, tmp_path / "out", "mesh '../meshes/link_0.obj' leads out of")


def test_a_package_path_out_of_its_package_is_refused(description, tmp_path):
    _edit(description / "urdf" / "iiwa.urdf", 'filename="../meshes/link_0.obj"', 'filename="package://pkg/../secret"')
    with mock.patch.dict(os.environ, {"ROS_PACKAGE_PATH": str(tmp_path)}):
        _refused(description, tmp_path / "out", "mesh 'package://pkg/../secret' leads out of")


def test_a_url_is_refused(description, tmp_path):
    _edit(description / "urdf" / "iiwa.urdf", 'filename="../meshes/link_0.obj"', 'filename="https://x.org/a.obj"')
    _refused(description, tmp_path / "out", "only package:// and file:// are read")


def test_a_texture_inside_the_package_and_a_package_mesh_are_copied(description, tmp_path):
    """A texture in a sibling folder of the package's meshes, and meshes named through ROS_PACKAGE_PATH: copied."""
    (description / "textures").mkdir()
    (description / "textures" / "paint.png").write_bytes(b"\x89PNG not really")
    _edit(description / "meshes" / "link_0.mtl", "illum 2", "illum 2\nmap_Kd ../textures/paint.png")
    _edit(
        description / "urdf" / "iiwa.urdf",
        'filename="../meshes/link_1.obj"',
        'filename="package://pkg/meshes/link_1.obj"',
    )
    with mock.patch.dict(os.environ, {"ROS_PACKAGE_PATH": str(tmp_path)}):
        done = _init(description, tmp_path / "out")
    assert done.exit_code == 0, done.output
    assert (tmp_path / "out" / "meshes" / "textures" / "paint.png").read_bytes() == b"\x89PNG not really"
    assert (tmp_path / "out" / "meshes" / "meshes" / "link_1.obj").is_file()
