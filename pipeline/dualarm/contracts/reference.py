"""``CartesianReference``: what the hands should do, sample by sample."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import TYPE_CHECKING

import numpy as np

from dualarm.arrays import finite_array, frozen, rigid_transforms
from dualarm.errors import InvalidArgumentError

if TYPE_CHECKING:
    from dualarm.model.robot import Robot


#: The default of CartesianReference's t, rep and segment: derived from the period and the samples.
_UNSET = np.empty(0)


@dataclass(frozen=True)
class HandReference:
    """The reference of one hand over N samples, in the robot base frame.

    Attributes:
        position: hand frame origin (N, 3) [m].
        rotation: hand frame orientation (N, 3, 3).
        linear_velocity: d position / dt (N, 3) [m/s].
        angular_velocity: angular velocity in the base frame (N, 3) [rad/s].
    """

    position: np.ndarray
    rotation: np.ndarray
    linear_velocity: np.ndarray
    angular_velocity: np.ndarray

    def __post_init__(self) -> None:
        n = np.shape(self.position)[0] if np.ndim(self.position) else 0
        for name, shape in (
            ("position", (n, 3)),
            ("rotation", (n, 3, 3)),
            ("linear_velocity", (n, 3)),
            ("angular_velocity", (n, 3)),
        ):
            object.__setattr__(self, name, frozen(finite_array(getattr(self, name), name), shape, name))

    @property
    def poses(self) -> np.ndarray:
        """Homogeneous transforms (N, 4, 4) [m]."""
        T = np.zeros((len(self.position), 4, 4))
        T[:, :3, :3] = self.rotation
        T[:, :3, 3] = self.position
        T[:, 3, 3] = 1.0
        return T


@dataclass(frozen=True)
class CartesianReference:
    """What the hands should do, sample by sample.

    The output of the path stage, and the input of every IK method.

    Build one from a task (:func:`~dualarm.paths.build_reference`) or from sampled hand poses
    (:meth:`from_poses`).

    Attributes:
        period_s: sample period [s]; the IK methods step at it (it is the only control period).
        hands: reference per hand name (``left``/``right``).
        t: sample times (N,) [s]: ``arange(N) * period_s`` (the default).
        rep: repetition index of each sample (N,), 0-based (default all 0).
        segment: index of the task move each sample belongs to (N,), 0-based within a repetition;
            the first sample (the start pose) is segment 0 (default all 0).
        frame: the frame poses are expressed in, a link of the robot; "" (the default) is the
            robot's base frame, its root link.
        task: the task's name ("" when there is none).
    """

    period_s: float
    hands: Mapping[str, HandReference]
    t: np.ndarray = field(default_factory=lambda: _UNSET)
    rep: np.ndarray = field(default_factory=lambda: _UNSET)
    segment: np.ndarray = field(default_factory=lambda: _UNSET)
    frame: str = ""
    task: str = ""

    def __post_init__(self) -> None:
        _check_period(self.period_s)
        if not self.hands:
            raise InvalidArgumentError("hands", "a reference needs at least one hand")
        n = len(next(iter(self.hands.values())).position)
        for hand, ref in self.hands.items():
            if not isinstance(ref, HandReference):
                raise InvalidArgumentError(f"hands[{hand}]", f"expected a HandReference, got {type(ref).__name__}")
            if len(ref.position) != n:
                raise InvalidArgumentError(f"hands[{hand}]", f"{len(ref.position)} samples, another hand has {n}")
        uniform = np.arange(n) * float(self.period_s)
        t = uniform if self.t is _UNSET else finite_array(self.t, "t", (n,))
        if np.abs(t - uniform).max(initial=0.0) > 1e-9 * max(1.0, float(uniform[-1]) if n else 1.0):
            raise InvalidArgumentError(
                "t",
                f"sample times must be arange(N) * period_s ({self.period_s} "
                "s): the reference's period is its only control period",
            )
        object.__setattr__(self, "period_s", float(self.period_s))
        object.__setattr__(self, "t", frozen(t, (n,), "t"))
        object.__setattr__(self, "rep", frozen(np.zeros(n, int) if self.rep is _UNSET else self.rep, (n,), "rep", int))
        object.__setattr__(
            self, "segment", frozen(np.zeros(n, int) if self.segment is _UNSET else self.segment, (n,), "segment", int)
        )
        if n and ((np.diff(self.rep) < 0).any() or self.rep[0] < 0):
            raise InvalidArgumentError("rep", "repetition indices must start at 0 or more and never decrease")
        _check_repetitions(self.rep)
        object.__setattr__(self, "hands", MappingProxyType(dict(self.hands)))

    @classmethod
    def from_poses(
        cls,
        period_s: float,
        poses: Mapping[str, np.ndarray],
        *,
        rep: np.ndarray | None = None,
        frame: str = "",
    ) -> CartesianReference:
        """A reference from sampled hand poses, e.g. a path of one's own.

        Velocities are the poses' central differences (one-sided at the ends): the linear velocity
        d position / dt [m/s] and the angular velocity of R_{k+1} R_{k-1}^T over 2 periods [rad/s]
        (in the base frame).

        Args:
            period_s: sample period [s].
            poses: hand name -> (N, 4, 4) poses [m], in ``frame``.
            rep: repetition index per sample (N,) (default all 0): 0 for the start pose and the first repetition's
                samples, then each further repetition's samples (one fewer than the first's), as the path stage
                lays out a task's.
            frame: the frame the poses are in ("" = the robot's base frame).

        Raises:
            InvalidArgumentError: a pose array of the wrong shape, not rigid, with a NaN; hands with
                different sample counts; a non-positive period; repetitions with gaps, or after the first not of one
                sample fewer than it (the first also holds the start pose).
        """
        _check_period(period_s)
        hands = {}
        for hand, T in poses.items():
            T = rigid_transforms(T, f"poses[{hand}]", many=True)
            hands[hand] = HandReference(
                position=T[:, :3, 3],
                rotation=T[:, :3, :3],
                linear_velocity=_derivative(T[:, :3, 3], period_s),
                angular_velocity=_angular_velocity(T[:, :3, :3], period_s),
            )
        return cls(period_s=period_s, hands=hands, rep=_UNSET if rep is None else np.asarray(rep), frame=frame)

    def __len__(self) -> int:
        return len(self.t)

    @property
    def duration_s(self) -> float:
        """Time of the last sample [s]."""
        return float(self.t[-1])

    def frame_in(self, robot: Robot) -> str:
        """The link of ``robot`` the poses are in (its root link when :attr:`frame` is "").

        After checking that the robot has the reference's hands.

        Raises:
            InvalidArgumentError: the frame is no link of the robot, or a hand is not one of its hands.
        """
        frame = self.frame or robot.urdf.root
        if frame not in robot.urdf.links:
            raise InvalidArgumentError("reference.frame", f"robot '{robot.name}' has no link '{frame}'")
        for hand in self.hands:
            if hand not in robot.hands:
                raise InvalidArgumentError(
                    "reference.hands", f"robot '{robot.name}' has no hand '{hand}' (hands: {', '.join(robot.hands)})"
                )
        return frame


def _check_period(period_s: object) -> None:
    if (
        isinstance(period_s, bool)
        or not isinstance(period_s, (int, float, np.floating))
        or not (np.isfinite(period_s) and period_s > 0)
    ):
        raise InvalidArgumentError("period_s", f"must be a positive number of seconds, got {period_s!r}")


def _derivative(x: np.ndarray, period_s: float) -> np.ndarray:
    return np.gradient(x, period_s, axis=0) if len(x) > 1 else np.zeros_like(x)


def _angular_velocity(R: np.ndarray, period_s: float) -> np.ndarray:
    """Central-difference angular velocity (N, 3) [rad/s] of rotations R (N, 3, 3), base frame."""
    from scipy.spatial.transform import Rotation  # here: the contracts import numpy alone

    if len(R) < 2:
        return np.zeros((len(R), 3))
    after = np.concatenate([R[1:], R[-1:]])
    before = np.concatenate([R[:1], R[:-1]])
    steps = np.r_[1.0, np.full(len(R) - 2, 2.0), 1.0] * period_s
    return Rotation.from_matrix(after @ before.transpose(0, 2, 1)).as_rotvec() / steps[:, None]


def _check_repetitions(rep: np.ndarray) -> None:
    """Refuse a repetition layout whose samples cannot be matched with the first repetition's.

    The layout the path stage builds and every consistency measure reads: repetitions numbered without gaps, the
    first holding the start pose (t = 0) and the others one sample fewer, the same places of the motion.
    """
    values, counts = np.unique(rep, return_counts=True)
    if len(values) < 2:
        return
    if (np.diff(values) != 1).any():
        gap = int(values[np.flatnonzero(np.diff(values) != 1)[0]])
        raise InvalidArgumentError("rep", f"repetition {gap} is followed by {int(values[values > gap][0])}: no gaps")
    for value, count in zip(values[1:], counts[1:], strict=True):
        if count != counts[0] - 1:
            raise InvalidArgumentError(
                "rep",
                f"repetition {int(value)} has {int(count)} samples and the first {int(counts[0])}: each repetition "
                "after the first must have one sample fewer than the first, which also holds the start pose at t = 0",
            )


def time_in_repetition(t: np.ndarray, rep: np.ndarray) -> np.ndarray:
    """Time since the repetition began, per sample (N,) [s].

    For sample times ``t`` [s] and repetition indices ``rep``.

    Repetition r spans (r T, (r + 1) T] (the first also holds t = 0), so samples at the same place
    of every repetition get the same value.
    """
    period = t[rep == rep[0]][-1] - t[0]
    return t - t[0] - (rep - rep[0]) * period


def first_repetition_index(t: np.ndarray, rep: np.ndarray, period_s: float) -> np.ndarray:
    """Per sample, the index of the sample at the same place in the first repetition (N,)."""
    return np.rint(time_in_repetition(t, rep) / period_s).astype(int)
