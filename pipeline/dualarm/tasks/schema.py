"""The schema of a task file, as frozen pydantic models (unknown keys are errors).

Units are in the key names: ``_s`` seconds, ``_m`` metres, ``_rad`` radians. Poses are a position
[m] and roll-pitch-yaw [rad], extrinsic x-y-z (R = Rz Ry Rx), in the robot base frame, or in the
task's ``frame`` (a link or a role such as the left shoulder; ``dualarm.tasks.load`` resolves them).

Every number has a range, refused at load with the range in the message (``1e+300 m is outside
the allowed range [-100, 100] m``). The ranges are physical (a scene within 100 m of the robot,
objects from 0.1 mm to 100 m, angles within a turn) or keep every stage's work bounded (a
control period of at least 0.1 ms, at most 1,000 repetitions; ``dualarm.tasks.load`` also bounds
a path's samples and the arm-angle margin by the robot's joint ranges). They are the constants
below; each field's docstring names its range.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Annotated, Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    GetCoreSchemaHandler,
    GetJsonSchemaHandler,
    StrictBool,
    ValidationError,
    model_validator,
)
from pydantic_core import core_schema

from dualarm.errors import InvalidArgumentError, excerpt

#: Largest |coordinate| of a position, displacement, arc centre or WTA position bound [m].
MAX_COORDINATE_M = 100.0
#: Largest |angle| of an orientation (rpy), an arm angle or a WTA angle bound [rad]: one turn.
MAX_ANGLE_RAD = 2 * math.pi
#: Largest |angle| of one arc move [rad]: two turns.
MAX_ARC_ANGLE_RAD = 4 * math.pi
#: Largest |value| of a joint value in a task (initial configuration, gesture goals) [rad or m];
#: the robot's joint limits apply on top.
MAX_JOINT_VALUE = 100.0
#: Range of an object's size, radius or height [m].
SIZE_RANGE_M = (1e-4, 100.0)
#: Range of the control period [s]: 0.1 ms (10 kHz) to 1 s.
CONTROL_PERIOD_RANGE_S = (1e-4, 1.0)
#: Longest move, switching time or schedule time [s]: a day.
MAX_TIME_S = 86_400.0
#: Most repetitions of a task (the file's or an override).
MAX_REPETITIONS = 1_000
#: Most moves, environment objects, WTAs and expected contacts of a task.
MAX_MOVES, MAX_OBJECTS, MAX_CONTACT_PAIRS = 10_000, 100, 1_000
#: Largest |component| of a direction (arc_axis, vertical) and its shortest length; any length between is
#: normalised.
MAX_DIRECTION, MIN_DIRECTION_LENGTH = 1e6, 1e-6
#: Range of a task's velocity limits [rad/s] and acceleration limits [rad/s^2]: the lowest keeps a
#: time-optimal motion's duration bounded, the highest is beyond any actuator.
VELOCITY_RANGE, ACCELERATION_RANGE = (1e-2, 1e2), (1e-2, 1e4)
#: Range of retime's velocity_fraction and acceleration_fraction.
FRACTION_RANGE = (1e-2, 1.0)
#: Range of TV-GDD's gains nu and feedback_gain [1/s] (the paper's nu = 2; K = 50 in ball_game).
GAIN_RANGE = (0.0, 1e3)
#: Range of TV-GDD's c_tuning [s]: the paper's 0 < c <= 1, and not below the shortest control
#: period (a smaller one is a step either way).
C_TUNING_RANGE = (1e-4, 1.0)
#: Range of a WTA's sampling weight.
WEIGHT_RANGE = (1e-6, 1e6)
#: Longest task name (it names the recordings directory) [characters].
MAX_NAME_CHARS = 64
#: The arm length ``scale = "arm"`` measures against: the shipped humanoid's upper arm (0.32 m) plus
#: forearm (0.28 m), S-R-S L2 + L3 [m]. The shipped tasks' numbers are written for it.
REFERENCE_ARM_M = 0.60
#: Frames a task's ``frame`` may name besides a URDF link: each hand's shoulder centre S (the S-R-S
#: point joints 1-3 turn about) and their midpoint, with the robot base frame's axes.
FRAME_ROLES = ("left.shoulder", "right.shoulder", "shoulders")


@dataclass(frozen=True)
class Range:
    """The range a number must lie in: [low, high], or (low, high] when ``low_open``.

    ``unit`` (" m", " s", ...) is for messages.

    As pydantic metadata (``Annotated[float, FINITE, Range(0, 1)]``) it refuses a number outside
    with the range in the message (``1e+300 m is outside the allowed range [-100, 100] m``) and
    puts the range in the JSON schema.
    """

    low: float
    high: float
    unit: str = ""
    low_open: bool = False

    def __contains__(self, value: float) -> bool:
        return (self.low < value if self.low_open else self.low <= value) and value <= self.high

    def __str__(self) -> str:
        return f"{'(' if self.low_open else '['}{self.low:g}, {self.high:g}]{self.unit}"

    def check(self, value: Any) -> Any:
        """``value`` if it lies in the range; ValueError naming the range otherwise."""
        if value in self:
            return value
        text = f"{value:g}" if isinstance(value, float) else excerpt(value, 24)
        raise ValueError(f"{text}{self.unit} is outside the allowed range {self}")

    def __get_pydantic_core_schema__(self, source: Any, handler: GetCoreSchemaHandler) -> core_schema.CoreSchema:
        return core_schema.no_info_after_validator_function(self.check, handler(source))

    def __get_pydantic_json_schema__(
        self, schema: core_schema.CoreSchema, handler: GetJsonSchemaHandler
    ) -> dict[str, Any]:
        json = handler(schema)
        json["exclusiveMinimum" if self.low_open else "minimum"] = self.low
        json["maximum"] = self.high
        return json


#: ``[transfer] duration_scale``: slower on another robot, up to ten times.
DURATION_SCALE_RANGE = (1.0, 10.0)

#: Metadata of every float of a task file: a TOML float or integer, finite.
FINITE = Field(strict=True, allow_inf_nan=False)

Float = Annotated[float, FINITE]
Coordinate = Annotated[float, FINITE, Range(-MAX_COORDINATE_M, MAX_COORDINATE_M, " m")]
Angle = Annotated[float, FINITE, Range(-MAX_ANGLE_RAD, MAX_ANGLE_RAD, " rad")]
ArcAngle = Annotated[float, FINITE, Range(-MAX_ARC_ANGLE_RAD, MAX_ARC_ANGLE_RAD, " rad")]
Size = Annotated[float, FINITE, Range(*SIZE_RANGE_M, " m")]
Time = Annotated[float, FINITE, Range(0.0, MAX_TIME_S, " s")]
Duration = Annotated[float, FINITE, Range(0.0, MAX_TIME_S, " s", low_open=True)]
Period = Annotated[float, FINITE, Range(*CONTROL_PERIOD_RANGE_S, " s")]
Component = Annotated[float, FINITE, Range(-MAX_DIRECTION, MAX_DIRECTION)]
JointValue = Annotated[float, FINITE, Range(-MAX_JOINT_VALUE, MAX_JOINT_VALUE)]
Velocity = Annotated[float, FINITE, Range(*VELOCITY_RANGE, " rad/s")]
Acceleration = Annotated[float, FINITE, Range(*ACCELERATION_RANGE, " rad/s^2")]
Fraction = Annotated[float, FINITE, Range(*FRACTION_RANGE)]
Gain = Annotated[float, FINITE, Range(*GAIN_RANGE, " 1/s", low_open=True)]
CTuning = Annotated[float, FINITE, Range(*C_TUNING_RANGE, " s")]
JointStep = Annotated[float, FINITE, Range(0.0, 2 * math.pi, " rad", low_open=True)]
Margin = Annotated[float, FINITE, Range(0.0, math.pi, " rad")]
Weight = Annotated[float, FINITE, Range(*WEIGHT_RANGE)]
Repetitions = Annotated[int, Field(strict=True), Range(1, MAX_REPETITIONS)]
Position = tuple[Coordinate, Coordinate, Coordinate]
Rpy = tuple[Angle, Angle, Angle]
Direction = tuple[Component, Component, Component]
JointValues = dict[str, JointValue]


def unit_vector(v: tuple[float, float, float]) -> tuple[float, float, float]:
    """``v`` / |v|, the length computed without overflow (math.hypot)."""
    length = math.hypot(*v)
    return (v[0] / length, v[1] / length, v[2] / length)


def _check_direction(v: tuple[float, float, float], key: str) -> None:
    if math.hypot(*v) < MIN_DIRECTION_LENGTH:
        raise ValueError(
            f"{key} must have a length of at least {MIN_DIRECTION_LENGTH:g} (a direction; it is normalised)"
        )


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Pose(_Model):
    """A pose: ``position`` [m] and ``rpy`` [rad] (R = Rz(yaw) Ry(pitch) Rx(roll)).

    Each coordinate of ``position`` within +-:data:`MAX_COORDINATE_M`, each angle of ``rpy`` within
    +-:data:`MAX_ANGLE_RAD`.
    """

    position: Position
    rpy: Rpy = (0.0, 0.0, 0.0)


class HandMove(_Model):
    """What one hand does during a move; exactly one of ``to``, ``by``, ``arc_*`` or ``hold``.

    - ``to``: straight line to a named waypoint, orientation by slerp.
    - ``by``: straight line by a displacement [m] (each within +-:data:`MAX_COORDINATE_M`), orientation kept.
    - ``arc_center`` [m] (within +-:data:`MAX_COORDINATE_M`), ``arc_axis`` (the normal of the circle's
      plane, right-hand rule; any length from :data:`MIN_DIRECTION_LENGTH`, components within
      +-:data:`MAX_DIRECTION`; see :attr:`arc_unit_axis`) and ``arc_angle_rad`` (within
      +-:data:`MAX_ARC_ANGLE_RAD`): arc about the centre, orientation kept.
    - ``hold = true``: stay still.
    """

    to: str | None = None
    by: Position | None = None
    arc_center: Position | None = None
    arc_axis: Direction | None = None
    arc_angle_rad: ArcAngle | None = None
    hold: StrictBool | None = None

    @model_validator(mode="after")
    def _one_kind(self) -> HandMove:
        arc = (self.arc_center, self.arc_axis, self.arc_angle_rad)
        if any(v is not None for v in arc) and not all(v is not None for v in arc):
            raise ValueError("an arc needs arc_center, arc_axis and arc_angle_rad")
        kinds = [self.to is not None, self.by is not None, self.arc_center is not None, bool(self.hold)]
        if sum(kinds) != 1:
            raise ValueError("give exactly one of to, by, arc_center/arc_axis/arc_angle_rad, hold = true")
        if self.arc_axis is not None:
            _check_direction(self.arc_axis, "arc_axis")
        return self

    @property
    def kind(self) -> str:
        """``to``, ``by``, ``arc`` or ``hold``."""
        if self.to is not None:
            return "to"
        if self.by is not None:
            return "by"
        return "arc" if self.arc_center is not None else "hold"

    @property
    def arc_unit_axis(self) -> tuple[float, float, float]:
        """``arc_axis`` normalised (its length computed without overflow)."""
        assert self.arc_axis is not None, "not an arc"
        return unit_vector(self.arc_axis)


class Move(_Model):
    """One segment of the path: every driven hand moves for ``duration_s`` with a smooth time scaling.

    ``duration_s`` is in (0, :data:`MAX_TIME_S`] s, a whole number of control periods; the time
    scaling has zero velocity and acceleration at both ends. A driven hand not named holds still.
    """

    duration_s: Duration
    left: HandMove | None = None
    right: HandMove | None = None

    def for_hand(self, hand: str) -> HandMove | None:
        """The move of ``hand``, or None if it is not named."""
        return getattr(self, hand)


class Start(_Model):
    """Start pose of each driven hand: a waypoint name, or ``"initial"``.

    ``"initial"`` is the pose the hand has at the task's initial configuration.
    """

    left: str | None = None
    right: str | None = None


class Limits(_Model):
    """Task-specific joint limits that replace the robot's.

    Each is a number for every joint, or a table joint -> value.

    Attributes:
        velocity: [rad/s], within :data:`VELOCITY_RANGE`.
        acceleration: [rad/s^2], within :data:`ACCELERATION_RANGE`.
    """

    velocity: Velocity | dict[str, Velocity] | None = None
    acceleration: Acceleration | dict[str, Acceleration] | None = None


class Retime(_Model):
    """How the retime stage times the joint path.

    Attributes:
        timing: ``jerk-limited`` (the default): near time-optimal within the full velocity,
            acceleration and jerk limits, exactly on the path (:mod:`dualarm.retime.jerk`; the
            smooth stage passes it through); ``optimal``: time-optimal within the velocity and
            acceleration limits (TOPP-RA), then tracked by the smooth stage within the jerk
            limits, off the path by its lag; ``task``: the task's own timing (its moves'
            durations), checked against the three limits.
        velocity_fraction / acceleration_fraction: for ``optimal``, the share of the velocity and
            acceleration limits TOPP-RA may use, within :data:`FRACTION_RANGE`. The rest is the
            smooth stage's headroom: a time-optimal profile switches its acceleration instantly
            (an infinite jerk), and a jerk-limited tracker lags behind each switch; with headroom
            it catches up. The reported ratios are always against the full limits.
    """

    timing: Literal["jerk-limited", "optimal", "task"] = "jerk-limited"
    velocity_fraction: Fraction = 0.9
    acceleration_fraction: Fraction = 0.3


class Ik(_Model):
    """How IK methods read the task.

    Attributes:
        task_space: ``pose``: every method solves the hands' positions and orientations;
            ``position``: the velocity-level methods (TV-GDD, pinv) solve positions only, as the
            TV-GDD paper does (m = 3 per hand, eq 13), and their orientation error is measured but
            not asked for. Pose-level methods always solve the whole pose.
    """

    task_space: Literal["pose", "position"] = "pose"


class Gesture(_Model):
    """TV-GDD time-varying gesture bounds (Zhang, Kong, Niu, eqs 19-22).

    Attributes:
        t_sp_s: switching time T_SP = T_d / N [s], in (0, :data:`MAX_TIME_S`].
        c_tuning: time-tuning parameter [s], within :data:`C_TUNING_RANGE` (the paper's 0 < c <= 1).
        nu: bound-to-velocity scaling nu of eq (21) [1/s], within :data:`GAIN_RANGE`.
        feedback_gain: position-error feedback K of eq (16) [1/s], within :data:`GAIN_RANGE`.
        bound_feedforward: add each bound's own rate to eq (21) so joints pressed against a closing
            bound stay inside it (not in the paper; see TvgddSettings).
        goal_lower / goal_upper: theta_goal- / theta_goal+ per joint [rad], within the joint's
            position limits (checked at load); a joint whose two goals are equal is a gesture
            joint driven to that value.
    """

    t_sp_s: Duration
    c_tuning: CTuning
    nu: Gain
    feedback_gain: Gain
    bound_feedforward: StrictBool = False
    goal_lower: JointValues
    goal_upper: JointValues

    @model_validator(mode="after")
    def _bounds_do_not_cross(self) -> Gesture:
        # with the feedforward the band of eq (19) may shrink at most at the relative rate nu;
        # it shrinks at up to 1 / c_tuning
        if self.bound_feedforward and self.nu * self.c_tuning <= 1:
            raise ValueError(
                f"bound_feedforward needs nu * c_tuning > 1 (here {self.nu * self.c_tuning:g}), "
                "or the lower and upper bounds cross"
            )
        return self


class ArmAngleTable(_Model):
    """A task file's ``[arm_angle]`` table, validated; :meth:`settings` converts it to :class:`ArmAngle`.

    Its keys and their ranges are those of :class:`ArmAngle`.
    """

    mode: Literal["initial", "constant", "schedule", "auto"] = "auto"
    value_rad: dict[Literal["left", "right"], Angle] = {}
    schedule: dict[Literal["left", "right"], tuple[tuple[Time, Angle], ...]] = {}
    vertical: Direction = (0.0, 0.0, 1.0)
    max_joint_step_rad: JointStep = 0.2
    margin_rad: Margin = 0.05
    range_rad: tuple[Float, Float] = (-math.pi, math.pi)

    @model_validator(mode="after")
    def _complete(self) -> ArmAngleTable:
        low, high = self.range_rad
        if not -math.pi <= low < high <= math.pi:
            raise ValueError(f"range_rad must be an interval within [-pi, pi] (here [{low:g}, {high:g}])")
        if self.mode == "constant" and not self.value_rad:
            raise ValueError("mode 'constant' needs value_rad = { left = ..., right = ... }")
        if self.mode == "schedule":
            if not self.schedule:
                raise ValueError("mode 'schedule' needs schedule = { left = [[t, psi], ...] }")
            for hand, points in self.schedule.items():
                times = [t for t, _ in points]
                if not points or any(b <= a for a, b in zip(times, times[1:], strict=False)):
                    raise ValueError(f"schedule.{hand}: times must increase")
        _check_direction(self.vertical, "vertical")
        return self

    def settings(self) -> ArmAngle:
        """The table as MC-Inverse's and SEW IK's settings."""
        return ArmAngle(**{name: getattr(self, name) for name in type(self).model_fields})


@dataclass(frozen=True)
class ArmAngle:
    """How MC-Inverse picks the arm angle psi of eq (1) along the path (Zou, Min, Xu, section III.B).

    Attributes:
        mode: ``auto`` (the default, the mode that finds a profile when one exists):
            see below; ``initial``: psi of the initial configuration, held (the branch nearest the
            initial configuration, which may leave the joint limits along the path); ``constant``:
            ``value_rad``; ``schedule``: ``schedule`` interpolated linearly in the time since the
            repetition began; ``auto``: the branch and psi profile of least joint and arm-angle
            travel that stays inside the joint limits (``margin_rad`` from them where it can) and
            within ``range_rad``, the same in every repetition (see ``mc_path._auto``). Each is a
            function of the pose and its place in the repetition, not of the history, so repeated
            passes give the same joints.
        value_rad: psi per hand for ``constant`` [rad], within +-:data:`MAX_ANGLE_RAD`.
        schedule: per hand, (time within a repetition [s], in [0, :data:`MAX_TIME_S`], psi [rad],
            within +-:data:`MAX_ANGLE_RAD`) pairs, times increasing.
        vertical: the vertical vector V of the reference plane, in the arm's base frame (a
            direction: any length from :data:`MIN_DIRECTION_LENGTH`, components within
            +-:data:`MAX_DIRECTION`).
        max_joint_step_rad: largest joint change between samples before the path fails [rad], in
            (0, 2 pi] (a step of a whole turn checks nothing).
        margin_rad: for ``auto``, the distance to the joint limits to keep [rad], in [0, pi]; and
            at load, below half the narrowest position range of a driven arm's joints (no
            configuration keeps a larger margin to both limits of that joint, and a huge margin
            drowns the travel cost the profile minimises).
        range_rad: for ``auto``, the open interval psi must stay in [rad], within [-pi, pi] (the
            MC-Inverse paper keeps it in (-pi, 0) for human-like motion).
    """

    mode: Literal["initial", "constant", "schedule", "auto"] = "auto"
    value_rad: Mapping[str, float] = field(default_factory=dict)
    schedule: Mapping[str, tuple[tuple[float, float], ...]] = field(default_factory=dict)
    vertical: tuple[float, float, float] = (0.0, 0.0, 1.0)
    max_joint_step_rad: float = 0.2
    margin_rad: float = 0.05
    range_rad: tuple[float, float] = (-math.pi, math.pi)

    def __post_init__(self) -> None:
        """Check every field as a task file's ``[arm_angle]`` table is checked.

        Raises:
            InvalidArgumentError: naming the field and why (the table's own message).
        """
        try:
            checked = ArmAngleTable.model_validate({f.name: getattr(self, f.name) for f in fields(self)})
        except ValidationError as exc:
            first = exc.errors()[0]
            where = ".".join(str(part) for part in first["loc"]) or "arm_angle"
            raise InvalidArgumentError(where, first["msg"].removeprefix("Value error, ")) from None
        for f in fields(self):  # the table's values: tuples, floats
            object.__setattr__(self, f.name, getattr(checked, f.name))


class CarriedObject(_Model):
    """An object held by both hands (MC-Inverse section IV, eq 11).

    The slave hand's pose follows from the master's: T_slave = T_master * master_to_object *
    inverse(slave_to_object). ``size_m`` [m]: each within :data:`SIZE_RANGE_M`.
    """

    name: str = "box"
    size_m: tuple[Size, Size, Size]
    master: Literal["left", "right"]
    slave: Literal["left", "right"]
    master_to_object: Pose
    slave_to_object: Pose

    @model_validator(mode="after")
    def _two_hands(self) -> CarriedObject:
        if self.master == self.slave:
            raise ValueError("master and slave must be different hands")
        return self


class EnvironmentObject(_Model):
    """A fixed object of the scene.

    ``box`` needs ``size_m``; ``cylinder`` needs ``radius_m`` and ``height_m`` (axis along its z);
    ``sphere`` needs ``radius_m``. Every dimension [m] within :data:`SIZE_RANGE_M`, the pose's
    position within +-:data:`MAX_COORDINATE_M`.
    """

    name: str
    shape: Literal["box", "cylinder", "sphere"]
    pose: Pose
    size_m: tuple[Size, Size, Size] | None = None
    radius_m: Size | None = None
    height_m: Size | None = None

    @model_validator(mode="after")
    def _dimensions(self) -> EnvironmentObject:
        needed = {"box": ("size_m",), "cylinder": ("radius_m", "height_m"), "sphere": ("radius_m",)}[self.shape]
        for key in needed:
            if getattr(self, key) is None:
                raise ValueError(f"a {self.shape} needs {key}")
        return self


class WorkspaceTargetArea(_Model):
    """A Workspace Target Area (Li-Liang eqs 21-31).

    Attributes:
        hand: the hand it is for.
        reference: ^w T_WTA, the WTA frame in the robot base frame.
        offset: ^WTA T_e, the hand's offset in the WTA frame.
        bounds: ^WTA B_e, six [lower, upper] rows: x, y, z [m] (within +-:data:`MAX_COORDINATE_M`),
            roll, pitch, yaw [rad] (within +-:data:`MAX_ANGLE_RAD`).
        weight: sampling weight (normalised over a hand's WTAs, eq 31), within :data:`WEIGHT_RANGE`.
    """

    name: str
    hand: Literal["left", "right"]
    reference: Pose
    offset: Pose = Pose(position=(0.0, 0.0, 0.0))
    bounds: tuple[
        tuple[Coordinate, Coordinate],
        tuple[Coordinate, Coordinate],
        tuple[Coordinate, Coordinate],
        tuple[Angle, Angle],
        tuple[Angle, Angle],
        tuple[Angle, Angle],
    ]
    weight: Weight = 1.0

    @model_validator(mode="after")
    def _ordered(self) -> WorkspaceTargetArea:
        for row, (lo, hi) in zip(("x", "y", "z", "roll", "pitch", "yaw"), self.bounds, strict=True):
            if lo > hi:
                raise ValueError(f"bounds row {row}: lower {lo:g} above upper {hi:g}")
        return self


class Transfer(_Model):
    """What a task uses on a robot other than the one its ``initial`` and ``[gesture]`` are written for.

    The task runs on another robot with ``--robot``.

    Attributes:
        written_for: the ``name`` (in its robot.toml) of the robot ``initial`` and ``[gesture]`` are
            written for.
        initial: the initial configuration there: a home pose of that robot's ``robot.toml``
            (``"ready"``) or joint -> value [rad].
        gesture: TV-GDD's bounds there (``[gesture]`` names the first robot's joints); default none.
        limits: the limits there in place of ``[limits]`` (a paper's robot's limits are not
            another robot's); default none: that robot's own.
        duration_scale: every move's ``duration_s`` there is multiplied by this (in
            :data:`DURATION_SCALE_RANGE`, rounded to whole control periods), for a task whose
            paper gives no timing and whose pace asks more speed than other robots' joints have.
        arm_angle: the ``[arm_angle]`` table there (an arm angle held at the humanoid's ``initial`` value need not
            keep another robot's joints within their limits: ``mode = "auto"`` searches); default: ``[arm_angle]``.
    """

    written_for: str
    initial: str | JointValues
    gesture: Gesture | None = None
    limits: Limits = Limits()
    duration_scale: Annotated[float, FINITE, Range(*DURATION_SCALE_RANGE)] = 1.0
    arm_angle: ArmAngleTable | None = None


class TaskSpec(_Model):
    """A whole task file.

    Attributes:
        name: letters, digits, ``_`` and ``-``, at most :data:`MAX_NAME_CHARS` characters (it names
            the recordings directory).
        control_period_s: [s], within :data:`CONTROL_PERIOD_RANGE_S`.
        repetitions: 1 to :data:`MAX_REPETITIONS`.
        moves: at most :data:`MAX_MOVES`; environment and wta at most :data:`MAX_OBJECTS` each,
            expected_contacts at most :data:`MAX_CONTACT_PAIRS`.
        frame: the frame waypoints, ``by`` displacements and arcs are stated in: a link of the
            robot's URDF, or a role of :data:`FRAME_ROLES`, its pose taken at the initial
            configuration; None: the robot base frame. Objects, the environment and WTAs stay in
            the robot base frame.
        scale: ``"arm"``: positions relative to ``frame`` (and displacements) are multiplied by
            the driven arms' mean L2 + L3 over :data:`REFERENCE_ARM_M`; None: as written [m].
        transfer: the initial configuration (and TV-GDD bounds) on a robot other than the one
            ``initial`` and ``[gesture]`` are written for.
    """

    name: Annotated[str, Field(pattern=r"^[A-Za-z0-9_\-]+$", max_length=MAX_NAME_CHARS)]
    title: str = ""
    source: str = ""
    robot: str
    notes: str = ""
    control_period_s: Period
    repetitions: Repetitions = 1
    waist: Literal["locked", "free"] = "locked"
    initial: str | JointValues
    waypoints: dict[str, Pose] = {}
    start: Start
    moves: Annotated[tuple[Move, ...], Field(max_length=MAX_MOVES)] = ()
    limits: Limits = Limits()
    retime: Retime = Retime()
    ik: Ik = Ik()
    gesture: Gesture | None = None
    arm_angle: ArmAngleTable = ArmAngleTable()
    object: CarriedObject | None = None
    environment: Annotated[tuple[EnvironmentObject, ...], Field(max_length=MAX_OBJECTS)] = ()
    wta: Annotated[tuple[WorkspaceTargetArea, ...], Field(max_length=MAX_OBJECTS)] = ()
    expected_contacts: Annotated[tuple[tuple[str, str], ...], Field(max_length=MAX_CONTACT_PAIRS)] = ()
    frame: Annotated[str, Field(min_length=1)] | None = None
    scale: Literal["arm"] | None = None
    transfer: Transfer | None = None

    @property
    def hands(self) -> tuple[str, ...]:
        """The hands the task drives: those with a start pose, plus a carried object's slave."""
        hands = [h for h in ("left", "right") if getattr(self.start, h) is not None]
        if self.object is not None and self.object.slave not in hands:
            hands.append(self.object.slave)
        return tuple(h for h in ("left", "right") if h in hands)
