"""URDFs as their makers ship them carry ROS extensions dualarm does not read: ``<transmission>`` (ROS
control) and ``<gazebo>``. They are dropped before ``urdf_parser_py`` parses the file, so a form it refuses
(the PR2's ``WristTransmission``, from example-robot-data 6.0.0) does not refuse the robot, and nothing of
theirs is printed (TALOS's ``<role>`` tags, 96 lines per command before). The joints are read as PyBullet
reads them."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import pytest

from dualarm.errors import RobotModelError
from dualarm.model.urdf import load_urdf

ARM = """<robot name="arm">
  <link name="base"/>
  <link name="upper"/>
  <link name="lower"/>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="upper"/><axis xyz="0 0 1"/>
    <limit lower="-1.5" upper="1.5" effort="10" velocity="2"/>
  </joint>
  <joint name="elbow" type="revolute">
    <parent link="upper"/><child link="lower"/><origin xyz="0 0 0.3"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="10" velocity="3"/>
  </joint>
  {extensions}
</robot>
"""
#: The PR2's wrist transmission (pr2_description/urdf/pr2.urdf), which urdf_parser_py 0.0.4 refuses.
PR2_WRIST = """<transmission name="wrist_trans" type="WristTransmission">
    <rightActuator mechanicalReduction="60.17" name="r_motor"/>
    <leftActuator mechanicalReduction="60.17" name="l_motor"/>
    <flexJoint mechanicalReduction="-1.0" name="shoulder"/>
    <rollJoint mechanicalReduction="1.0" name="elbow"/>
  </transmission>"""
#: TALOS's differential transmission (talos_data/robots/talos_reduced.urdf): its <role> tags were printed.
TALOS_DIFFERENTIAL = """<transmission name="torso_trans">
    <type>transmission_interface/DifferentialTransmission</type>
    <actuator name="m1"><role>actuator1</role><mechanicalReduction>1.0</mechanicalReduction></actuator>
    <actuator name="m2"><role>actuator2</role><mechanicalReduction>1.0</mechanicalReduction></actuator>
    <joint name="shoulder"><role>joint1</role><offset>0.0</offset></joint>
    <joint name="elbow"><role>joint2</role><offset>0.0</offset></joint>
  </transmission>
  <gazebo reference="upper"><material>Gazebo/Grey</material></gazebo>"""


@pytest.mark.parametrize("extensions", [PR2_WRIST, TALOS_DIFFERENTIAL], ids=["pr2-wrist", "talos-differential"])
def test_ros_extensions_neither_refuse_the_robot_nor_print(tmp_path, capfd, extensions):
    path = tmp_path / "arm.urdf"
    path.write_text(ARM.format(extensions=extensions))
    model = load_urdf(path)
    printed = capfd.readouterr()
    assert printed.out == "" and printed.err == ""
    # the joints as the file states them, read with the standard library's parser
    stated = ET.fromstring(path.read_text()).findall("joint")
    assert [j.name for j in model.joints] == [j.get("name") for j in stated]
    for joint, element in zip(model.joints, stated, strict=True):
        limit = element.find("limit")
        assert (joint.lower, joint.upper) == (float(limit.get("lower")), float(limit.get("upper")))
    assert "transmission" not in model.kinematic_xml and "gazebo" not in model.kinematic_xml


def test_a_broken_joint_is_still_refused_in_one_line(tmp_path):
    path = tmp_path / "arm.urdf"
    path.write_text(ARM.format(extensions=PR2_WRIST).replace('<parent link="upper"/>', ""))
    with pytest.raises(RobotModelError, match="not a valid URDF"):
        load_urdf(path)


def test_a_schema_error_is_one_line_naming_the_element_its_line_and_column(tmp_path):
    """urdf_parser_py's two-line 'ParseError in /robot/joint[@name=...]:' becomes one line with the start tag's line and
    column, found here in the text independently (the PR2's error printed a literal backslash-n)."""
    text = ARM.format(extensions="").replace('type="revolute"', 'type="spinning"', 1)
    path = tmp_path / "arm.urdf"
    path.write_text(text)
    with pytest.raises(RobotModelError) as info:
        load_urdf(path)
    message = str(info.value)
    lines = text.splitlines()
    row = next(i for i, line in enumerate(lines) if 'type="spinning"' in line)
    name = ET.fromstring(text).find("joint").get("name")
    column = lines[row].index("<joint") + 1
    assert "\n" not in message and "\\n" not in message
    assert f"not a valid URDF: joint '{name}' (line {row + 1}, column {column}): " in message
    assert "spinning" in message


@pytest.mark.integration
def test_a_file_pybullet_cannot_load_is_one_line_naming_it(tmp_path):
    """A revolute joint without <limit> (URDF requires one; urdf_parser_py lets it pass, PyBullet refuses): robot init
    exits 2 with one line naming the user's file, not a traceback, and writes nothing."""
    from typer.testing import CliRunner

    from dualarm.cli import app

    text = ARM.format(extensions="")
    start = text.index("<limit")
    path = tmp_path / "arm.urdf"
    path.write_text(text[:start] + text[text.index("/>", start) + 2 :])
    result = CliRunner().invoke(app, ["robot", "init", str(path), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2, result.output
    (line,) = result.stderr.strip().splitlines()
    assert line == f"error: {path}: PyBullet cannot load it " + (
        "(a revolute or prismatic joint without <limit>, which URDF requires, or a mesh it cannot read)"
    )
    assert not (tmp_path / "out").exists()
