"""Sinks: where the stages hand their products.

The pipeline never writes files itself; it tells a sink, and the sink decides what to keep.

- :class:`Sink`: the protocol. Each stage calls :meth:`Sink.begin` when it starts and hands its
  product once; the driver hands the run's metrics last.
- :class:`NullSink`: keeps nothing but when each stage began (``stage_seconds``): a run in memory.
- :class:`MetricsSink`: keeps the metrics too.
- :class:`Tee`: hands every product to several sinks; the :class:`~dualarm.record.recorder.Recorder` is a tee of
  the MCAP sink (``run.mcap``, for Foxglove) and the Rerun sink (``run.rrd``).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any, Literal, Protocol, get_args, runtime_checkable

import numpy as np

from dualarm.errors import InvalidArgumentError, excerpt

if TYPE_CHECKING:
    from dualarm.contracts.execution import ExecutionLog
    from dualarm.contracts.joint_path import JointPath
    from dualarm.contracts.reference import CartesianReference
    from dualarm.contracts.trajectory import JointTrajectory
    from dualarm.model.robot import Robot


@runtime_checkable
class Sink(Protocol):
    """What the stages hand their products to (see the module docstring)."""

    def begin(self, stage: str) -> None:
        """A stage starts (``record`` when the sink is about to be closed)."""

    def robot_state(self, stage: str, t: float, q: Mapping[str, float], rep: int = 0) -> None:
        """The robot at configuration ``q`` [rad] at motion time ``t`` [s]."""

    def environment(self, objects: Sequence[Any], carried: Any | None = None) -> None:
        """The task's fixed objects (:class:`~dualarm.tasks.schema.EnvironmentObject`), what the hands carry.

        ``carried``: a :class:`~dualarm.tasks.schema.CarriedObject`, or None.
        """

    def reference(self, ref: CartesianReference) -> None:
        """The path stage's product."""

    def joint_path(
        self, path: JointPath, velocity_limits: np.ndarray, arm_angles: Mapping[str, np.ndarray], stage: str = "ik"
    ) -> None:
        """The IK (or plan) stage's product, with the joints' velocity limits and each hand's arm angle.

        The velocity limits [rad/s]; the arm angle [rad] per sample.
        """

    def trajectory(
        self,
        traj: JointTrajectory,
        limits: Mapping[str, np.ndarray],
        hand_positions: Mapping[str, np.ndarray],
        extras: Mapping[str, np.ndarray] = ...,
    ) -> None:
        """A retime or smooth stage's product, its limits, the hands' positions and extra per-sample arrays.

        The limits: kind -> (n,); the hands' positions (M, 3) [m].
        """

    def execution(self, log: ExecutionLog) -> None:
        """The execute stage's product (with its approach's log, when the approach was played)."""

    def metrics(self, values: Mapping[str, float], t: float) -> None:
        """The run's metrics, at motion time ``t`` [s]."""


class NullSink:
    """A sink that records nothing.

    It notes when each stage began, so that :attr:`stage_seconds` gives each stage's wall time (the
    last one until :meth:`finish`).

    Args:
        on_begin: called with each stage's name as it begins (a progress display).
    """

    def __init__(self, on_begin: Callable[[str], None] | None = None) -> None:
        self._marks: list[tuple[str, float]] = []
        self._on_begin = on_begin

    def begin(self, stage: str) -> None:
        """Note the start of ``stage``."""
        self._marks.append((stage, time.perf_counter()))
        if self._on_begin is not None:
            self._on_begin(stage)

    def finish(self) -> None:
        """Note the end of the last stage."""
        self._marks.append(("", time.perf_counter()))

    @property
    def stage_seconds(self) -> dict[str, float]:
        """Wall time of each stage that began, from its start to the next one's (or to now) [s]."""
        marks = [*self._marks, ("", time.perf_counter())] if self._marks and self._marks[-1][0] else self._marks
        return {stage: end - start for (stage, start), (_, end) in zip(marks, marks[1:], strict=False)}

    def robot_state(self, stage: str, t: float, q: Mapping[str, float], rep: int = 0) -> None:
        """Ignored."""

    def environment(self, objects: Sequence[Any], carried: Any | None = None) -> None:
        """Ignored."""

    def reference(self, ref: CartesianReference) -> None:
        """Ignored."""

    def joint_path(
        self, path: JointPath, velocity_limits: np.ndarray, arm_angles: Mapping[str, np.ndarray], stage: str = "ik"
    ) -> None:
        """Ignored."""

    def trajectory(
        self,
        traj: JointTrajectory,
        limits: Mapping[str, np.ndarray],
        hand_positions: Mapping[str, np.ndarray],
        extras: Mapping[str, np.ndarray] = {},
    ) -> None:
        """Ignored."""

    def execution(self, log: ExecutionLog) -> None:
        """Ignored."""

    def metrics(self, values: Mapping[str, float], t: float) -> None:
        """Ignored."""

    def close(self, manifest: Mapping[str, object]) -> None:
        """Note the end of the last stage (a sink that writes files finishes them here)."""
        self.finish()


