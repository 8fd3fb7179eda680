"""Reading a URDF into plain, immutable joint descriptions.

The URDF is parsed by ``urdf_parser_py`` (ROS's urdfdom-py). That parser rejects the ``<capsule>``
collision geometry PyBullet and Rerun understand, and kinematics needs no collision geometry, so
``<collision>`` elements are removed before parsing. So are the ROS extensions no part of dualarm
reads (:data:`IGNORED`: ``<transmission>``, ``<gazebo>``), which makers ship in forms the parser
refuses (the PR2's differential transmissions) or reports line by line on stderr (TALOS's
``<role>`` tags); what the parser still reports of the rest is not printed.
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from urdf_parser_py.urdf import URDF
from urdf_parser_py.xml_reflection import core as xml_reflection

from dualarm.errors import RobotModelError, excerpt
from dualarm.files import listing, read_text

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
        raise RobotModelError(
            f"{excerpt(self.path)}: no joint '{excerpt(name, 40)}' (joints: {listing(j.name for j in self.joints)})"
        )

    def chain(self, base: str, tip: str) -> tuple[JointSpec, ...]:
        """The joints from link ``base`` down to link ``tip``, fixed joints included.

        Raises:
            RobotModelError: a link is unknown, or ``tip`` does not descend from ``base``.
        """
        for link in (base, tip):
            if link not in self.links:
                raise RobotModelError(
                    f"{excerpt(self.path)}: no link '{excerpt(link, 40)}' (links: {listing(self.links)})"
                )
        by_child = {j.child: j for j in self.joints}
        path: list[JointSpec] = []
        link = tip
        while link != base:
            if link not in by_child:
                raise RobotModelError(
                    f"{excerpt(self.path)}: link '{excerpt(tip, 40)}' is not below link '{excerpt(base, 40)}'"
                )
            path.append(by_child[link])
            link = path[-1].parent
        return tuple(reversed(path))

    def subtree(self, link: str) -> frozenset[str]:
        """``link`` and every link below it (what a joint whose child is ``link`` moves)."""
        below, todo = {link}, [link]
        while todo:
            parent = todo.pop()
            children = [j.child for j in self.joints if j.parent == parent]
            below.update(children)
            todo += children
        return frozenset(below)


def _vector3(values, what: str) -> tuple[float, float, float]:
    """Three finite numbers as a tuple of floats; RobotModelError naming ``what`` otherwise."""
    x, y, z = (float(v) for v in values)
    if not all(np.isfinite((x, y, z))):
        raise RobotModelError(f"{what}: expected finite numbers, got [{x:g}, {y:g}, {z:g}]")
    return x, y, z


def _finite(value: float | None, default: float) -> float:
    return default if value is None else float(value)


#: The most links a robot may have (TIAGo dual, the largest public robot tried, has 129), the longest name of a robot,
#: link or joint [characters], and the largest magnitude of an origin's coordinate [m] (a position limit beyond it
#: [rad, m] is read as none).
MAX_LINKS, MAX_NAME, MAX_MAGNITUDE = 1000, 256, 1e6


def _check_tree(where: str, name: str, links: list[str], joints: list[JointSpec]) -> str:
    """The root link of a tree of links PyBullet and dualarm can read; any other robot refused in one line.

    Bounded names and sizes; every link and joint named once; every joint between two declared links, parent not its
    child; every link the child of at most one joint; one root, from which every link is reached (no loop). PyBullet
    crashed (signal 11) on a joint whose parent is its child, on a duplicate joint name and on a 5 MB robot name, and
    a loop made the chain search run forever.
    """
    if len(links) > MAX_LINKS:
        raise RobotModelError(f"{where}: {len(links)} links; dualarm reads robots of at most {MAX_LINKS}")
    for kind, names in (("robot", [name]), ("link", links), ("joint", [j.name for j in joints])):
        long = next((n for n in names if len(n) > MAX_NAME), None)
        if long is not None:
            raise RobotModelError(
                f"{where}: {kind} name '{excerpt(long, 40)}' is {len(long)} characters (<= {MAX_NAME})"
            )
        twice = next((n for n, count in Counter(names).items() if count > 1), None)
        if twice is not None:
            raise RobotModelError(f"{where}: two {kind}s are named '{excerpt(twice, 40)}'")
    declared, parent_of = set(links), dict[str, str]()
    for j in joints:
        joint = f"{where}: joint '{excerpt(j.name, 40)}'"
        for role, link in (("parent", j.parent), ("child", j.child)):
            if link not in declared:
                raise RobotModelError(f"{joint}: its {role} link '{excerpt(link, 40)}' is not declared")
        if j.parent == j.child:
            raise RobotModelError(f"{joint}: its parent and child are the same link '{excerpt(j.child, 40)}'")
        if j.child in parent_of:
            raise RobotModelError(
                f"{joint}: link '{excerpt(j.child, 40)}' is already the child of joint "
                f"'{excerpt(parent_of[j.child], 40)}' (a URDF is a tree: one parent joint per link)"
            )
        parent_of[j.child] = j.name
        big = max(abs(v) for v in j.origin_xyz)
        if big > MAX_MAGNITUDE:
            raise RobotModelError(f"{joint}: an origin coordinate of {big:g} m (<= {MAX_MAGNITUDE:g})")
    roots = [link for link in links if link not in parent_of]
    if len(roots) != 1:
        raise RobotModelError(
            f"{where}: {len(roots)} root links (links no joint moves)"
            + (
                f": {excerpt(', '.join(roots), 80)}; a URDF has one"
                if roots
                else "; a URDF has one (joints form a loop)"
            )
        )
    children: dict[str, list[str]] = {}
    for j in joints:
        children.setdefault(j.parent, []).append(j.child)
    reached, todo = {roots[0]}, [roots[0]]
    while todo:
        for child in children.get(todo.pop(), []):
            reached.add(child)
            todo.append(child)
    if len(reached) != len(links):
        missing = next(link for link in links if link not in reached)
        raise RobotModelError(f"{where}: link '{excerpt(missing, 40)}' is on a loop of joints, not below the root")
    return roots[0]


#: Top-level URDF elements removed before parsing: ROS (2) control's and Gazebo's, which dualarm does not read.
IGNORED = ("transmission", "gazebo", "ros2_control")


@contextmanager
def parser_warnings_silenced() -> Iterator[None]:
    """Drop what ``urdf_parser_py`` prints on stderr (unknown tags and attributes of valid extensions)."""
    printed = xml_reflection.on_error
    xml_reflection.on_error = lambda message: None
    try:
        yield
    finally:
        xml_reflection.on_error = printed


def _parse(path: Path, text: str) -> tuple[URDF, str]:
    """The URDF of ``text`` and its XML without <collision> elements.

    RobotModelError naming ``path`` for anything urdf_parser_py or the XML parser refuse.
    """
    try:
        root = ET.fromstring(text)
        if root.tag != "robot":
            raise RobotModelError(f"{excerpt(path)}: root element is <{excerpt(root.tag, 40)}>, a URDF needs <robot>")
        for link in root.iter("link"):
            for element in link.findall("collision") + link.findall(
                "contact"
            ):  # <contact>: PyBullet's, which urdf_parser_py reports on stderr
                link.remove(element)
        for element in [e for e in root if e.tag in IGNORED]:
            root.remove(element)
        kinematic_xml = ET.tostring(root, encoding="unicode")
    except ET.ParseError as exc:
        raise RobotModelError(f"{excerpt(path)}: not valid XML ({exc})") from None
    except RecursionError:
        raise RobotModelError(f"{excerpt(path)}: not a valid URDF (elements nested too deeply)") from None
    try:
        with parser_warnings_silenced():
            return URDF.from_xml_string(kinematic_xml), kinematic_xml
    except Exception as exc:  # urdf_parser_py raises bare Exception on schema errors
        raise RobotModelError(f"{excerpt(path)}: not a valid URDF: {_where_in(text, str(exc))}") from None


def _where_in(text: str, error: str) -> str:
    """urdf_parser_py's error as ``joint 'j' (line L, column C): why``, when it names an element.

    urdf_parser_py says ``ParseError in /robot[...]/joint[@name='j']:`` and the reason on the next line; the line
    and column are of the element's start tag in ``text``. Otherwise its message, on one line.
    """
    match = re.match(r"ParseError in (\S*?)(\w+)\[@name='([^']*)'\]:\s*(.*)", error, re.DOTALL)
    if match is None:
        return excerpt(error, 200)
    tag, name, why = match.group(2), match.group(3), " ".join(match.group(4).split())
    start = re.search(rf"<{tag}\b[^>]*\bname\s*=\s*[\"']{re.escape(name)}[\"']", text)
    where = ""
    if start is not None:
        line = text.count("\n", 0, start.start()) + 1
        where = f" (line {line}, column {start.start() - text.rfind(chr(10), 0, start.start())})"
    return f"{tag} '{excerpt(name, 40)}'{where}: {excerpt(why, 160)}"


def load_urdf(path: str | Path) -> UrdfModel:
    """Parse a URDF file.

    Every number the kinematics use must be finite: joint origins and axes; position limits may
    be absent (unbounded) but not NaN, and the lower not above the upper.

    Args:
        path: URDF file (a regular file of UTF-8 text).

    Raises:
        RobotModelError: one line naming the file and the cause: it cannot be read (missing, a
            directory, a FIFO, ... see :func:`dualarm.files.read_text`), or is not a valid URDF.
    """
    path = Path(path)
    robot, kinematic_xml = _parse(path, read_text(path, "URDF", RobotModelError))
    where = excerpt(path)

    joints = []
    for j in robot.joints:
        origin = j.origin
        joint = f"{where}: joint '{excerpt(j.name, 40)}'"
        xyz = _vector3(
            origin.xyz if origin is not None and origin.xyz is not None else (0, 0, 0), f"{joint} origin xyz"
        )
        rpy = _vector3(
            origin.rpy if origin is not None and origin.rpy is not None else (0, 0, 0), f"{joint} origin rpy"
        )
        axis = np.asarray(_vector3(j.axis if j.axis is not None else (1.0, 0.0, 0.0), f"{joint} axis"))
        if j.type in MOVABLE_TYPES and not np.isclose(np.linalg.norm(axis), 1.0, atol=1e-9):
            norm = math.hypot(*axis)  # no overflow for huge entries
            if norm == 0 or not math.isfinite(norm):
                raise RobotModelError(f"{joint} has a zero axis")
            axis = axis / norm
        limit = j.limit
        lower = -np.inf if j.type == "continuous" or limit is None else _finite(limit.lower, -np.inf)
        upper = np.inf if j.type == "continuous" or limit is None else _finite(limit.upper, np.inf)
        # Beyond MAX_MAGNITUDE a position limit is the "no limit" of Gazebo's exports (1e16), not a number to use.
        lower, upper = (-np.inf if lower < -MAX_MAGNITUDE else lower), (np.inf if upper > MAX_MAGNITUDE else upper)
        velocity = _finite(limit.velocity if limit is not None else None, np.inf)
        effort = _finite(limit.effort if limit is not None else None, np.inf)
        if np.isnan([lower, upper, velocity, effort]).any():
            raise RobotModelError(f"{joint} has a NaN limit")
        if lower > upper:
            raise RobotModelError(f"{joint} has lower limit {lower:g} above upper limit {upper:g}")
        joints.append(
            JointSpec(
                name=j.name,
                type=j.type,
                parent=j.parent,
                child=j.child,
                origin_xyz=xyz,
                origin_rpy=rpy,
                axis=(float(axis[0]), float(axis[1]), float(axis[2])),
                lower=lower,
                upper=upper,
                velocity=velocity,
                effort=effort,
            )
        )
    return UrdfModel(
        path=path,
        name=str(robot.name),
        root=_check_tree(where, str(robot.name), [link.name for link in robot.links], joints),
        links=tuple(link.name for link in robot.links),
        joints=tuple(joints),
        kinematic_xml=kinematic_xml,
    )


def viewer_urdf(text: str) -> str:
    """The URDF ``text`` as URDF 1.0 viewers read it.

    Each ``<capsule>`` (a PyBullet and Gazebo extension, which Foxglove's URDF parser refuses) as a cylinder and a
    sphere at each end.

    The capsule's axis is the z axis of its ``<origin>``; the three shapes keep its tag (visual or
    collision), its origin's orientation and its material. Everything else is left as it is.
    """
    from dualarm.model.poses import pose_matrix

    root = ET.fromstring(text)
    for link in root.iter("link"):
        for index, element in enumerate(list(link)):
            capsule = element.find("geometry/capsule")
            if capsule is None:
                continue
            radius, length = capsule.get("radius", "0"), float(capsule.get("length", "0"))
            origin = element.find("origin")
            xyz = np.array([float(v) for v in (origin.get("xyz", "0 0 0") if origin is not None else "0 0 0").split()])
            rpy = origin.get("rpy", "0 0 0") if origin is not None else "0 0 0"
            axis = pose_matrix(xyz, [float(v) for v in rpy.split()])[:3, 2]
            link.remove(element)
            shapes = (
                ("cylinder", xyz, {"radius": radius, "length": f"{length:g}"}),
                ("sphere", xyz + axis * length / 2, {"radius": radius}),
                ("sphere", xyz - axis * length / 2, {"radius": radius}),
            )
            for offset, (shape, centre, size) in enumerate(shapes):
                copy = ET.Element(element.tag, element.attrib)
                ET.SubElement(copy, "origin", {"xyz": " ".join(f"{v:.9g}" for v in centre), "rpy": rpy})
                ET.SubElement(ET.SubElement(copy, "geometry"), shape, size)
                copy.extend(child for child in element if child.tag not in ("origin", "geometry"))  # material, ...
                link.insert(index + offset, copy)
    return ET.tostring(root, encoding="unicode")
