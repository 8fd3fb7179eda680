"""``JointPath``: the output of an IK stage."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Literal, get_args

import numpy as np

from dualarm.arrays import frozen
from dualarm.errors import InvalidArgumentError, excerpt

#: Per-sample solver status codes.
OK, FAILED = 0, 1

#: What an IK method solves: the hands' whole ``pose``, or their ``position`` only.
TaskSpace = Literal["pose", "position"]
TASK_SPACES: tuple[str, ...] = get_args(TaskSpace)


def check_task_space(task_space: object) -> None:
    """Refuse a task space not in :data:`TASK_SPACES` (an InvalidArgumentError naming ``task_space``)."""
    if task_space not in TASK_SPACES:
        raise InvalidArgumentError(
            "task_space", f"unknown task space '{excerpt(task_space)}' (task spaces: {', '.join(TASK_SPACES)})"
        )


#: The default of ``hand_orientation_error_rad``: not measured (NaN), e.g. a planner's path, which follows no reference.
_NOT_MEASURED = np.empty(0)


@dataclass(frozen=True)
class JointPath:
    """Joint positions that realise a Cartesian reference, sample by sample.

    Attributes:
        method: the IK method (``tvgdd``, ``pinv``, ...).
        joint_names: the active joints, the columns of ``q``.
        t: sample times (N,) [s].
        rep: repetition index (N,).
        q: joint positions (N, n) [rad].
        qd: joint velocities the method commanded (N, n) [rad/s]; zeros for position-level methods.
        status: per-sample solver status (N,): 0 ok, 1 failed.
        solve_time_s: per-sample solve time (N,) [s].
        hand_error_m: per-sample hand position error |r - f(q)| per hand (N, h) [m].
        hands: the hands, the columns of ``hand_error_m``.
        hand_orientation_error_rad: per-sample hand orientation error, the angle of
            R_asked^T R_reached per hand (N, h) [rad]; NaN where not measured (the default).
        task_space: what the method solved: ``pose`` (the hands' positions and orientations) or
            ``position`` (positions only; the orientation error is measured, not asked for).
        fixed: values of the robot's locked joints [rad].
        extras: method-specific per-sample arrays (N, n), e.g. TV-GDD bounds.
        chosen: what the method chose along the path beyond the joints, JSON-ready (MC-Inverse's
            ``arm_angle_profile``); a run's manifest records it with the method's settings.
    """

    method: str
    joint_names: tuple[str, ...]
    t: np.ndarray
    rep: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    status: np.ndarray
    solve_time_s: np.ndarray
    hand_error_m: np.ndarray
    hands: tuple[str, ...]
    hand_orientation_error_rad: np.ndarray = field(default_factory=lambda: _NOT_MEASURED)
    task_space: TaskSpace = "pose"
    fixed: Mapping[str, float] = field(default_factory=dict)
    extras: Mapping[str, np.ndarray] = field(default_factory=dict)
    chosen: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        N, n = len(self.t), len(self.joint_names)
        if self.hand_orientation_error_rad is _NOT_MEASURED:
            object.__setattr__(self, "hand_orientation_error_rad", np.full((N, len(self.hands)), np.nan))
        check_task_space(self.task_space)
        for name, shape, dtype in (
            ("t", (N,), float),
            ("rep", (N,), int),
            ("q", (N, n), float),
            ("qd", (N, n), float),
            ("status", (N,), int),
            ("solve_time_s", (N,), float),
            ("hand_error_m", (N, len(self.hands)), float),
            ("hand_orientation_error_rad", (N, len(self.hands)), float),
        ):
            object.__setattr__(self, name, frozen(getattr(self, name), shape, name, dtype))
        object.__setattr__(self, "extras", MappingProxyType({k: frozen(v, (N, n), k) for k, v in self.extras.items()}))
        object.__setattr__(self, "fixed", MappingProxyType(dict(self.fixed)))
        object.__setattr__(self, "chosen", MappingProxyType(dict(self.chosen)))

    @classmethod
    def of_positions(
        cls,
        method: str,
        joint_names: tuple[str, ...],
        t: np.ndarray,
        q: np.ndarray,
        rep: np.ndarray | None = None,
        fixed: Mapping[str, float] | None = None,
    ) -> JointPath:
        """Joint positions ``q`` (N, n) [rad] at times ``t`` (N,) [s] alone: every sample solved, no hands.

        No velocities commanded and no solve times; ``rep`` 0 for every sample unless given.
        """
        N = len(t)
        return cls(
            method=method,
            joint_names=joint_names,
            t=t,
            rep=np.zeros(N, dtype=int) if rep is None else rep,
            q=q,
            qd=np.zeros(np.shape(q)),
            status=np.zeros(N, dtype=int),
            solve_time_s=np.zeros(N),
            hand_error_m=np.zeros((N, 0)),
            hands=(),
            fixed=fixed or {},
        )

    def __len__(self) -> int:
        return len(self.t)

    def configuration(self, k: int) -> dict[str, float]:
        """Every robot joint at sample ``k`` (active and locked) [rad]."""
        return {**self.fixed, **dict(zip(self.joint_names, self.q[k].tolist(), strict=True))}