class MetricsSink(NullSink):
    """A sink that keeps only the run's metrics (:attr:`values`) and the stages' wall times."""

    def __init__(self, on_begin: Callable[[str], None] | None = None) -> None:
        super().__init__(on_begin)
        self.values: dict[str, float] = {}

    def metrics(self, values: Mapping[str, float], t: float) -> None:
        """Keep ``values``."""
        self.values.update(values)


#: How much of a run is recorded (``dualarm run --record``), besides ``manifest.json`` and
#: ``metrics.json``, which every run has (every stage runs and is judged whatever the level):
#:
#: - ``full``: ``run.mcap`` and ``run.rrd`` hold every stage's products.
#: - ``ik``: they hold the path stage's and the ik (or plan) stage's products only.
#: - ``metrics``: no ``run.mcap``, no ``run.rrd``.
RecordLevel = Literal["full", "ik", "metrics"]
RECORD_LEVELS: tuple[str, ...] = get_args(RecordLevel)
#: The stages whose products each level records (None: every stage).
_RECORDED: Mapping[str, tuple[str, ...] | None] = {"full": None, "ik": ("path", "ik", "plan"), "metrics": ()}


def record_level(level: str) -> str:
    """``level`` if it is one of :data:`RECORD_LEVELS`.

    Raises:
        InvalidArgumentError: another value (naming the levels).
    """
    if level not in _RECORDED:
        raise InvalidArgumentError(
            "record", f"unknown recording level '{excerpt(level)}' (levels: {', '.join(RECORD_LEVELS)})"
        )
    return level


#: The stages whose robot moves, in pipeline order (the approach, on its own clock, is not one).
MOTION_STAGES = ("path", "ik", "plan", "retime", "smooth", "execute")


def shown_stage(stages: Sequence[str]) -> str:
    """The stage a recording of ``stages`` is shown by: the last whose robot moves.

    ``execute`` when it ran; its robot is the one on ``/tf``.
    """
    return [s for s in MOTION_STAGES if s in stages][-1] if any(s in stages for s in MOTION_STAGES) else "path"


def recorded_stages(level: str, stages: Sequence[str]) -> tuple[str, ...]:
    """The stages of ``stages`` whose products a run recorded at ``level`` writes, in the order given.

    Raises:
        InvalidArgumentError: an unknown level.
    """
    kept = _RECORDED[record_level(level)]
    return tuple(s for s in stages if kept is None or s in kept)


class Tee(NullSink):
    """A sink that hands every product to each of ``sinks``, in order; it notes the stages' times itself.

    Args:
        sinks: the sinks (their own ``begin`` is not called).
        on_begin: called with each stage's name as it begins.
    """

    def __init__(self, *sinks: NullSink, on_begin: Callable[[str], None] | None = None) -> None:
        super().__init__(on_begin)
        self.sinks = sinks
        self._closed = False

    def robot_state(self, stage: str, t: float, q: Mapping[str, float], rep: int = 0) -> None:
        """Handed to each sink."""
        for sink in self.sinks:
            sink.robot_state(stage, t, q, rep)

    def environment(self, objects: Sequence[Any], carried: Any | None = None) -> None:
        """Handed to each sink."""
        for sink in self.sinks:
            sink.environment(objects, carried)

    def reference(self, ref: CartesianReference) -> None:
        """Handed to each sink."""
        for sink in self.sinks:
            sink.reference(ref)

    def joint_path(
        self, path: JointPath, velocity_limits: np.ndarray, arm_angles: Mapping[str, np.ndarray], stage: str = "ik"
    ) -> None:
        """Handed to each sink."""
        for sink in self.sinks:
            sink.joint_path(path, velocity_limits, arm_angles, stage)

    def trajectory(
        self,
        traj: JointTrajectory,
        limits: Mapping[str, np.ndarray],
        hand_positions: Mapping[str, np.ndarray],
        extras: Mapping[str, np.ndarray] = {},
    ) -> None:
        """Handed to each sink."""
        for sink in self.sinks:
            sink.trajectory(traj, limits, hand_positions, extras)

    def execution(self, log: ExecutionLog) -> None:
        """Handed to each sink."""
        for sink in self.sinks:
            sink.execution(log)

    def metrics(self, values: Mapping[str, float], t: float) -> None:
        """Handed to each sink."""
        for sink in self.sinks:
            sink.metrics(values, t)

    def close(self, manifest: Mapping[str, object]) -> None:
        """Close each sink once (a second call does nothing), then note the end of the last stage."""
        if self._closed:
            return
        self._closed = True
        for sink in self.sinks:
            sink.close(manifest)
        self.finish()


