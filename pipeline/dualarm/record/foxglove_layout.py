"""A Foxglove layout for a run's ``run.mcap``.

The JSON Foxglove Studio 1.48 writes with "Export layout".

The recorder writes it into each run directory as ``foxglove-layout.json``. To use it, open
``run.mcap`` in Foxglove Studio or Lichtblick (its open-source continuation, same layout format),
then choose Layouts -> Import from file... -> ``foxglove-layout.json``.

What it shows: on the left one 3D panel in frame ``world`` with the robot (a URDF layer holding what
``/robot_description`` holds, drawn when the panel mounts, moved by ``/tf``), the task's reference
path, the hands' path (executed, when the run executed) and the task's objects, frame axes small and
unlabelled, the camera framing the whole robot; on the right one Plot panel per quantity, in tabs:
hand error and arm angle, the joint positions of each chain, and the contact counts, each over its
stage's clock. Only panels for topics that ``stages`` produce are
included. Plot paths use Studio's message path syntax ``<topic>.<field>.<key>`` over the run's JSON
messages (see :mod:`dualarm.record.schemas`); ``tests/record/test_viewer_foxglove.py`` opens a run
with this layout in Studio itself.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from urllib.parse import quote

import numpy as np

from dualarm.contracts.run import ALL_STAGES
from dualarm.errors import InvalidArgumentError, excerpt
from dualarm.files import listing
from dualarm.model.robot import Robot
from dualarm.record.sink import SERIES_COLORS, plot_range, robot_box, shown_stage

#: The stages a run may hold, in order.
STAGES = ALL_STAGES
#: Stages whose ``/<stage>/sample`` holds ``hand_error_m``, the most refined first.
HAND_ERROR_STAGES = ("execute", "ik", "plan")

#: The camera of the 3D panel, in frame ``world`` (the robot base at the floor, x forward, z up), for a robot whose
#: largest side is 1 m (:func:`~dualarm.record.sink.robot_box`; the distance and ``targetOffset`` scale with it): aimed
#: at the box's centre moved forward by TARGET_AHEAD, from in front of the robot and to its left, a little above, so
#: that the whole robot stays in view (for the 1.59 m humanoid: at (0.15, 0, 0.8) from 3.4 m). Angles in degrees, as in
#: Studio: ``phi`` from the vertical, ``thetaOffset`` about it (-120: the robot's front-left).
DISTANCE_PER_M = 2.138
CAMERA = {
    "distance": DISTANCE_PER_M,
    "perspective": True,
    "phi": 65.0,
    "target": [0.0, 0.0, 0.0],
    "targetOffset": [0.0, 0.0, 0.0],
    "targetOrientation": [0.0, 0.0, 0.0, 1.0],
    "thetaOffset": -120.0,
    "fovy": 45.0,
    "near": 0.01,
    "far": 100.0,
}
TARGET_AHEAD = (0.094, 0.0, 0.0)
#: The 3D panel's background: dark, as Rerun's, so that white meshes stand out.
BACKGROUND = "#2b2b2b"
#: The key of a panel's title in its config (Studio's PANEL_TITLE_CONFIG_KEY).
TITLE = "foxglovePanelTitle"
#: The 3D panel's URDF layer of the robot. Studio loads a URDF layer from the layout (its ``url``) when the panel
#: mounts; a message on ``/robot_description`` reaches a panel only when Studio sends it the messages before the
#: current time, which it does when the topics any panel shows change (IterablePlayer.setSubscriptions), so a panel
#: mounted again with the same topics gets none (a layout imported into an open file showed no robot, once in four,
#: until the timeline was clicked). The characters a URDF keeps as they are in that ``data:`` URL (the others, among
#: them ``%``, ``#`` and line breaks, are percent-encoded).
ROBOT_LAYER = "robot"
URL_SAFE = " /+=:;,.-_<>\"'()!*@$?&[]{}~"
#: The id of the 3D panel (Studio panel ids are ``<panel type>!<any suffix>``), and of the Tab panel holding the plots.
THREE_D_PANEL = "3D!dualarm"
PLOT_TABS = "Tab!plots"
#: Field names Studio's message path grammar takes unquoted (its ``quoteFieldNameIfNeeded``).
_PLAIN_FIELD = re.compile(r"^[a-zA-Z0-9_-]+$")


def foxglove_layout(
    robot: Robot,
    stages: Sequence[str],
    hands: Sequence[str],
    joint_names: Sequence[str] | None = None,
    ranges: Mapping[str, tuple[float, float]] | None = None,
    carried: bool = False,
    description: str | None = None,
) -> dict:
    """The Foxglove Studio layout of a run of ``stages`` of ``robot`` moving ``hands``.

    Args:
        robot: the run's robot (its chains name the joint groups of the plots).
        stages: the stages the run records, names from :data:`STAGES`.
        hands: the hands the task moves (``left``, ``right``).
        joint_names: the joints in the run's samples (default: the joints of the ``hands``' arm
            chains); joints of other chains (a free waist) get a plot of their own.
        ranges: the lowest and highest value of each plotted message path (:func:`message_path`); each plot then
            shows its values' range, no narrower than its unit's floor (:func:`~dualarm.record.sink.plot_range`).
            None: Studio's own range.
        carried: whether the hands carry an object (its topic ``/<shown stage>/object`` is then in the 3D panel).
        description: the URDF ``/robot_description`` carries (:func:`~dualarm.record.mcap_sink.robot_description`):
            the 3D panel then draws the robot from a URDF layer holding it (:data:`ROBOT_LAYER`), not from the topic.

    Returns:
        The layout as Studio exports it: ``configById``, ``globalVariables``, ``userNodes``,
        ``playbackConfig`` and ``layout`` (the panels' arrangement).

    Raises:
        InvalidArgumentError: a stage, hand or joint the run cannot have.
    """
    _check("stages", stages, STAGES)
    _check("hands", hands, robot.hands)
    joints = (
        tuple(joint_names)
        if joint_names is not None
        else tuple(j for hand in hands for j in robot.hand_chain(hand).joint_names)
    )
    _check("joint_names", joints, robot.joint_names)
    plots = _plots(robot, tuple(stages), tuple(hands), joints, ranges or {})
    configs = {
        THREE_D_PANEL: _three_d(robot, stages, carried, description),
        **{panel_id: config for _, panel_id, config in plots},
    }
    layout: str | dict = THREE_D_PANEL
    if plots:
        tabs = {tab: [panel_id for in_tab, panel_id, _ in plots if in_tab == tab] for tab, _, _ in plots}
        configs[PLOT_TABS] = {
            "activeTabIdx": 0,
            "tabs": [{"title": tab, "layout": _stack(panel_ids)} for tab, panel_ids in tabs.items()],
        }
        layout = {"first": THREE_D_PANEL, "second": PLOT_TABS, "direction": "row", "splitPercentage": 55}
    return {
        "configById": configs,
        "globalVariables": {},
        "userNodes": {},
        "playbackConfig": {"speed": 1.0},
        "layout": layout,
    }


def _check(argument: str, given: Sequence[str], valid: Sequence[str]) -> None:
    for name in given:
        if name not in valid:
            raise InvalidArgumentError(argument, f"unknown name '{excerpt(name)}' (valid: {listing(valid)})")


def _shown(stages: Sequence[str]) -> str | None:
    """The stage whose robot is on ``/tf`` (none for the path stage alone).

    Its hands' path is on ``/<stage>/hand_path`` and its joints in ``/<stage>/sample``.
    """
    shown = shown_stage(stages)
    return None if shown == "path" else shown


def _three_d(robot: Robot, stages: Sequence[str], carried: bool, description: str | None) -> dict:
    """The 3D panel, in ``world``, its camera on ``robot`` (:data:`CAMERA`).

    The robot (the URDF layer of ``description``, else of ``/robot_description``), the task's paths and objects, the
    shown stage's hand path (the executed one) and the object its hands carry.
    """
    topics: dict[str, dict] = {"/robot_description": {"visible": description is None}}
    if "path" in stages:
        topics["/task/reference_path"] = {"visible": True}
        topics["/task/environment"] = {"visible": True}  # written only when the task has objects
    shown = _shown(stages)
    if shown is not None:
        topics[f"/{shown}/hand_path"] = {"visible": True}
        if carried:
            topics[f"/{shown}/object"] = {"visible": True}
    grid = {
        "layerId": "foxglove.Grid",
        "instanceId": "floor",
        "label": "floor (0.25 m)",
        "visible": True,
        "frameLocked": True,
        "size": 3,
        "divisions": 12,
        "lineWidth": 1,
        "color": "#9e9e9e80",
        "position": [0, 0, 0],
        "rotation": [0, 0, 0],
        "order": 1,
    }
    centre, size = robot_box(robot)
    camera = {
        **CAMERA,
        "distance": DISTANCE_PER_M * size,
        "targetOffset": (centre + size * np.array(TARGET_AHEAD)).tolist(),
    }
    return {
        TITLE: "robot (world)",
        "cameraState": camera,
        "followMode": "follow-pose",
        "followTf": "world",
        # URDF meshes are z-up in their links (ROS REP-103); Studio turns STL and OBJ meshes as y-up unless told
        # and a dark background, as Rerun's: a robot whose meshes have no colour (the Panda's) is drawn white
        "scene": {
            "transforms": {"showLabel": False, "axisScale": 0.2, "lineWidth": 1},
            "meshUpAxis": "z_up",
            "backgroundColor": BACKGROUND,
        },
        "transforms": {},
        "topics": topics,
        "layers": {"floor": grid, **({} if description is None else {ROBOT_LAYER: _urdf_layer(description)})},
    }


def _urdf_layer(description: str) -> dict:
    """A URDF layer of the 3D panel drawing ``description``, held in its ``url`` (a ``data:`` URL)."""
    return {
        "layerId": "foxglove.Urdf",
        "instanceId": ROBOT_LAYER,
        "label": "robot",
        "visible": True,
        "frameLocked": True,
        "url": "data:application/xml;charset=utf-8," + quote(description, safe=URL_SAFE),
        "order": 2,
    }


def _plots(
    robot: Robot,
    stages: tuple[str, ...],
    hands: tuple[str, ...],
    joints: tuple[str, ...],
    ranges: Mapping[str, tuple[float, float]],
) -> list[tuple[str, str, dict]]:
    """``(tab, panel id, Plot config)`` per quantity the run records, in display order.

    ``ranges``: as :func:`foxglove_layout`'s. A tab holds few plots, so that each is tall enough for its legend (a
    column of five plots showed 5 of an arm's 7 names).
    """
    plots: list[tuple[str, str, dict]] = []
    error_stage = next((s for s in HAND_ERROR_STAGES if s in stages), None)
    if error_stage is not None:
        topic = f"/{error_stage}/sample"
        paths = [(message_path(topic, "hand_error_m", hand), hand) for hand in hands]
        plots.append(
            ("errors", "Plot!hand-error", _plot(f"hand position error [m] ({error_stage})", "m", topic, paths, ranges))
        )
    if "ik" in stages:
        paths = [(message_path("/ik/sample", "arm_angle_rad", hand), hand) for hand in hands]
        plots.append(
            ("errors", "Plot!arm-angle", _plot("arm angle psi [rad] (ik)", "rad", "/ik/sample", paths, ranges))
        )
    joint_stage = _shown(stages)
    if joint_stage is not None:
        topic = f"/{joint_stage}/sample"
        for group, names in _joint_groups(robot, joints):
            paths = [(message_path(topic, "position", name), _short(name, names)) for name in names]
            title = f"{group} joint positions [rad] ({joint_stage})"
            plots.append((f"{group} joints", f"Plot!joints-{group}", _plot(title, "rad", topic, paths, ranges)))
    if "execute" in stages:
        paths = [
            (message_path("/execute/sample", f"{kind}_contacts"), kind) for kind in ("self", "environment", "expected")
        ]
        plots.append(
            ("contacts", "Plot!contacts", _plot("contacts (execute)", "count", "/execute/sample", paths, ranges))
        )
    return plots


def _joint_groups(robot: Robot, joints: tuple[str, ...]) -> list[tuple[str, tuple[str, ...]]]:
    """``joints`` grouped by the robot's chain holding them (chain order).

    Those of no chain last as ``other``.
    """
    groups = [(name, tuple(j for j in chain.joint_names if j in joints)) for name, chain in robot.chains.items()]
    chained = {j for _, names in groups for j in names}
    groups.append(("other", tuple(j for j in joints if j not in chained)))
    return [(name, names) for name, names in groups if names]


def _short(name: str, names: tuple[str, ...]) -> str:
    """``name`` without the ``<word>_`` prefix every one of ``names`` shares, for short legends.

    For example ``left_elbow`` among the left arm's joints: ``elbow``.
    """
    prefix = name.split("_", 1)[0] + "_"
    return (
        name.removeprefix(prefix)
        if len(names) > 1 and all(n.startswith(prefix) and n != prefix for n in names)
        else name
    )


def message_path(topic: str, *fields: str) -> str:
    """A message path ``<topic>.<field>...``, each field quoted as Studio's grammar needs."""
    return topic + "".join(
        "." + (f if _PLAIN_FIELD.match(f) else '"' + f.replace("\\", "\\\\").replace('"', '\\"') + '"') for f in fields
    )


def _plot(
    title: str, unit: str, topic: str, paths: list[tuple[str, str]], ranges: Mapping[str, tuple[float, float]]
) -> dict:
    """A Plot panel of ``paths`` (message path, legend label) on ``topic`` in ``unit``, over motion time.

    Its y-range from the ``ranges`` of its paths (:func:`~dualarm.record.sink.plot_range`); none logged: Studio's
    own, from 0 for a quantity that cannot be negative ([m], counts). Its x-range is its stage's clock, the range of
    the topic's ``t`` (the IK on the task's clock, the execution on its own), not linked to the other plots'; the
    series in :data:`~dualarm.record.sink.SERIES_COLORS`, as in Rerun; the legend on its left.
    """
    logged = [ranges[value] for value, _ in paths if value in ranges]
    config = {
        TITLE: title,
        "paths": [
            {
                "value": value,
                "label": label,
                "enabled": True,
                "timestampMethod": "receiveTime",
                "color": "#{:02x}{:02x}{:02x}".format(*SERIES_COLORS[i % len(SERIES_COLORS)]),
            }
            for i, (value, label) in enumerate(paths)
        ],
        "showXAxisLabels": True,
        "showYAxisLabels": True,
        "showLegend": True,
        "legendDisplay": "left",
        "showPlotValuesInLegend": False,
        "isSynced": False,
        "xAxisVal": "timestamp",
        "sidebarDimension": 150,
    }
    if logged:
        config["minYValue"], config["maxYValue"] = plot_range(logged, unit)
    elif unit in ("m", "count"):
        config["minYValue"] = 0.0
    clock = ranges.get(message_path(topic, "t"))
    if clock is not None:
        config["minXValue"], config["maxXValue"] = clock
    return config


def _stack(panel_ids: list[str]) -> str | dict:
    """``panel_ids`` as a column of equal heights (Studio's layout tree splits in two at each node)."""
    if len(panel_ids) == 1:
        return panel_ids[0]
    return {
        "first": panel_ids[0],
        "second": _stack(panel_ids[1:]),
        "direction": "column",
        "splitPercentage": 100 / len(panel_ids),
    }
