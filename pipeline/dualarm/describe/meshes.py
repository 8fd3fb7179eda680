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


def _package_candidates(package: str, rest: str, urdf: Path) -> list[tuple[Path, Path]]:
    """Where ``package://package/rest`` may be, each with its package's folder.

    Under each ``ROS_PACKAGE_PATH`` entry, then under the URDF's own folders.
    """
    out = []
    for entry in filter(None, os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep)):
        root = Path(entry)
        out += [root / package] + ([root] if root.name == package else [])
    for folder in urdf.resolve().parents:
        out += [folder] if folder.name == package else []
        out.append(folder / package)
    return [(base / rest, base) for base in out]


def description_root(urdf: Path) -> Path:
    """The folder a URDF's relative and absolute mesh paths must stay in.

    The nearest folder above it holding a ``package.xml`` (its ROS package), else the URDF's own folder.
    """
    folder = urdf.resolve().parent
    return next((above for above in (folder, *folder.parents) if (above / "package.xml").is_file()), folder)


def _inside(path: Path, root: Path) -> bool:
    """Whether ``path``, its links followed, is in ``root`` (links followed too)."""
    return path.resolve().is_relative_to(root.resolve())


def resolve_mesh(filename: str, urdf: Path) -> tuple[Path, Path]:
    """The file a URDF's ``<mesh filename>`` names, and the folder it and its companions must stay in.

    ``package://PKG/path`` (through ``ROS_PACKAGE_PATH``, then the URDF's own folders, each as PKG or holding PKG;
    ``package:///PKG/path`` the same) must stay in PKG's folder; ``file://``, absolute, or relative to the URDF, in
    :func:`description_root`. Links are followed before that check, so a link out of the folder is refused too.

    Raises:
        RobotModelError: no such file, or one that leaves its folder (one line naming the URDF and the path).
    """
    if filename.startswith("package://"):
        package, _, rest = filename[len("package://") :].lstrip("/").partition("/")
        candidates = _package_candidates(package, rest, urdf) if package else []
        where = "in ROS_PACKAGE_PATH nor in the URDF's folders"
    elif "://" in filename and not filename.startswith("file://"):
        raise RobotModelError(f"{excerpt(urdf)}: mesh '{excerpt(filename)}': only package:// and file:// are read")
    else:
        path = Path(filename[len("file://") :] if filename.startswith("file://") else filename)
        candidates = [(path if path.is_absolute() else urdf.parent / path, description_root(urdf))]
        where = "" if path.is_absolute() else "relative to the URDF"
    for candidate, root in candidates:
        if kind(candidate) == REGULAR_FILE:
            if not _inside(candidate, root):
                raise RobotModelError(
                    f"{excerpt(urdf)}: mesh '{excerpt(filename)}' leads out of {excerpt(root)}: refused (a robot "
                    "directory copies only its description's own files)"
                )
            return candidate.resolve(), root.resolve()
    raise RobotModelError(f"{excerpt(urdf)}: mesh '{excerpt(filename)}' not found{' ' + where if where else ''}")


def _companions(mesh: Path, root: Path, urdf: Path) -> list[Path]:
    """Files a mesh needs beside it: an .obj's ``mtllib`` files and their texture maps (those that exist).

    Raises:
        RobotModelError: one that leads out of ``root`` (the mesh's own folder, :func:`resolve_mesh`).
    """
    out = []

    def inside(path: Path, line: str) -> bool:
        if kind(path) != REGULAR_FILE:
            return False
        if not _inside(path, root):
            raise RobotModelError(
                f"{excerpt(urdf)}: mesh {excerpt(mesh.name)} names '{excerpt(line)}', which leads out of "
                f"{excerpt(root)}: refused (a robot directory copies only its description's own files)"
            )
        return True

    if mesh.suffix.lower() == ".obj":
        for line in mesh.read_text(errors="replace").splitlines():
            if line.startswith("mtllib "):
                mtl = mesh.parent / line.split(maxsplit=1)[1].strip()
                if inside(mtl, line):
                    out.append(mtl.resolve())
                    for entry in mtl.read_text(errors="replace").splitlines():
                        parts = entry.split()
                        if parts and parts[0].startswith("map_") and inside(mtl.parent / parts[-1], entry):
                            out.append((mtl.parent / parts[-1]).resolve())
    return out


def _files(root: ET.Element, urdf: Path) -> tuple[list[tuple[ET.Element, Path]], list[Path]]:
    """Each ``<mesh>`` of ``root`` with its file, and every file to copy (meshes and their companions)."""
    found = [(element, *resolve_mesh(element.get("filename", ""), urdf)) for element in root.iter("mesh")]
    companions = {c for _, path, folder in found for c in _companions(path, folder, urdf)}
    return [(element, path) for element, path, _ in found], sorted({path for _, path, _ in found} | companions)


def check_meshes(urdf: Path) -> None:
    """Refuse, before anything is written, a mesh or material file :func:`copy_urdf` would refuse."""
    _files(ET.fromstring(urdf.read_text()), urdf)


def copy_urdf(urdf: Path, directory: Path) -> Path:
    """Write ``urdf`` into ``directory`` with every mesh copied under ``directory/meshes/``.

    Relative layout kept, and its path rewritten relative; comments (a licence) are kept. Returns the copy.

    Raises:
        RobotModelError: a mesh that cannot be found, or a mesh or material file that leads out of its description's
            folder (see :func:`resolve_mesh`).
    """
    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    root = ET.fromstring(urdf.read_text(), parser=parser)
    meshes, files = _files(root, urdf)
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