#: Colour of each hand's reference path.
HAND_COLORS = {"left": (40, 120, 230), "right": (230, 90, 40)}
#: Colour of each stage's hand traces, one per stage so that the traces tell apart where they part.
STAGE_COLORS = {
    "ik": (60, 170, 80),
    "plan": (60, 170, 80),
    "retime": (150, 90, 200),
    "smooth": (0, 170, 170),
    "approach": (150, 150, 150),
    "execute": (220, 40, 40),
}
#: Colour of an object both hands carry.
OBJECT_COLOR = (140, 115, 90)
#: Period of the robot's animation (/tf and the Rerun URDF) for stages sampled faster [s].
ANIMATION_PERIOD_S = 0.01


def animation_rows(t: np.ndarray) -> np.ndarray:
    """The samples of times ``t`` (N,) [s] a recording animates the robot at.

    Every :data:`ANIMATION_PERIOD_S` and the last.
    """
    stride = max(1, int(round(ANIMATION_PERIOD_S / float(np.median(np.diff(t))))) if len(t) > 1 else 1)
    return np.unique(np.r_[np.arange(0, len(t), stride), len(t) - 1])


def robot_box(robot: Robot) -> tuple[np.ndarray, float]:
    """Where the viewers' cameras look: the box around ``robot``'s link frames with every joint at 0.

    Its centre (3,) [m] in the robot's base frame (the viewers' world) and its largest side [m] (at least 0.1 m).
    """
    import casadi as cs  # not for every importer of the sinks

    from dualarm.model.kinematics import link_frames

    frames = link_frames(robot.urdf.joints, robot.urdf.root, {})
    points = np.array([np.asarray(cs.evalf(T))[:3, 3] for T in frames.values()])
    low, high = points.min(axis=0), points.max(axis=0)
    return (low + high) / 2, max(float((high - low).max()), 0.1)


#: The colours of the series of one plot, in order, in both viewers: matplotlib's tab10, then its lighter shades
#: (20 apart).
SERIES_COLORS = [
    (31, 119, 180),
    (255, 127, 14),
    (44, 160, 44),
    (214, 39, 40),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (127, 127, 127),
    (188, 189, 34),
    (23, 190, 207),
    (174, 199, 232),
    (255, 187, 120),
    (152, 223, 138),
    (255, 152, 150),
    (197, 176, 213),
    (196, 156, 148),
    (247, 182, 210),
    (199, 199, 199),
    (219, 219, 141),
    (158, 218, 229),
]

#: The narrowest value range a plot shows, per unit, so that a series constant up to rounding (MC-Inverse's held arm
#: angle spreads 2.7e-15 rad) is drawn as the flat line it is, not as noise filling the plot: [m], [rad], a ratio to a
#: limit, a count.
PLOT_FLOORS = {"m": 1e-4, "rad": 1e-3, "ratio": 0.1, "count": 1.0}
#: Room above and below a plot's values, a share of their range.
PLOT_PADDING = 0.05


def plot_range(logged: Sequence[tuple[float, float]], unit: str) -> tuple[float, float]:
    """The value range a plot shows of series whose values span ``logged`` (low, high each) in ``unit``.

    Their [lowest, highest] padded by :data:`PLOT_PADDING`, widened about its middle to the unit's floor
    (:data:`PLOT_FLOORS`); never below 0 when no value is (errors, counts, ratios).
    """
    low, high = min(r[0] for r in logged), max(r[1] for r in logged)
    floor = PLOT_FLOORS[unit]
    middle, half = (low + high) / 2, max((high - low) * (1 + 2 * PLOT_PADDING), floor) / 2
    bottom = middle - half
    if low >= 0 > bottom:
        bottom = 0.0
    return bottom, bottom + 2 * half


def extend_range(ranges: dict[str, tuple[float, float]], key: str, values: np.ndarray) -> None:
    """Widen ``ranges[key]`` (low, high) to the finite ``values``; none: unchanged."""
    finite = np.asarray(values, dtype=float)
    finite = finite[np.isfinite(finite)]
    if finite.size:
        low, high = ranges.get(key, (np.inf, -np.inf))
        ranges[key] = (min(low, float(finite.min())), max(high, float(finite.max())))


def carried_poses(carried: Any | None, hand_poses: Mapping[str, np.ndarray]) -> np.ndarray | None:
    """The pose of the object both hands carry (K, 4, 4) [m], from its master hand's ``hand_poses``.

    ``hand_poses``: hand -> (K, 4, 4) [m].

    T_object = T_master ^{T_master}T_object (MC-Inverse, eq 11); None without a carried object or that hand's poses.
    ``carried``: a :class:`~dualarm.tasks.schema.CarriedObject`.
    """
    from dualarm.model.poses import pose_matrix  # scipy: not for every importer of the sinks

    if carried is None or carried.master not in hand_poses:
        return None
    offset = pose_matrix(carried.master_to_object.position, carried.master_to_object.rpy)
    return np.asarray(hand_poses[carried.master]) @ offset
