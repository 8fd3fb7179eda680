"""A study's spec (``SPEC.toml``): which robot and methods, how many trials, and the distributions.

The distributions the trials' tasks are drawn from.

A study asks the MC-Inverse paper's open question (section VI): under what conditions, and how
often, does motion become inconsistent when an arm repeats a motion to the same targets? Each
trial is one generated repeated-motion task (:mod:`dualarm.study.trials`), run by every method;
a method's trial is inconsistent when its joints differ between repetitions by more than
``[inconsistent] joint_deviation_rad``, or (``failed_repetition``) when a repetition fails.

Every number has a range, and a range is ``[low, high]`` with low <= high; a mistake is one line
naming the key (:class:`dualarm.errors.TaskFileError`, exit code 2), as for a task file. Positions
are in the drawing hand's shoulder frame (the S-R-S shoulder centre, the robot base frame's axes)
and in arm lengths of the shipped humanoid (the task files' ``frame = "<hand>.shoulder"``,
``scale = "arm"``), so one spec draws the same shapes, in proportion, on any robot; ``y`` is for the
left hand and mirrored for the right.

Units: [m], [rad], [s].
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Annotated, Literal

from pydantic import Field, ValidationError, model_validator

from dualarm.errors import TaskFileError, excerpt
from dualarm.methods import IK_METHODS
from dualarm.tasks.schema import CONTROL_PERIOD_RANGE_S, FINITE, MAX_NAME_CHARS, Pose, Range, Size, _Model

#: Most trials one study may draw.
MAX_TRIALS = 1_000_000
#: A shape's size (its circumradius) [m], in the humanoid's arm lengths.
SIZE_RANGE_M = (0.005, 0.5)
#: Repetitions per trial.
REPETITIONS_RANGE = (2, 100)
#: One repetition's duration [s].
PERIOD_RANGE_S = (0.5, 120.0)

Metres = Annotated[float, FINITE, Range(-1.0, 1.0, " m")]
Radians = Annotated[float, FINITE, Range(-3.2, 3.2, " rad")]


def _ordered(pair: tuple[float, float], key: str) -> None:
    if pair[0] > pair[1]:
        raise ValueError(f"{key}: the low end {pair[0]:g} is above the high end {pair[1]:g}")


class Shape(_Model):
    """The closed shapes a trial's hand draws, each repetition once around.

    Attributes:
        kinds: drawn uniformly from these: ``polygon`` (straight edges, the hand's orientation
            changing at the vertices), ``circle``, ``figure-eight`` (two circles of half the size,
            through the centre).
        vertices: a polygon's number of vertices, [low, high] (uniform integer).
        size_m: the circumradius [m], [low, high] (uniform).
        tilt_rad: the shape's plane is the y-z plane (facing forward) turned about a random
            horizontal axis by up to this [rad].
    """

    kinds: tuple[Literal["polygon", "circle", "figure-eight"], ...] = ("polygon", "circle", "figure-eight")
    vertices: tuple[
        Annotated[int, Field(strict=True), Range(3, 6)], Annotated[int, Field(strict=True), Range(3, 6)]
    ] = (3, 6)
    size_m: tuple[
        Annotated[float, FINITE, Range(*SIZE_RANGE_M, " m")], Annotated[float, FINITE, Range(*SIZE_RANGE_M, " m")]
    ] = (0.05, 0.15)
    tilt_rad: Annotated[float, FINITE, Range(0.0, 1.6, " rad")] = 0.5

    @model_validator(mode="after")
    def _check(self) -> Shape:
        if not self.kinds:
            raise ValueError("kinds: name at least one of polygon, circle, figure-eight")
        _ordered(self.vertices, "vertices")
        _ordered(self.size_m, "size_m")
        return self


class Centre(_Model):
    """Where a shape's centre is drawn (uniformly in a box), in the drawing hand's shoulder frame [m].

    See the module docstring.

    Attributes:
        x, y, z: the box, [low, high] each [m].
        reachable: draw the trial again (up to :data:`~dualarm.study.trials.MAX_DRAWS` times)
            until every pose of its shape is within reach of the arm: the analytic S-R-S solution
            (MC-Inverse's) is inside the joint limits for some arm angle of a 5 degree
            grid and some branch (:func:`~dualarm.study.trials.within_reach`); so the box holds the
            reachable workspace's part. Needs S-R-S arms; ``false`` keeps every first draw.
    """

    x: tuple[Metres, Metres] = (0.25, 0.40)
    y: tuple[Metres, Metres] = (-0.15, 0.10)
    z: tuple[Metres, Metres] = (-0.40, -0.15)
    reachable: bool = True

    @model_validator(mode="after")
    def _check(self) -> Centre:
        for key in ("x", "y", "z"):
            _ordered(getattr(self, key), key)
        return self


class Orientation(_Model):
    """The hand's orientation along a trial's shape.

    Attributes:
        rpy: the base orientation, extrinsic x-y-z Euler angles [rad] (the circle task's, hand
            pointing forward, by default).
        change: drawn per trial: ``held`` (the base orientation everywhere) or ``changing`` (each
            polygon vertex turned from the base by up to ``change_rad`` about each axis; circles
            and figure-eights hold theirs).
        change_rad: the largest turn about each axis [rad].
    """

    rpy: tuple[Radians, Radians, Radians] = (-1.571, 1.571, -1.571)
    change: tuple[Literal["held", "changing"], ...] = ("held", "changing")
    change_rad: Annotated[float, FINITE, Range(0.0, 1.6, " rad")] = 0.3

    @model_validator(mode="after")
    def _check(self) -> Orientation:
        if not self.change:
            raise ValueError("change: name at least one of held, changing")
        return self


class Carry(_Model):
    """A master-slave carry, the trials whose ``hands`` draw is ``both``.

    MC-Inverse section IV, eq (11); the carry_box task's grasp by default.

    The left (master) hand draws the trial's shape as the left hand alone would (its centre in the
    left shoulder's frame, ``[centre]``), and the right (slave) hand holds a box with it: its pose
    follows the master's by eq (11), T_slave = T_master master_to_object inverse(slave_to_object).

    Attributes:
        rpy: the master hand's base orientation, extrinsic x-y-z Euler angles [rad], in place of
            ``[orientation] rpy`` (palm facing right, onto the box, by default). With ``changing``
            orientation each polygon vertex turns it, and the box and the slave hand turn with it.
        size_m: the box [m].
        master_to_object, slave_to_object: the box's pose in each hand's frame (eq (11)'s
            ^{T_l}T_obj and ^{T_r}T_obj) [m], [rad]; not scaled by the arm's length.
    """

    rpy: tuple[Radians, Radians, Radians] = (1.5707963267948966, 0.0, 0.0)
    size_m: tuple[Size, Size, Size] = (0.15, 0.24, 0.15)
    master_to_object: Pose = Pose(position=(0.0, 0.0, 0.12), rpy=(-1.5707963267948966, 0.0, 0.0))
    slave_to_object: Pose = Pose(position=(0.0, 0.0, 0.12), rpy=(1.5707963267948966, 0.0, 0.0))


class Inconsistent(_Model):
    """When a method's trial counts as inconsistent.

    Attributes:
        joint_deviation_rad: its largest joint difference between repetitions at the same point
            of the path above this [rad] (``ik.rep_joint_deviation_max_rad``).
        failed_repetition: a repetition with a failed IK sample counts too.
    """

    joint_deviation_rad: Annotated[float, FINITE, Range(0.0, 6.3, " rad", low_open=True)] = 0.01
    failed_repetition: bool = True


class StudySpec(_Model):
    """A study's spec file (module docstring).

    Attributes:
        name: the study's name (letters, digits, ``_`` and ``-``).
        robot: a robot directory (relative to the spec file) or a shipped robot's name.
        methods: the IK methods every trial runs.
        trials: how many trials.
        seed: the trials' seed: the same spec and seed give the same trials on any machine.
        hands: drawn uniformly per trial: the hand that draws (``left``, ``right``), or ``both``:
            the left draws and the right carries a box with it (:class:`Carry`).
        repetitions: [low, high] (uniform integer).
        period_s: one repetition's duration [s], [low, high] (uniform, rounded to the control period).
        control_period_s: the generated tasks' control period [s].
    """

    name: Annotated[str, Field(pattern=r"^[A-Za-z0-9_\-]+$", max_length=MAX_NAME_CHARS)]
    robot: Annotated[str, Field(min_length=1, max_length=4096)] = "humanoid"
    methods: tuple[str, ...] = IK_METHODS
    trials: Annotated[int, Field(strict=True), Range(1, MAX_TRIALS)]
    seed: Annotated[int, Field(strict=True), Range(0, 2**63 - 1)] = 0
    hands: tuple[Literal["left", "right", "both"], ...] = ("left", "right")
    repetitions: tuple[
        Annotated[int, Field(strict=True), Range(*REPETITIONS_RANGE)],
        Annotated[int, Field(strict=True), Range(*REPETITIONS_RANGE)],
    ] = (5, 20)
    period_s: tuple[
        Annotated[float, FINITE, Range(*PERIOD_RANGE_S, " s")], Annotated[float, FINITE, Range(*PERIOD_RANGE_S, " s")]
    ] = (3.0, 6.0)
    control_period_s: Annotated[float, FINITE, Range(*CONTROL_PERIOD_RANGE_S, " s")] = 0.01
    shape: Shape = Shape()
    centre: Centre = Centre()
    orientation: Orientation = Orientation()
    carry: Carry = Carry()
    inconsistent: Inconsistent = Inconsistent()

    @model_validator(mode="after")
    def _check(self) -> StudySpec:
        if not self.methods:
            raise ValueError("methods: name at least one IK method")
        for name in self.methods:
            if name not in IK_METHODS:
                raise ValueError(
                    f"methods: '{excerpt(name, 40)}' is not an IK method (methods: {', '.join(IK_METHODS)})"
                )
        if len(set(self.methods)) != len(self.methods):
            raise ValueError("methods: a method is named twice")
        if not self.hands:
            raise ValueError("hands: name at least one of left, right, both")
        if "\0" in self.robot:
            raise ValueError("robot: a robot directory or name cannot hold a NUL byte")
        _ordered(self.repetitions, "repetitions")
        _ordered(self.period_s, "period_s")
        return self


def load_study(path: str | Path) -> tuple[StudySpec, Path]:
    """Read and validate a study spec file: the spec and the directory its ``robot`` is relative to.

    Raises:
        TaskFileError: one line, ``file:key`` and the cause (or the OS's reason the file cannot be read).
    """
    from dualarm.tasks.parse import _read, _validation_message

    file = Path(path)
    if not file.is_file():
        raise TaskFileError(f"{excerpt(file)}: no such study spec file")
    _, data = _read(file)
    try:
        return StudySpec.model_validate(data), file.parent
    except ValidationError as exc:
        raise TaskFileError(_validation_message(str(file), exc, data)) from None


def study_from_toml(text: str, where: str = "<spec>") -> StudySpec:
    """A spec from TOML text (tests, notebooks); errors as :func:`load_study`'s, naming ``where``."""
    from dualarm.tasks.parse import _validation_message

    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise TaskFileError(f"{where}: not valid TOML: {exc}") from None
    try:
        return StudySpec.model_validate(data)
    except ValidationError as exc:
        raise TaskFileError(_validation_message(where, exc, data)) from None
