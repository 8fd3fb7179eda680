"""JSON Schemas of dualarm's own MCAP messages (self-describing, so Foxglove can plot any field).

Every message carries the motion time ``t`` [s] and the repetition index ``rep``, which the
pandas read-back turns into columns.

Maps (joint name -> value, hand -> value, metric -> value) are written here with the kind of their
keys; :func:`named` lists the run's keys as the map's ``properties`` before a schema is written.
Foxglove's JSON-schema parser reads an object's fields from ``properties`` alone: a map without
them breaks the whole topic ("Cannot convert undefined or null to object").
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

#: Internal key of a map object: the kind of its keys ("joints", "hands" or "metrics"), replaced by
#: ``properties`` in :func:`named`.
_KEYS = "x-dualarm-keys"
_NUMBER = {"type": "number"}
_VECTOR3 = {"type": "object", "properties": {k: _NUMBER for k in "xyz"}, "required": list("xyz")}
_QUATERNION = {"type": "object", "properties": {k: _NUMBER for k in "xyzw"}, "required": list("xyzw")}
_JOINT_MAP = {"type": "object", "additionalProperties": _NUMBER, _KEYS: "joints"}
_HAND_MAP = {"type": "object", "additionalProperties": _NUMBER, _KEYS: "hands"}
_HAND_VECTORS = {"type": "object", "additionalProperties": _VECTOR3, _KEYS: "hands"}


def named(schema: Mapping, keys: Mapping[str, Sequence[str]]) -> dict:
    """``schema`` with each map's keys listed as its ``properties``.

    The keys: kind -> names; kinds ``joints``, ``hands``, ``metrics``.
    """
    filled = {
        key: named(value, keys) if isinstance(value, Mapping) else value
        for key, value in schema.items()
        if key != _KEYS
    }
    if _KEYS in schema:
        filled["properties"] = {name: filled["additionalProperties"] for name in keys.get(schema[_KEYS], ())}
    return filled


HAND_REFERENCE = {
    "title": "dualarm.HandReference",
    "description": "One sample of a hand's Cartesian reference, in the robot base frame.",
    "type": "object",
    "properties": {
        "t": {**_NUMBER, "description": "motion time [s]"},
        "rep": {"type": "integer", "description": "repetition index, 0-based"},
        "segment": {"type": "integer", "description": "index of the task move, 0-based"},
        "frame_id": {"type": "string"},
        "position": {**_VECTOR3, "description": "hand frame origin [m]"},
        "orientation": {**_QUATERNION, "description": "hand frame orientation (unit quaternion)"},
        "linear_velocity": {**_VECTOR3, "description": "[m/s]"},
        "angular_velocity": {**_VECTOR3, "description": "in the base frame [rad/s]"},
    },
    "required": ["t", "rep", "segment", "frame_id", "position", "orientation", "linear_velocity", "angular_velocity"],
}

METRICS = {
    "title": "dualarm.Metrics",
    "description": "The run's metrics, keys <stage>.<name> with the unit as suffix (as in metrics.json).",
    "type": "object",
    "properties": {
        "t": _NUMBER,
        "rep": {"type": "integer"},
        "values": {"type": "object", "additionalProperties": _NUMBER, _KEYS: "metrics"},
    },
    "required": ["t", "rep", "values"],
}

ROBOT_DESCRIPTION = {
    "title": "std_msgs/String",
    "description": "The robot's URDF, for Foxglove's URDF layer (source: topic /robot_description).",
    "type": "object",
    "properties": {"data": {"type": "string"}},
    "required": ["data"],
}

JOINT_STATE = {
    "title": "dualarm.JointState",
    "description": "Joint positions of the robot at one instant [rad].",
    "type": "object",
    "properties": {
        "t": {**_NUMBER, "description": "motion time [s]"},
        "rep": {"type": "integer"},
        "position": {**_JOINT_MAP, "description": "joint name -> position [rad]"},
    },
    "required": ["t", "rep", "position"],
}


IK_SAMPLE = {
    "title": "dualarm.IkSample",
    "description": "One sample of an IK stage's joint path.",
    "type": "object",
    "properties": {
        "t": {**_NUMBER, "description": "motion time [s]"},
        "rep": {"type": "integer"},
        "method": {"type": "string"},
        "status": {"type": "integer", "description": "0 ok, 1 failed"},
        "solve_time_s": {**_NUMBER, "description": "solver time of this sample [s]"},
        "position": {**_JOINT_MAP, "description": "joint -> position [rad]"},
        "velocity": {**_JOINT_MAP, "description": "joint -> commanded velocity [rad/s]"},
        "hand_error_m": {**_HAND_MAP, "description": "hand -> |r - f(q)| [m]"},
        "hand_orientation_error_rad": {
            **_HAND_MAP,
            "description": (
                "hand -> angle of R_asked^T R_reached [rad] (IK stages; "
                "measured even where the method solved positions only)"
            ),
        },
        "task_space": {
            "type": "string",
            "enum": ["pose", "position"],
            "description": "what the method solved: the hands' poses, or their positions only",
        },
        "arm_angle_rad": {
            **_HAND_MAP,
            "description": (
                "hand -> arm angle [rad]: psi of MC-Inverse eq (1) on an S-R-S arm, else the stereographic SEW angle"
            ),
        },
    },
    "required": [
        "t",
        "rep",
        "method",
        "status",
        "solve_time_s",
        "position",
        "velocity",
        "hand_error_m",
        "arm_angle_rad",
    ],
}

JOINT_LIMITS = {
    "title": "dualarm.JointLimits",
    "description": "The physical limits a stage was held to, per active joint (the task's limits where it sets them).",
    "type": "object",
    "properties": {
        "t": _NUMBER,
        "rep": {"type": "integer"},
        "lower": {**_JOINT_MAP, "description": "position lower limit [rad]"},
        "upper": {**_JOINT_MAP, "description": "position upper limit [rad]"},
        "velocity": {**_JOINT_MAP, "description": "velocity limit, symmetric [rad/s]"},
        "acceleration": {**_JOINT_MAP, "description": "acceleration limit, symmetric [rad/s^2] (retime, smooth)"},
        "jerk": {**_JOINT_MAP, "description": "jerk limit, symmetric [rad/s^3] (smooth)"},
    },
    "required": ["t", "rep", "lower", "upper", "velocity"],
}

JOINT_BOUNDS = {
    "title": "dualarm.JointBounds",
    "description": "Time-varying joint bounds of one sample (TV-GDD eqs 19 and 22).",
    "type": "object",
    "properties": {
        "t": _NUMBER,
        "rep": {"type": "integer"},
        "theta_lower": {**_JOINT_MAP, "description": "theta_new-(t) [rad]"},
        "theta_upper": {**_JOINT_MAP, "description": "theta_new+(t) [rad]"},
        "zeta_lower": {**_JOINT_MAP, "description": "zeta_new-(t) [rad/s]"},
        "zeta_upper": {**_JOINT_MAP, "description": "zeta_new+(t) [rad/s]"},
    },
    "required": ["t", "rep"],
}

TRAJECTORY_SAMPLE = {
    "title": "dualarm.TrajectorySample",
    "description": "One sample of a timed joint trajectory (retime or smooth stage).",
    "type": "object",
    "properties": {
        "t": {**_NUMBER, "description": "motion time [s]"},
        "rep": {"type": "integer"},
        "position": {**_JOINT_MAP, "description": "joint -> position [rad]"},
        "velocity": {**_JOINT_MAP, "description": "joint -> velocity [rad/s]"},
        "acceleration": {**_JOINT_MAP, "description": "joint -> acceleration [rad/s^2]"},
        "jerk": {**_JOINT_MAP, "description": "joint -> mean jerk over the period ending here [rad/s^3] (smooth)"},
        "deviation_rad": {**_JOINT_MAP, "description": "joint -> |q - q_retimed| at the same time [rad] (smooth)"},
        "hand_position": {**_HAND_VECTORS, "description": "hand -> position by forward kinematics [m]"},
    },
    "required": ["t", "rep", "position", "velocity", "acceleration", "hand_position"],
}

EXECUTED_SAMPLE = {
    "title": "dualarm.ExecutedSample",
    "description": "The state the execution starts from (t = 0), then each physics step of it, measured at its end.",
    "type": "object",
    "properties": {
        "t": {**_NUMBER, "description": "simulation time [s]"},
        "rep": {"type": "integer"},
        "position": {**_JOINT_MAP, "description": "joint -> measured position [rad]"},
        "velocity": {**_JOINT_MAP, "description": "joint -> measured velocity [rad/s]"},
        "command": {**_JOINT_MAP, "description": "joint -> the trajectory's position at t [rad]"},
        "hand_position": {**_HAND_VECTORS, "description": "hand -> measured position (PyBullet) [m]"},
        "hand_error_m": {**_HAND_MAP, "description": "hand -> |measured - forward kinematics of the command| [m]"},
        "self_contacts": {"type": "integer", "description": "unexpected robot-robot contact points"},
        "environment_contacts": {"type": "integer", "description": "unexpected robot-environment contact points"},
        "expected_contacts": {"type": "integer", "description": "contact points of pairs the task expects"},
    },
    "required": [
        "t",
        "rep",
        "position",
        "velocity",
        "command",
        "hand_position",
        "hand_error_m",
        "self_contacts",
        "environment_contacts",
        "expected_contacts",
    ],
}

CONTACT = {
    "title": "dualarm.Contact",
    "description": "A pair of bodies touching in one physics step of the execution.",
    "type": "object",
    "properties": {
        "t": _NUMBER,
        "rep": {"type": "integer"},
        "first": {"type": "string", "description": "robot link or object"},
        "second": {"type": "string", "description": "robot link or object"},
        "depth_m": {"type": "number", "description": "deepest penetration in the step [m]"},
        "expected": {"type": "boolean", "description": "named in the task's expected_contacts"},
    },
    "required": ["t", "rep", "first", "second", "depth_m", "expected"],
}
