"""Which way a URDF's root frame points: dualarm takes it as x forward, y left, z up (REP 103).

A description whose root frame is y-up (as some exporters write them) would have every task's forward and up
wrong without a word. ``robot init`` looks at where a two-armed robot's shoulders are at the zero pose
(:func:`looks_turned`): above the root's origin along a horizontal axis, or apart from each other along x or z,
the root frame is not z-up and y-left, and init refuses in one line naming the axis that points up. With
``--up AXIS`` it turns the copy of the URDF (:func:`turn_root`): a new root link :data:`TURNED_ROOT`, z up and y
towards the left arm, holds the old root by a fixed joint, and every pose of a task is in it.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from dualarm.errors import RobotModelError

#: The axes ``--up`` names, as unit vectors of the URDF's root frame.
AXES = {
    "x": (1.0, 0.0, 0.0),
    "-x": (-1.0, 0.0, 0.0),
    "y": (0.0, 1.0, 0.0),
    "-y": (0.0, -1.0, 0.0),
    "z": (0.0, 0.0, 1.0),
    "-z": (0.0, 0.0, -1.0),
}
#: The root link ``--up`` adds, and the fixed joint holding the URDF's own root.
TURNED_ROOT = "dualarm_base"
TURNED_JOINT = "dualarm_base_joint"
#: The shoulders' midpoint must be this far from the root's origin [m] for its direction to count, and within
#: this angle of an axis [rad].
SHOULDERS_OFF_M = 0.05
ALONG_RAD = np.radians(30.0)


def nearest_axis(v: np.ndarray) -> tuple[str, float]:
    """The axis of :data:`AXES` nearest the direction of ``v`` (3,), and the angle between them [rad]."""
    u = np.asarray(v, dtype=float) / np.linalg.norm(v)
    name = max(AXES, key=lambda a: float(np.dot(AXES[a], u)))
    return name, float(np.arccos(np.clip(np.dot(AXES[name], u), -1.0, 1.0)))


def looks_turned(left_shoulder: np.ndarray, right_shoulder: np.ndarray) -> str | None:
    """Why a root frame is not z-up and y-left, from the shoulders at the zero pose [m]; None if it is.

    Not z-up: the shoulders' midpoint lies along a horizontal axis of the root (more than
    :data:`SHOULDERS_OFF_M` away, within :data:`ALONG_RAD` of the axis), or the arms lie apart along x or z (a
    robot stands with its arms apart along y). A midpoint straight below the root is allowed (a robot hung
    from the ceiling).
    """
    middle, apart = (left_shoulder + right_shoulder) / 2, left_shoulder - right_shoulder
    if np.linalg.norm(middle) > SHOULDERS_OFF_M:
        axis, angle = nearest_axis(middle)
        if axis not in ("z", "-z") and angle < ALONG_RAD:
            return f"the shoulders are {np.linalg.norm(middle):.3g} m along {axis} of it; give --up {axis}"
    if np.linalg.norm(apart) > 0 and nearest_axis(apart)[0] not in ("y", "-y"):
        axis = nearest_axis(apart)[0].lstrip("-")
        return f"the arms lie apart along {axis}, not y; give --up AXIS, the axis of the root that points up"
    return None


def turning(up: str, left_shoulder: np.ndarray | None, right_shoulder: np.ndarray | None) -> np.ndarray:
    """The rotation (3, 3) from the URDF's root frame to the turned one: ``up`` to z, the left arm to +y.

    With one arm, y is the root's axis nearest y that is not along ``up``.

    Raises:
        RobotModelError: ``up`` is not an axis name, or the arms lie apart along it.
    """
    if up not in AXES:
        raise RobotModelError(f"--up {up!r}: not an axis (one of {', '.join(AXES)})")
    z = np.array(AXES[up])
    if left_shoulder is not None and right_shoulder is not None:
        y = left_shoulder - right_shoulder
    else:
        y = next(np.array(AXES[a]) for a in ("y", "z", "x") if abs(np.dot(AXES[a], z)) < 0.5)
    y = y - np.dot(y, z) * z
    if np.linalg.norm(y) < 1e-6:
        raise RobotModelError(f"--up {up}: the arms lie apart along that axis; give the axis that points up")
    y /= np.linalg.norm(y)
    return np.stack([np.cross(y, z), y, z])


def turn_root(copy: Path, root: str, R: np.ndarray) -> None:
    """Rewrite the URDF ``copy``: a new root link :data:`TURNED_ROOT` holds ``root``, turned by ``R``."""
    text = copy.read_text()
    if f'name="{TURNED_ROOT}"' in text:
        raise RobotModelError(f"{copy}: already has a link '{TURNED_ROOT}'")
    rpy = " ".join(f"{a:.17g}" for a in Rotation.from_matrix(R).as_euler("xyz"))
    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    tree = ET.fromstring(text, parser=parser)
    link = ET.Element("link", {"name": TURNED_ROOT})
    joint = ET.Element("joint", {"name": TURNED_JOINT, "type": "fixed"})
    ET.SubElement(joint, "parent", {"link": TURNED_ROOT})
    ET.SubElement(joint, "child", {"link": root})
    ET.SubElement(joint, "origin", {"xyz": "0 0 0", "rpy": rpy})
    tree.insert(0, joint)
    tree.insert(0, link)
    copy.write_text('<?xml version="1.0"?>\n' + ET.tostring(tree, encoding="unicode") + "\n")
