"""Reading a URDF into plain, immutable joint descriptions.

The URDF is parsed by ``urdf_parser_py`` (ROS's urdfdom-py). That parser rejects the ``<capsule>``
collision geometry PyBullet and Rerun understand, and kinematics needs no collision geometry, so
``<collision>`` elements are removed before parsing.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from urdf_parser_py.urdf import URDF

from dualarm.errors import RobotModelError

MOVABLE_TYPES = ("revolute", "continuous", "prismatic")


@dataclass(frozen=True)
class JointSpec:
    """One URDF joint.

    Attributes:
        name: joint name.
        type: URDF joint type (``revolute``, ``continuous``, ``prismatic`` or ``fixed``).
        parent: parent link name.
        child: child link name.
        origin_xyz: translation of the joint frame in the parent link frame [m], shape (3,).
        origin_rpy: fixed-axis roll, pitch, yaw of the joint frame in the parent frame [rad], (3,).
        axis: unit joint axis in the joint frame, shape (3,).
        lower: lower position limit [rad or m] (-inf where the URDF gives none).
        upper: upper position limit [rad or m] (+inf where the URDF gives none).
        velocity: velocity limit [rad/s or m/s] (inf where the URDF gives none).
        effort: effort limit [N m or N] (inf where the URDF gives none).
    """

    name: str
    type: str
    parent: str
    child: str
    origin_xyz: tuple[float, float, float]
    origin_rpy: tuple[float, float, float]
    axis: tuple[float, float, float]
    lower: float
    upper: float
    velocity: float
    effort: float

    @property
    def movable(self) -> bool:
        """True for joints with a degree of freedom."""
        return self.type in MOVABLE_TYPES


@dataclass(frozen=True)
class UrdfModel:
    """A parsed URDF.

    Attributes:
        path: the file it was read from.
        name: the robot name.
        root: the root link (the link with no parent).
        links: every link name.
        joints: every joint, in file order.
        kinematic_xml: the URDF text without its <collision> elements (what urdf_parser_py and
            adam-robotics can read).
    """

    path: Path
    name: str
    root: str
    links: tuple[str, ...]
    joints: tuple[JointSpec, ...]
    kinematic_xml: str

    def joint(self, name: str) -> JointSpec:
        """The joint called ``name``; RobotModelError listing the joints if there is none."""
        for j in self.joints:
            if j.name == name:
                return j
        raise RobotModelError(f"{self.path}: no joint '{name}' (joints: {', '.join(j.name for j in self.joints)})")

    def chain(self, base: str, tip: str) -> tuple[JointSpec, ...]:
        """The joints from link ``base`` down to link ``tip``, fixed joints included.

        Raises:
            RobotModelError: a link is unknown, or ``tip`` does not descend from ``base``.
        """
        for link in (base, tip):
            if link not in self.links:
                raise RobotModelError(f"{self.path}: no link '{link}' (links: {', '.join(self.links)})")
        by_child = {j.child: j for j in self.joints}
        path: list[JointSpec] = []
        link = tip
        while link != base:
            if link not in by_child:
                raise RobotModelError(f"{self.path}: link '{tip}' is not below link '{base}'")
            path.append(by_child[link])
            link = path[-1].parent
        return tuple(reversed(path))


def _vector3(values) -> tuple[float, float, float]:
    """Three numbers as a tuple of floats."""
    x, y, z = (float(v) for v in values)
    return x, y, z


def _finite(value: float | None, default: float) -> float:
    return default if value is None else float(value)


def load_urdf(path: str | Path) -> UrdfModel:
    """Parse a URDF file.

    Args:
        path: URDF file.

    Raises:
        RobotModelError: the file is missing or is not a valid URDF.
    """
    path = Path(path)
    try:
        tree = ET.parse(path)
    except FileNotFoundError:
        raise RobotModelError(f"{path}: URDF file not found") from None
    except ET.ParseError as exc:
        raise RobotModelError(f"{path}: not valid XML ({exc})") from None
    root = tree.getroot()
    if root.tag != "robot":
        raise RobotModelError(f"{path}: root element is <{root.tag}>, a URDF needs <robot>")
    for link in root.iter("link"):
        for collision in link.findall("collision"):
            link.remove(collision)
    kinematic_xml = ET.tostring(root, encoding="unicode")
    try:
        robot = URDF.from_xml_string(kinematic_xml)
    except Exception as exc:  # urdf_parser_py raises bare Exception on schema errors
        raise RobotModelError(f"{path}: not a valid URDF ({exc})") from None

    joints = []
    for j in robot.joints:
        origin = j.origin
        xyz = _vector3(origin.xyz if origin is not None and origin.xyz is not None else (0, 0, 0))
        rpy = _vector3(origin.rpy if origin is not None and origin.rpy is not None else (0, 0, 0))
        axis = np.asarray(j.axis if j.axis is not None else (1.0, 0.0, 0.0), dtype=float)
        if j.type in MOVABLE_TYPES and not np.isclose(np.linalg.norm(axis), 1.0, atol=1e-9):
            norm = np.linalg.norm(axis)
            if norm == 0:
                raise RobotModelError(f"{path}: joint '{j.name}' has a zero axis")
            axis = axis / norm
        limit = j.limit
        lower = -np.inf if j.type == "continuous" or limit is None else _finite(limit.lower, -np.inf)
        upper = np.inf if j.type == "continuous" or limit is None else _finite(limit.upper, np.inf)
        if lower > upper:
            raise RobotModelError(f"{path}: joint '{j.name}' has lower limit {lower} above upper limit {upper}")
        joints.append(
            JointSpec(
                name=j.name,
                type=j.type,
                parent=j.parent,
                child=j.child,
                origin_xyz=xyz,
                origin_rpy=rpy,
                axis=_vector3(axis),
                lower=lower,
                upper=upper,
                velocity=_finite(limit.velocity if limit is not None else None, np.inf),
                effort=_finite(limit.effort if limit is not None else None, np.inf),
            )
        )
    return UrdfModel(
        path=path,
        name=robot.name,
        root=robot.get_root(),
        links=tuple(link.name for link in robot.links),
        joints=tuple(joints),
        kinematic_xml=kinematic_xml,
    )
