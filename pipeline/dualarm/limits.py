"""Joint limits: the one place where per-joint limits are validated and limit ratios are taken.

A limit ratio is |x_j(t)| / limit_j: 1 is at the limit, and a run whose ratio exceeds
1 + :data:`LIMIT_TOLERANCE` breaks it. The retime and smooth stages, their checks and the task's
limit overrides all go through :func:`per_joint` and :func:`limit_ratios`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from dualarm.errors import InvalidArgumentError, StageError

#: The kinds of joint limit and their units.
UNITS = {"velocity": "rad/s", "acceleration": "rad/s^2", "jerk": "rad/s^3"}
#: Relative excess over a limit that still counts as within it (rounding).
LIMIT_TOLERANCE = 1e-6


def per_joint(values: Any, joint_names: Sequence[str], kind: str, stage: str) -> np.ndarray:
    """``values`` as one positive finite ``kind`` limit per joint (n,); a scalar applies to every joint.

    Args:
        values: a number, or one number per joint.
        joint_names: the joints, in order.
        kind: ``velocity``, ``acceleration`` or ``jerk``.
        stage: the stage asking, for the message.

    Raises:
        InvalidArgumentError: (``argument`` = ``kind``) a wrong number of limits, or one that is not
            a positive finite number, naming the joint and the stage.
    """
    unit = UNITS[kind]
    try:
        limits = np.broadcast_to(np.asarray(values, dtype=float), (len(joint_names),)).copy()
    except (TypeError, ValueError):
        raise InvalidArgumentError(
            kind,
            f"{stage} expected {len(joint_names)} limits (one per "
            f"joint: {', '.join(joint_names)}), got {np.shape(values)}",
        ) from None
    bad = np.flatnonzero(~(np.isfinite(limits) & (limits > 0)))
    if len(bad):
        j = int(bad[0])
        raise InvalidArgumentError(
            kind,
            f"the limit of joint {j} ({joint_names[j]}) is {float(limits[j])!r} "
            f"{unit} in {stage}; every limit must be a positive finite number",
            joint=joint_names[j],
        )
    return limits


@dataclass(frozen=True)
class LimitRatio:
    """The largest ratio of one kind over a trajectory's samples.

    Attributes:
        kind: ``velocity``, ``acceleration`` or ``jerk``.
        ratio: the largest |x_j| / limit_j over samples and joints (0 for no samples).
        joint: the joint where it occurs ("" for no samples).
        t_s: the time of the sample where it occurs [s] (0 for no samples).
    """

    kind: str
    ratio: float
    joint: str
    t_s: float

    @property
    def exceeded(self) -> bool:
        """Whether the ratio is above 1 + :data:`LIMIT_TOLERANCE`."""
        return self.ratio > 1 + LIMIT_TOLERANCE


def limit_ratios(
    t: np.ndarray, joint_names: Sequence[str], samples: Mapping[str, np.ndarray], limits: Mapping[str, Any], stage: str
) -> dict[str, LimitRatio]:
    """The largest limit ratio of each kind.

    Args:
        t: sample times (M,) [s].
        joint_names: the joints, the columns of the samples.
        samples: kind -> (M, n) values (velocities [rad/s], accelerations [rad/s^2], jerks [rad/s^3]).
        limits: kind -> limits (a number or one per joint), validated by :func:`per_joint`.
        stage: the stage, for messages.

    Returns:
        kind -> :class:`LimitRatio`, for every kind in ``limits``.
    """
    out = {}
    for kind, limit in limits.items():
        values = np.asarray(samples[kind], dtype=float)
        if values.shape != (len(t), len(joint_names)):
            raise StageError(
                f"{stage}: {kind} samples: expected shape {(len(t), len(joint_names))}, got {values.shape}", stage=stage
            )
        if not values.size:
            out[kind] = LimitRatio(kind, 0.0, "", 0.0)
            continue
        ratio = np.abs(values) / per_joint(limit, joint_names, kind, stage)
        k, j = np.unravel_index(np.argmax(ratio), ratio.shape)
        out[kind] = LimitRatio(kind, float(ratio[k, j]), joint_names[int(j)], float(t[k]))
    return out
