"""Concave collision meshes cut into convex parts, so that PyBullet collides the shapes the maker drew.

PyBullet collides a moving link's mesh as the mesh's convex hull. A concave link (a PR2 upper arm, the clevis
that holds its elbow) is then far larger than drawn: PyBullet finds the PR2's forearm 10.5 mm inside its upper
arm while the ball game flexes the elbow, where the two meshes are 11.5 mm apart (FCL, on the triangles, as
MoveIt checks them). Every check here (the planners' and the IK searches' checkers, the execute stage's
preflight, the simulation's contacts) would refuse motions the robot makes.

:func:`convex_collisions` gives each ``<collision>`` mesh of a robot directory's URDF that is not convex an
approximate convex decomposition by CoACD (Wei et al., SIGGRAPH 2022: collision-aware concavity; the ``coacd``
package): an OBJ of convex parts, one object each, which PyBullet loads as one compound shape. It is written
under ``meshes/convex/`` and the ``<collision>`` points to it; the ``<visual>`` meshes are untouched. A mesh
that is convex already (closed, and its hull's volume within :data:`CONVEX_RATIO` of its own) is kept. Meshes
are read by trimesh (STL, OBJ, and COLLADA through pycollada). A decomposition is kept between robot inits
under the cache directory (:func:`~dualarm.numerics.compiled.cache_dir`), named by the SHA-256 of the mesh
file, :data:`COACD_OPTIONS` and CoACD's version; CoACD with a fixed seed gives the same parts bit for bit.

Why CoACD and not V-HACD (``pybullet.vhacd``): on the PR2's elbow, flexed to its limit, V-HACD's parts of the
forearm and the upper arm still overlap by up to 5.1 mm (at its defaults, and with 10 times the voxels or a fifth
of the concavity), where the meshes are 11 mm apart (FCL); CoACD's, none.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import xml.etree.ElementTree as ET
from collections.abc import Callable
from importlib.metadata import version
from pathlib import Path

from dualarm.errors import RobotModelError, excerpt
from dualarm.numerics.compiled import cache_dir
from dualarm.quiet import c_output_silenced

#: A closed mesh whose convex hull's volume is at most this times its own is taken as convex, and kept.
CONVEX_RATIO = 1.02
#: ``coacd.run_coacd``'s options: its default concavity threshold (0.05) and seed; a shallower tree search than
#: its default (60 iterations of depth 2, not 150 of 3): on the PR2's forearm and upper arm, as many parts, none
#: overlapping at the flexed elbow, in 40 % of the time. Not ``decimate``: on an iiwa link (not closed, so remeshed
#: first) its 64-vertex parts left mesh vertices 7 mm outside every part; without it, none.
COACD_OPTIONS: dict[str, float] = {
    "threshold": 0.05,
    "seed": 0,
    "mcts_iterations": 60,
    "mcts_max_depth": 2,
}
#: Where the parts are written in a robot directory, under ``meshes/``.
CONVEX_DIR = "convex"


def convex_collisions(urdf: Path, progress: Callable[[str], None] | None = None) -> tuple[int, int]:
    """Point the ``<collision>`` meshes of ``urdf`` (a robot directory's copy) to their convex parts.

    Meshes relative to the URDF, as :func:`~dualarm.describe.meshes.copy_urdf` writes them. Rewrites ``urdf`` in
    place (its comments kept). Returns how many distinct collision meshes were decomposed and how many were kept
    as convex. ``progress`` is told each mesh before it is read (``collision mesh K/N: FILE``).

    Raises:
        RobotModelError: a collision mesh that trimesh cannot read (one line naming it).
    """
    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    root = ET.fromstring(urdf.read_text(), parser=parser)
    elements = [mesh for collision in root.iter("collision") for mesh in collision.iter("mesh")]
    filenames = list(dict.fromkeys(element.get("filename", "") for element in elements))
    done: dict[str, str] = {}
    for k, filename in enumerate(filenames):
        if progress is not None:
            progress(f"collision mesh {k + 1}/{len(filenames)}: {filename}")
        done[filename] = _convex(urdf.parent, filename)
    for element in elements:
        element.set("filename", done[element.get("filename", "")])
    urdf.write_text('<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n")
    decomposed = sum(1 for old, new in done.items() if new != old)
    return decomposed, len(done) - decomposed


def _convex(directory: Path, filename: str) -> str:
    """The file (under ``directory``) of mesh ``filename``'s convex parts; ``filename`` if it is convex."""
    import trimesh

    path = directory / filename
    try:
        mesh = trimesh.load_mesh(path)
        if isinstance(mesh, trimesh.Scene):  # a COLLADA of several meshes: one, placed as its scene places them
            mesh = mesh.to_mesh()
        volume = float(mesh.volume) if mesh.is_watertight else None
        hull = float(mesh.convex_hull.volume)
    except Exception as exc:  # trimesh raises many kinds for a file it cannot read
        raise RobotModelError(
            f"collision mesh '{excerpt(filename)}' cannot be read: {excerpt(str(exc), 120)}"
        ) from None
    if volume is not None and volume > 0 and hull <= CONVEX_RATIO * volume:
        return filename
    options = ",".join(f"{k}={v!r}" for k, v in sorted(COACD_OPTIONS.items())) + f",coacd={version('coacd')},obj=6f"
    key = hashlib.sha256(path.read_bytes() + options.encode()).hexdigest()
    cached = cache_dir() / "convex" / f"{key}.obj"
    if not cached.exists():
        _decompose(mesh, cached, filename)
    meshes = directory / "meshes"
    relative = path.relative_to(meshes) if path.is_relative_to(meshes) else Path(path.name)
    target = meshes / CONVEX_DIR / relative.with_suffix(".obj")
    target.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(cached, target)
    return target.relative_to(directory).as_posix()


def _decompose(mesh, out: Path, filename: str) -> None:
    """CoACD's convex parts of the trimesh ``mesh`` (from ``filename``) into OBJ ``out``, an object each.

    Written beside ``out``, then renamed into place: a cache entry is whole or absent.
    """
    import coacd

    coacd.set_log_level("error")
    with c_output_silenced():
        parts = coacd.run_coacd(coacd.Mesh(mesh.vertices, mesh.faces), **COACD_OPTIONS)
    if not parts:
        raise RobotModelError(f"collision mesh '{excerpt(filename)}': CoACD gave no convex parts")
    lines, offset = [], 1
    for k, (vertices, faces) in enumerate(parts):
        lines.append(f"o part{k}")
        lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices.tolist()]  # to 1e-6 of its unit (1 µm in metres)
        lines += [f"f {a + offset} {b + offset} {c + offset}" for a, b, c in faces.tolist()]
        offset += len(vertices)
    out.parent.mkdir(parents=True, exist_ok=True)
    staged = out.with_name(f"{out.name}.{os.getpid()}.tmp")
    staged.write_text("\n".join(lines) + "\n")
    os.replace(staged, out)
