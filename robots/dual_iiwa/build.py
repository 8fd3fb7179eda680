"""Build robots/dual_iiwa: two KUKA LBR iiwa 14 R820 arms on a fixed torso, described by ``dualarm robot init``.

The arms are pybullet_data's kuka_iiwa/model.urdf. The assembled URDF: ``base_link`` on the floor (x
forward, y left, z up) holding a pedestal, ``torso`` fixed 1.40 m above it (a 0.20 m wide box
hanging 0.50 m below), and one iiwa on each side of the torso at that height, its base's z axis
pointing out sideways (+y left, -y right) and its x axis forward. So each arm's first joint turns
about the lateral axis, like a shoulder's pitch, and at the zero pose the arms stretch out sideways
(a T pose) with the shoulder centres S 0.46 m out. Every iiwa link and joint is copied from
pybullet_data (inertias, origins, axes, position limits, and the licence comment), renamed ``left_...`` /
``right_...``, but for the velocity limits: KUKA's data sheet's (:data:`DATASHEET_VELOCITY_DEG_S`) replace
pybullet_data's 10 rad/s, so that ``robot init`` scales its assumed acceleration and jerk limits from the
arm's real speeds; visuals and collisions use the STL meshes (the OBJ visuals would double the size for
a colour the URDF's materials give), referenced as ``package://kuka_iiwa/meshes/...`` and found
through ``ROS_PACKAGE_PATH`` = pybullet_data's folder.

Then ``dualarm robot init`` writes the robot directory (URDF copy with relative mesh paths, the
meshes, robot.toml) into a temporary folder, and its outputs replace dual_iiwa.urdf, robot.toml and
meshes/ here. Run from anywhere: ``python robots/dual_iiwa/build.py``.
"""

from __future__ import annotations

import copy
import os
import shutil
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

import pybullet_data

HERE = Path(__file__).resolve().parent
IIWA = Path(pybullet_data.getDataPath()) / "kuka_iiwa" / "model.urdf"
#: Height of the torso frame (the arms' mounts and shoulders) above the floor [m].
SHOULDER_HEIGHT_M = 1.40
#: Half the torso's width: each arm's base sits this far left / right of the middle [m].
MOUNT_Y_M = 0.10
#: rpy of each arm's base in the torso frame [rad]: z out sideways, x forward.
MOUNT_RPY = {"left": "-1.5707963267948966 0 0", "right": "1.5707963267948966 0 0"}
#: Outputs of the build (replaced on every run).
OUTPUTS = ("dual_iiwa.urdf", "robot.toml", "meshes")
#: KUKA's data sheet for the LBR iiwa 14 R820: largest speed per axis A1..A7 [deg/s], as lbr-stack/lbr_fri_ros2_stack's
#: lbr_description/urdf/iiwa14/joint_limits.yaml also gives them; pybullet_data's URDF says 10 rad/s for all.
DATASHEET_VELOCITY_DEG_S = (85, 85, 100, 75, 130, 135, 135)


def _box(parent: ET.Element, tag: str, size: str, xyz: str, material: str | None = None) -> None:
    element = ET.SubElement(parent, tag)
    ET.SubElement(element, "origin", {"xyz": xyz, "rpy": "0 0 0"})
    ET.SubElement(ET.SubElement(element, "geometry"), "box", {"size": size})
    if material:
        ET.SubElement(element, "material", {"name": material})


def _body(robot: ET.Element) -> None:
    """base_link with its pedestal, and the torso fixed above it."""
    ET.SubElement(ET.SubElement(robot, "material", {"name": "Torso"}), "color", {"rgba": "0.7 0.7 0.75 1.0"})
    base = ET.SubElement(robot, "link", {"name": "base_link"})
    torso_bottom = SHOULDER_HEIGHT_M - 0.5
    for tag in ("visual", "collision"):
        _box(
            base, tag, f"0.16 0.16 {torso_bottom:g}", f"0 0 {torso_bottom / 2:g}", "Torso" if tag == "visual" else None
        )
    _inertial(base, 10.0)
    joint = ET.SubElement(robot, "joint", {"name": "base_to_torso", "type": "fixed"})
    ET.SubElement(joint, "parent", {"link": "base_link"})
    ET.SubElement(joint, "child", {"link": "torso"})
    ET.SubElement(joint, "origin", {"xyz": f"0 0 {SHOULDER_HEIGHT_M:g}", "rpy": "0 0 0"})
    torso = ET.SubElement(robot, "link", {"name": "torso"})
    for tag in ("visual", "collision"):
        _box(torso, tag, f"0.20 {2 * MOUNT_Y_M:g} 0.50", "0 0 -0.25", "Torso" if tag == "visual" else None)
    _inertial(torso, 10.0)


