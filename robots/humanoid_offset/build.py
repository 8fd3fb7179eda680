"""Build robots/humanoid_offset: the shipped humanoid with a shoulder offset and an elbow offset.

So its arms are 7R but not S-R-S.

Real humanoid arms rarely meet S-R-S exactly: their shoulder and elbow carry offsets of a few
centimetres. This robot is the humanoid (``robots/humanoid``) with two of them on each arm:

- shoulder: the shoulder pitch and upper-arm roll axes still meet, at a point
  :data:`SHOULDER_OFFSET_M` in front of the shoulder yaw axis (which they no longer meet);
- elbow: the elbow axis sits :data:`ELBOW_OFFSET_M` behind the upper arm's axis (as a human's
  elbow), and the forearm comes back by as much, so the forearm roll axis is again in line at
  q = 0 (as the Franka Panda's elbow). The forearm's shapes move with it. Behind rather than in
  front: with the axis in front, the forearm folding forward keeps the hand further from the
  shoulder, and on the shipped circle none of 48 held SEW angles kept the elbow inside its range
  (TRAC-IK, DLS-SVD and PyBullet IK were all violated there too).

The wrist stays spherical, so each arm is of the SEW solver's R-2R-R-3R family
(:mod:`dualarm.ik.analytic.sew`). Everything else (limits, masses, shapes, robot.toml's chains, limits and
home poses) is the humanoid's. Run from anywhere: ``python robots/humanoid_offset/build.py``.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path

HERE = Path(__file__).resolve().parent
HUMANOID = HERE.parent / "humanoid"
#: How far in front (+x) of the shoulder yaw axis the shoulder pitch and upper-arm roll axes meet [m].
SHOULDER_OFFSET_M = 0.04
#: How far behind (-x) the upper arm's axis the elbow axis runs [m].
ELBOW_OFFSET_M = 0.03
HEADER = (
    "dualarm humanoid with offsets, built by robots/humanoid_offset/build.py from robots/humanoid/humanoid.urdf\n"
    "     (do not edit: rebuild). The humanoid's arms with the shoulder pitch and upper-arm roll axes meeting\n"
    f"     {SHOULDER_OFFSET_M} m in front of the shoulder yaw axis, and the elbow axis {ELBOW_OFFSET_M} m behind the"
    " upper arm's axis\n"
    "     (the forearm coming back as much). Not S-R-S: 7R arms of the R-2R-R-3R family. "
)


def _shift(element: ET.Element, dx: float) -> None:
    x, y, z = (float(v) for v in element.attrib["xyz"].split())
    element.attrib["xyz"] = f"{x + dx:g} {y:g} {z:g}"


def build_urdf() -> str:
    """The offset humanoid's URDF text."""
    robot = ET.parse(HUMANOID / "humanoid.urdf", ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))).getroot()
    robot.attrib["name"] = "humanoid_offset"
    joints = {j.attrib["name"]: j for j in robot.iter("joint")}
    links = {link.attrib["name"]: link for link in robot.iter("link")}
    for side in ("left", "right"):
        _shift(joints[f"{side}_shoulder_pitch"].find("origin"), SHOULDER_OFFSET_M)
        _shift(joints[f"{side}_elbow"].find("origin"), -ELBOW_OFFSET_M)
        _shift(joints[f"{side}_forearm_roll"].find("origin"), ELBOW_OFFSET_M)
        for origin in links[f"{side}_forearm"].iter("origin"):  # the forearm's shapes stay on the forearm roll axis
            _shift(origin, ELBOW_OFFSET_M)
    return f'<?xml version="1.0"?>\n<!-- {HEADER}-->\n{ET.tostring(robot, encoding="unicode")}\n'


def build_toml() -> str:
    """The humanoid's robot.toml with this robot's name, URDF and description."""
    text = (HUMANOID / "robot.toml").read_text()
    text = text.replace('name = "humanoid"', 'name = "humanoid_offset"').replace(
        'urdf = "humanoid.urdf"', 'urdf = "humanoid_offset.urdf"'
    )
    description = (
        f"The dualarm humanoid with a {SHOULDER_OFFSET_M * 100:g} cm shoulder offset (the shoulder pitch and"
        " upper-arm roll axes meet\n"
        f"in front of the shoulder yaw axis) and a {ELBOW_OFFSET_M * 100:g} cm elbow offset on each arm: 7R arms"
        " that are not S-R-S\n"
        "(the SEW solver's R-2R-R-3R family). Built by build.py; everything else is the humanoid's."
    )
    text = re.sub(r'description = """.*?"""', f'description = """\n{description}"""', text, count=1, flags=re.S)
    return "# Built by robots/humanoid_offset/build.py from robots/humanoid/robot.toml: do not edit, rebuild.\n" + text


def main() -> None:
    """Write humanoid_offset.urdf and robot.toml here."""
    (HERE / "humanoid_offset.urdf").write_text(build_urdf())
    (HERE / "robot.toml").write_text(build_toml())


if __name__ == "__main__":
    main()
