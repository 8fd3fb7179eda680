"""The schema of a task file, as frozen pydantic models (unknown keys are errors).

Units are in the key names: ``_s`` seconds, ``_m`` metres, ``_rad`` radians. Poses are a position
[m] and roll-pitch-yaw [rad], extrinsic x-y-z (R = Rz Ry Rx), in the robot base frame.
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, StrictBool, model_validator

Float = Annotated[float, Field(strict=True, allow_inf_nan=False)]
PositiveFloat = Annotated[float, Field(strict=True, gt=0, allow_inf_nan=False)]
Vec3 = tuple[Float, Float, Float]
JointValues = dict[str, Float]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Pose(_Model):
    """A pose: ``position`` [m] and ``rpy`` [rad] (R = Rz(yaw) Ry(pitch) Rx(roll))."""

    position: Vec3
    rpy: Vec3 = (0.0, 0.0, 0.0)


class HandMove(_Model):
    """What one hand does during a move; exactly one of ``to``, ``by``, ``arc_*`` or ``hold``.

    - ``to``: straight line to a named waypoint, orientation by slerp.
    - ``by``: straight line by a displacement [m], orientation kept.
    - ``arc_center`` [m], ``arc_axis`` (unit normal of the circle's plane, right-hand rule) and
      ``arc_angle_rad``: arc about the centre, orientation kept.
    - ``hold = true``: stay still.
    """

    to: str | None = None
    by: Vec3 | None = None
    arc_center: Vec3 | None = None
    arc_axis: Vec3 | None = None
    arc_angle_rad: Float | None = None
    hold: bool | None = None

    @model_validator(mode="after")
    def _one_kind(self) -> "HandMove":
        arc = (self.arc_center, self.arc_axis, self.arc_angle_rad)
        if any(v is not None for v in arc) and not all(v is not None for v in arc):
            raise ValueError("an arc needs arc_center, arc_axis and arc_angle_rad")
        kinds = [self.to is not None, self.by is not None, self.arc_center is not None, bool(self.hold)]
        if sum(kinds) != 1:
            raise ValueError("give exactly one of to, by, arc_center/arc_axis/arc_angle_rad, hold = true")
        if self.arc_axis is not None and sum(v * v for v in self.arc_axis) == 0:
            raise ValueError("arc_axis must not be zero")
        return self

    @property
    def kind(self) -> str:
        """``to``, ``by``, ``arc`` or ``hold``."""
        if self.to is not None:
            return "to"
        if self.by is not None:
            return "by"
        return "arc" if self.arc_center is not None else "hold"


class Move(_Model):
    """One segment of the path: every driven hand moves for ``duration_s`` with a smooth time scaling (zero velocity and acceleration at both ends).

    A driven hand not named holds still.
    """

    duration_s: PositiveFloat
    left: HandMove | None = None
    right: HandMove | None = None

    def for_hand(self, hand: str) -> HandMove | None:
        """The move of ``hand``, or None if it is not named."""
        return getattr(self, hand)


class Start(_Model):
    """Start pose of each driven hand: a waypoint name, or ``"initial"`` for the pose the hand has at the task's initial configuration."""

    left: str | None = None
    right: str | None = None


class Limits(_Model):
    """Task-specific joint limits that replace the robot's: a number for every joint, or a table joint -> value."""

    velocity: PositiveFloat | dict[str, PositiveFloat] | None = None
    acceleration: PositiveFloat | dict[str, PositiveFloat] | None = None


class Retime(_Model):
    """How the retime stage times the joint path.

    Attributes:
        timing: ``optimal``: time-optimal within the limits (TOPP-RA); ``task``: the task's own
            timing (its moves' durations), checked against the limits.
        velocity_fraction / acceleration_fraction: for ``optimal``, the share of the velocity and
            acceleration limits TOPP-RA may use. The rest is the smooth stage's headroom: a
            time-optimal profile switches its acceleration instantly (an infinite jerk), and a
            jerk-limited tracker lags behind each switch; with headroom it catches up. The
            reported ratios are always against the full limits.
    """

    timing: Literal["optimal", "task"] = "optimal"
    velocity_fraction: Annotated[float, Field(strict=True, gt=0, le=1, allow_inf_nan=False)] = 0.9
    acceleration_fraction: Annotated[float, Field(strict=True, gt=0, le=1, allow_inf_nan=False)] = 0.3


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
        t_sp_s: switching time T_SP = T_d / N [s].
        c_tuning: time-tuning parameter, 0 < c <= 1.
        nu: bound-to-velocity scaling nu of eq (21).
        feedback_gain: position-error feedback K of eq (16) [1/s].
        bound_feedforward: add each bound's own rate to eq (21) so joints pressed against a closing
            bound stay inside it (not in the paper; see TvgddSettings).
        goal_lower / goal_upper: theta_goal- / theta_goal+ per joint [rad]; a joint whose two goals
            are equal is a gesture joint driven to that value.
    """

    t_sp_s: PositiveFloat
    c_tuning: Annotated[float, Field(strict=True, gt=0, le=1, allow_inf_nan=False)]
    nu: PositiveFloat
    feedback_gain: PositiveFloat
    bound_feedforward: StrictBool = False
    goal_lower: JointValues
    goal_upper: JointValues

    @model_validator(mode="after")
    def _bounds_do_not_cross(self) -> "Gesture":
        # with the feedforward the band of eq (19) may shrink at most at the relative rate nu;
        # it shrinks at up to 1 / c_tuning
        if self.bound_feedforward and self.nu * self.c_tuning <= 1:
            raise ValueError(f"bound_feedforward needs nu * c_tuning > 1 (here {self.nu * self.c_tuning:g}), or the lower and upper bounds cross")
        return self


class ArmAngle(_Model):
    """How MC-Inverse picks the arm angle psi of eq (1) along the path (Zou, Min, Xu, section III.B).

    Attributes:
        mode: ``initial``: psi of the initial configuration, held; ``constant``: ``value_rad``;
            ``schedule``: ``schedule`` interpolated linearly in the time since the repetition
            began; ``auto``: the branch and psi profile of least joint and arm-angle travel that
            stays inside the joint limits (``margin_rad`` from them where it can) and within
            ``range_rad``, the same in every repetition (see ``mc_path._auto``). Each is a function of
            the pose and its place in the repetition, not of the history, so repeated passes
            give the same joints.
        value_rad: psi per hand for ``constant`` [rad].
        schedule: per hand, (time within a repetition [s], psi [rad]) pairs, times increasing.
        vertical: the vertical vector V of the reference plane, in the arm's base frame.
        max_joint_step_rad: largest joint change between samples before the path fails [rad].
        margin_rad: for ``auto``, the distance to the joint limits to keep [rad].
        range_rad: for ``auto``, the open interval psi must stay in [rad] (the MC-Inverse paper keeps
            it in (-pi, 0) for human-like motion).
    """

    mode: Literal["initial", "constant", "schedule", "auto"] = "initial"
    value_rad: dict[Literal["left", "right"], Float] = {}
    schedule: dict[Literal["left", "right"], tuple[tuple[Float, Float], ...]] = {}
    vertical: Vec3 = (0.0, 0.0, 1.0)
    max_joint_step_rad: PositiveFloat = 0.2
    margin_rad: Annotated[float, Field(strict=True, ge=0, allow_inf_nan=False)] = 0.05
    range_rad: tuple[Float, Float] = (-math.pi, math.pi)

    @model_validator(mode="after")
    def _complete(self) -> "ArmAngle":
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
                if not points or any(b <= a for a, b in zip(times, times[1:])):
                    raise ValueError(f"schedule.{hand}: times must increase")
        if sum(v * v for v in self.vertical) == 0:
            raise ValueError("vertical must not be zero")
        return self


class CarriedObject(_Model):
    """An object held by both hands (MC-Inverse section IV, eq 11).

    The slave hand's pose follows from the master's: T_slave = T_master * master_to_object *
    inverse(slave_to_object).
    """

    name: str = "box"
    size_m: tuple[PositiveFloat, PositiveFloat, PositiveFloat]
    master: Literal["left", "right"]
    slave: Literal["left", "right"]
    master_to_object: Pose
    slave_to_object: Pose

    @model_validator(mode="after")
    def _two_hands(self) -> "CarriedObject":
        if self.master == self.slave:
            raise ValueError("master and slave must be different hands")
        return self


class EnvironmentObject(_Model):
    """A fixed object of the scene.

    ``box`` needs ``size_m``; ``cylinder`` needs ``radius_m`` and ``height_m`` (axis along its z);
    ``sphere`` needs ``radius_m``.
    """

    name: str
    shape: Literal["box", "cylinder", "sphere"]
    pose: Pose
    size_m: tuple[PositiveFloat, PositiveFloat, PositiveFloat] | None = None
    radius_m: PositiveFloat | None = None
    height_m: PositiveFloat | None = None

    @model_validator(mode="after")
    def _dimensions(self) -> "EnvironmentObject":
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
        bounds: ^WTA B_e, six [lower, upper] rows: x, y, z [m], roll, pitch, yaw [rad].
        weight: sampling weight (normalised over a hand's WTAs, eq 31).
    """

    name: str
    hand: Literal["left", "right"]
    reference: Pose
    offset: Pose = Pose(position=(0.0, 0.0, 0.0))
    bounds: tuple[tuple[Float, Float], tuple[Float, Float], tuple[Float, Float], tuple[Float, Float], tuple[Float, Float], tuple[Float, Float]]
    weight: PositiveFloat = 1.0

    @model_validator(mode="after")
    def _ordered(self) -> "WorkspaceTargetArea":
        for row, (lo, hi) in zip(("x", "y", "z", "roll", "pitch", "yaw"), self.bounds):
            if lo > hi:
                raise ValueError(f"bounds row {row}: lower {lo} above upper {hi}")
        return self


class TaskSpec(_Model):
    """A whole task file."""

    name: Annotated[str, Field(pattern=r"^[A-Za-z0-9_\-]+$")]
    title: str = ""
    source: str = ""
    robot: str
    notes: str = ""
    control_period_s: PositiveFloat
    repetitions: Annotated[int, Field(strict=True, ge=1)] = 1
    waist: Literal["locked", "free"] = "locked"
    initial: str | JointValues
    waypoints: dict[str, Pose] = {}
    start: Start
    moves: tuple[Move, ...] = ()
    limits: Limits = Limits()
    retime: Retime = Retime()
    ik: Ik = Ik()
    gesture: Gesture | None = None
    arm_angle: ArmAngle = ArmAngle()
    object: CarriedObject | None = None
    environment: tuple[EnvironmentObject, ...] = ()
    wta: tuple[WorkspaceTargetArea, ...] = ()
    expected_contacts: tuple[tuple[str, str], ...] = ()

    @property
    def hands(self) -> tuple[str, ...]:
        """The hands the task drives: those with a start pose, plus a carried object's slave."""
        hands = [h for h in ("left", "right") if getattr(self.start, h) is not None]
        if self.object is not None and self.object.slave not in hands:
            hands.append(self.object.slave)
        return tuple(h for h in ("left", "right") if h in hands)
