"""The meshes a URDF names, found and copied into a robot directory.

Found through ``package://``, relative and absolute paths.
"""

from __future__ import annotations

import os
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

from dualarm.errors import RobotModelError, excerpt
from dualarm.files import REGULAR_FILE, kind


def _package_candidates(package: str, rest: str, urdf: Path) -> list[Path]:
    """Where ``package://package/rest`` may be.

    Under each ``ROS_PACKAGE_PATH`` entry, then under the URDF's own folders.
    """
    out = []
    for entry in filter(None, os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep)):
        root = Path(entry)
        out += [root / package / rest] + ([root / rest] if root.name == package else [])
    for folder in urdf.resolve().parents:
        out += [folder / rest] if folder.name == package else []
        out.append(folder / package / rest)
    return out


def resolve_mesh(filename: str, urdf: Path) -> Path:
    """The file a URDF's ``<mesh filename>`` names.

    ``package://PKG/path`` (through ``ROS_PACKAGE_PATH``, then the URDF's own folders, each as PKG or holding PKG),
    ``file://``, absolute, or relative to the URDF.

    Raises:
        RobotModelError: no such file (one line naming the URDF and the path).
    """
    if filename.startswith("package://"):
        package, _, rest = filename[len("package://") :].partition("/")
        candidates = _package_candidates(package, rest, urdf)
        where = "in ROS_PACKAGE_PATH nor in the URDF's folders"
    else:
        path = Path(filename[len("file://") :] if filename.startswith("file://") else filename)
        candidates = [path if path.is_absolute() else urdf.parent / path]
        where = "" if path.is_absolute() else "relative to the URDF"
    for candidate in candidates:
        if kind(candidate) == REGULAR_FILE:
            return candidate.resolve()
    raise RobotModelError(f"{excerpt(urdf)}: mesh '{excerpt(filename)}' not found{' ' + where if where else ''}")


def _companions(mesh: Path) -> list[Path]:
    """Files a mesh needs beside it: an .obj's ``mtllib`` files and their texture maps (those that exist)."""
    out = []
    if mesh.suffix.lower() == ".obj":
        for line in mesh.read_text(errors="replace").splitlines():
            if line.startswith("mtllib "):
                mtl = mesh.parent / line.split(maxsplit=1)[1].strip()
                if mtl.is_file():
                    out.append(mtl.resolve())
                    for entry in mtl.read_text(errors="replace").splitlines():
                        parts = entry.split()
                        if parts and parts[0].startswith("map_") and (mtl.parent / parts[-1]).is_file():
                            out.append((mtl.parent / parts[-1]).resolve())
    return out


def copy_urdf(urdf: Path, directory: Path) -> Path:
    """Write ``urdf`` into ``directory`` with every mesh copied under ``directory/meshes/``.

    Relative layout kept, and its path rewritten relative; comments (a licence) are kept. Returns the copy.

    Raises:
        RobotModelError: a mesh that cannot be found (see :func:`resolve_mesh`).
    """
    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    root = ET.fromstring(urdf.read_text(), parser=parser)
    meshes = [(element, resolve_mesh(element.get("filename", ""), urdf)) for element in root.iter("mesh")]
    files = sorted({p for _, p in meshes} | {c for _, p in meshes for c in _companions(p)})
    if files:
        common = Path(os.path.commonpath([p.parent for p in files]))
        for source in files:
            target = directory / "meshes" / source.relative_to(common)
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(source, target)
        for element, source in meshes:
            element.set("filename", (Path("meshes") / source.relative_to(common)).as_posix())
    copy = directory / urdf.name
    copy.write_text('<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n")
    return copy
