"""A Foxglove layout for a run's ``run.mcap``.

The JSON Foxglove Studio 1.48 writes with "Export layout".

The recorder writes it into each run directory as ``foxglove-layout.json``. To use it, open
``run.mcap`` in Foxglove Studio or Lichtblick (its open-source continuation, same layout format),
then choose Layouts -> Import from file... -> ``foxglove-layout.json``.

What it shows: on the left one 3D panel in frame ``world`` with the robot (the URDF layer of
``/robot_description``, moved by ``/tf``), the task's reference path, the hands' path (executed,
when the run executed) and the task's objects, frame axes small and unlabelled, the camera framing
the whole robot; on the right one Plot panel per quantity, stacked: hand error, arm angle, the joint
positions of each chain, and the contact counts. Only panels for topics that ``stages`` produce are
included. Plot paths use Studio's message path syntax ``<topic>.<field>.<key>`` over the run's JSON
messages (see :mod:`dualarm.record.schemas`); ``tests/record/test_viewer_foxglove.py`` opens a run
with this layout in Studio itself.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence

import numpy as np

from dualarm.contracts.run import ALL_STAGES
from dualarm.errors import InvalidArgumentError, excerpt
from dualarm.files import listing
from dualarm.model.robot import Robot
from dualarm.record.sink import plot_range, robot_box, shown_stage

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
#: The id of the 3D panel (Studio panel ids are ``<panel type>!<any suffix>``).
THREE_D_PANEL = "3D!dualarm"
#: Field names Studio's message path grammar takes unquoted (its ``quoteFieldNameIfNeeded``).
_PLAIN_FIELD = re.compile(r"^[a-zA-Z0-9_-]+$")


def foxglove_layout(
    robot: Robot,
    stages: Sequence[str],
    hands: Sequence[str],
    joint_names: Sequence[str] | None = None,
    ranges: Mapping[str, tuple[float, float]] | None = None,
    carried: bool = False,
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
    configs = {THREE_D_PANEL: _three_d(robot, stages, carried), **{panel_id: config for panel_id, config in plots}}
    layout: str | dict = THREE_D_PANEL
    if plots:
        layout = {
            "first": THREE_D_PANEL,
            "second": _stack([panel_id for panel_id, _ in plots]),
            "direction": "row",
            "splitPercentage": 55,
        }
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


def _three_d(robot: Robot, stages: Sequence[str], carried: bool) -> dict:
    """The 3D panel, in ``world``, its camera on ``robot`` (:data:`CAMERA`).

    The URDF layer, the task's paths and objects, the shown stage's hand path (the executed one) and the object its
    hands carry.
    """
    topics: dict[str, dict] = {"/robot_description": {"visible": True}}
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
        "layers": {"floor": grid},
    }


def _plots(
    robot: Robot,
    stages: tuple[str, ...],
    hands: tuple[str, ...],
    joints: tuple[str, ...],
    ranges: Mapping[str, tuple[float, float]],
) -> list[tuple[str, dict]]:
    """``(panel id, Plot config)`` per quantity the run records, in display order.

    ``ranges``: as :func:`foxglove_layout`'s.
    """
    plots: list[tuple[str, dict]] = []
    error_stage = next((s for s in HAND_ERROR_STAGES if s in stages), None)
    if error_stage is not None:
        paths = [(message_path(f"/{error_stage}/sample", "hand_error_m", hand), hand) for hand in hands]
        plots.append(("Plot!hand-error", _plot(f"hand position error [m] ({error_stage})", "m", paths, ranges)))
    if "ik" in stages:
        paths = [(message_path("/ik/sample", "arm_angle_rad", hand), hand) for hand in hands]
        plots.append(("Plot!arm-angle", _plot("arm angle psi [rad] (ik)", "rad", paths, ranges)))
    joint_stage = _shown(stages)
    if joint_stage is not None:
        for group, names in _joint_groups(robot, joints):
            paths = [(message_path(f"/{joint_stage}/sample", "position", name), _short(name, names)) for name in names]
            plots.append(
                (f"Plot!joints-{group}", _plot(f"{group} joint positions [rad] ({joint_stage})", "rad", paths, ranges))
            )
    if "execute" in stages:
        paths = [
            (message_path("/execute/sample", f"{kind}_contacts"), kind) for kind in ("self", "environment", "expected")
        ]
        plots.append(("Plot!contacts", _plot("contacts (execute)", "count", paths, ranges)))
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


def _plot(title: str, unit: str, paths: list[tuple[str, str]], ranges: Mapping[str, tuple[float, float]]) -> dict:
    """A Plot panel of ``paths`` (message path, legend label) in ``unit`` against the log (motion) time.

    Its y-range from the ``ranges`` of its paths (:func:`~dualarm.record.sink.plot_range`); none logged: Studio's
    own, from 0 for a quantity that cannot be negative ([m], counts).
    """
    logged = [ranges[value] for value, _ in paths if value in ranges]
    config = {
        TITLE: title,
        "paths": [
            {"value": value, "label": label, "enabled": True, "timestampMethod": "receiveTime"}
            for value, label in paths
        ],
        "showXAxisLabels": True,
        "showYAxisLabels": True,
        "showLegend": True,
        "legendDisplay": "left",
        "showPlotValuesInLegend": False,
        "isSynced": True,
        "xAxisVal": "timestamp",
        "sidebarDimension": 150,
    }
    if logged:
        config["minYValue"], config["maxYValue"] = plot_range(logged, unit)
    elif unit in ("m", "count"):
        config["minYValue"] = 0.0
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