def _inertial(link: ET.Element, mass_kg: float) -> None:
    inertial = ET.SubElement(link, "inertial")
    ET.SubElement(inertial, "origin", {"xyz": "0 0 0", "rpy": "0 0 0"})
    ET.SubElement(inertial, "mass", {"value": f"{mass_kg:g}"})
    ET.SubElement(inertial, "inertia", {"ixx": "0.1", "ixy": "0", "ixz": "0", "iyy": "0.1", "iyz": "0", "izz": "0.1"})


def _arm(robot: ET.Element, iiwa: ET.Element, side: str) -> None:
    """One iiwa, its links and joints renamed ``side_...``, mounted on the torso."""
    mount = ET.SubElement(robot, "joint", {"name": f"{side}_mount", "type": "fixed"})
    ET.SubElement(mount, "parent", {"link": "torso"})
    ET.SubElement(mount, "child", {"link": f"{side}_lbr_iiwa_link_0"})
    ET.SubElement(
        mount, "origin", {"xyz": f"0 {MOUNT_Y_M if side == 'left' else -MOUNT_Y_M:g} 0", "rpy": MOUNT_RPY[side]}
    )
    for element in iiwa:
        if element.tag not in ("link", "joint"):
            continue
        element = copy.deepcopy(element)
        element.set("name", f"{side}_{element.get('name')}")
        for ref in (*element.findall("parent"), *element.findall("child")):
            ref.set("link", f"{side}_{ref.get('link')}")
        for mesh in element.iter("mesh"):
            mesh.set("filename", "package://kuka_iiwa/" + mesh.get("filename", "").replace(".obj", ".stl"))
        limit = element.find("limit")
        if element.tag == "joint" and limit is not None:
            axis = int(element.get("name", "").rsplit("_", 1)[1])
            limit.set("velocity", f"{DATASHEET_VELOCITY_DEG_S[axis - 1] * 3.141592653589793 / 180:.4f}")
        robot.append(element)


def assemble() -> str:
    """The dual-arm URDF's text (pybullet_data's licence comment kept)."""
    iiwa = ET.parse(IIWA).getroot()
    robot = ET.Element("robot", {"name": "dual_iiwa"})
    for material in iiwa.findall("material"):
        robot.append(copy.deepcopy(material))
    _body(robot)
    for side in ("left", "right"):
        _arm(robot, iiwa, side)
    ET.indent(robot)
    header = IIWA.read_text().split("<robot", 1)[0].replace('<?xml version="1.0" ?>', "").strip()
    note = (
        "<!-- dual_iiwa: two copies of pybullet_data's kuka_iiwa/model.urdf on a torso, assembled by"
        " robots/dual_iiwa/build.py; the iiwa's header and licence follow. -->"
    )
    return '<?xml version="1.0"?>\n' + note + "\n" + header + "\n" + ET.tostring(robot, encoding="unicode") + "\n"


def main() -> None:
    """Assemble the URDF, run ``dualarm robot init`` on it, and put its outputs here."""
    with tempfile.TemporaryDirectory() as tmp:
        source = Path(tmp) / "src" / "dual_iiwa.urdf"
        source.parent.mkdir()
        source.write_text(assemble())
        out = Path(tmp) / "dual_iiwa"
        env = {**os.environ, "ROS_PACKAGE_PATH": pybullet_data.getDataPath()}
        dualarm = Path(sys.executable).parent / "dualarm"
        subprocess.run([str(dualarm), "robot", "init", str(source), "--out", str(out)], env=env, check=True)
        for name in OUTPUTS:
            target = HERE / name
            if target.is_dir():
                shutil.rmtree(target)
            elif target.exists():
                target.unlink()
            shutil.move(str(out / name), str(target))
    print(f"wrote {', '.join(str(HERE / n) for n in OUTPUTS)}")


if __name__ == "__main__":
    main()
