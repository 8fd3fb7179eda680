"""``CartesianReference``: what the hands should do, sample by sample."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from pipeline.arrays import frozen


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
        n = np.shape(self.position)[0]
        for name, shape in (
            ("position", (n, 3)),
            ("rotation", (n, 3, 3)),
            ("linear_velocity", (n, 3)),
            ("angular_velocity", (n, 3)),
        ):
            object.__setattr__(self, name, frozen(getattr(self, name), shape, name))

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
    """The output of the path stage.

    Attributes:
        task: the task's name.
        frame: the frame poses are expressed in (the robot's root link).
        period_s: sample period [s].
        t: sample times (N,) [s], t[0] = 0, spaced by ``period_s``.
        rep: repetition index of each sample (N,), 0-based.
        segment: index of the task move each sample belongs to (N,), 0-based within a repetition;
            the first sample (the start pose) is segment 0.
        hands: reference per hand name (``left``/``right``).
    """

    task: str
    frame: str
    period_s: float
    t: np.ndarray
    rep: np.ndarray
    segment: np.ndarray
    hands: Mapping[str, HandReference]

    def __post_init__(self) -> None:
        n = np.shape(self.t)[0]
        object.__setattr__(self, "t", frozen(self.t, (n,), "t"))
        object.__setattr__(self, "rep", frozen(self.rep, (n,), "rep", int))
        object.__setattr__(self, "segment", frozen(self.segment, (n,), "segment", int))
        for hand, ref in self.hands.items():
            if len(ref.position) != n:
                raise ValueError(f"hand {hand}: {len(ref.position)} samples, t has {n}")
        object.__setattr__(self, "hands", MappingProxyType(dict(self.hands)))

    def __len__(self) -> int:
        return len(self.t)

    @property
    def duration_s(self) -> float:
        """Time of the last sample [s]."""
        return float(self.t[-1])


def time_in_repetition(t: np.ndarray, rep: np.ndarray) -> np.ndarray:
    """Time since the repetition began, per sample (N,) [s], for sample times ``t`` [s] and
    repetition indices ``rep``. Repetition r spans (r T, (r + 1) T] (the first also holds t = 0),
    so samples at the same place of every repetition get the same value."""
    period = t[rep == rep[0]][-1] - t[0]
    return t - t[0] - (rep - rep[0]) * period


def first_repetition_index(t: np.ndarray, rep: np.ndarray, period_s: float) -> np.ndarray:
    """Per sample, the index of the sample at the same place in the first repetition (N,)."""
    return np.rint(time_in_repetition(t, rep) / period_s).astype(int)
