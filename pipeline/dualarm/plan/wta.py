"""Workspace Target Areas: Li & Liang, eqs (21)-(31).

Li & Liang, *Study on Humanoid Robot's Dual-arm Collision Avoidance Motion Planning Algorithm*.

A WTA is a reference frame ^w T_WTA in the world (here: the robot base frame), the hand's offset
^WTA T_e in it, and a 6x2 bound matrix ^WTA B_e on the displacement of the WTA frame as the hand
would carry it: x, y, z [m] and roll, pitch, yaw [rad] (extrinsic x-y-z, R = Rz Ry Rx, the
convention of :func:`dualarm.model.poses.pose_matrix`). The same construction is Berenson's Task
Space Region (the paper's ref. [10]), which also fixes the two garbled equations:

- eq (23) as printed, T_g = T_WTA [^w T_WTA(Theta)]^-1, is read as the object frame the hand
  carries, ^w T_g(Theta) = ^w T_e(Theta) (^WTA T_e)^-1, which is eq (22)'s right-hand side; eq (24)
  then expresses it in the WTA frame, ^WTA T_g = (^w T_WTA)^-1 ^w T_g;
- eq (29) as printed repeats T_rand; it is ^w T_e,rand = ^w T_WTA ^WTA T_rand ^WTA T_e, the hand
  pose that puts the carried frame at the sample.

Several WTAs of one hand are sampled "by weight", eqs (30)-(31), with weights Z_i proportional to
the sum of the area's six widths (eq 31) times the task file's ``weight``, normalised to sum 1. Eq
(30) as printed sums the weighted samples of all areas into one pose; for two areas apart (the
two sides of a bowl) that average lies in neither, so, as in Berenson's TSR sampling, one area is
drawn with probability Z_i and sampled by eq (27). When every area of the hand is a single pose
(all widths zero), the areas are drawn in proportion to their ``weight`` alone.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from dualarm.arrays import frozen
from dualarm.model.poses import invert, pose_matrix
from dualarm.tasks.schema import WorkspaceTargetArea


def pose_vector(T: np.ndarray) -> np.ndarray:
    """Eq (25): the 6-D vector [x, y, z, roll, pitch, yaw] of poses T (..., 4, 4) [m, rad].

    roll = atan2(R32, R33), pitch = -asin(R31), yaw = atan2(R21, R11).
    """
    R = T[..., :3, :3]
    return np.concatenate(
        [
            T[..., :3, 3],
            np.arctan2(R[..., 2, 1], R[..., 2, 2])[..., None],
            -np.arcsin(np.clip(R[..., 2, 0], -1.0, 1.0))[..., None],
            np.arctan2(R[..., 1, 0], R[..., 0, 0])[..., None],
        ],
        axis=-1,
    )


def displacement(x: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """Eq (26): per component, how far ``x`` (..., 6) lies outside the bounds ``bounds`` (6, 2); 0 inside.

    Below the lower bound (negative) or above the upper bound (positive).
    """
    return np.where(x < bounds[:, 0], x - bounds[:, 0], np.where(x > bounds[:, 1], x - bounds[:, 1], 0.0))


@dataclass(frozen=True)
class Wta:
    """One Workspace Target Area, eq (21).

    Attributes:
        name: the task file's name for it.
        hand: the hand it is for.
        reference: ^w T_WTA, the WTA frame in the robot base frame (4, 4) [m].
        offset: ^WTA T_e, the hand frame in the WTA frame (4, 4) [m].
        bounds: ^WTA B_e (6, 2): [lower, upper] of x, y, z [m], roll, pitch, yaw [rad].
        weight: the task file's weight multiplier (eq 31's weight is this times the widths' sum).
    """

    name: str
    hand: str
    reference: np.ndarray
    offset: np.ndarray
    bounds: np.ndarray
    weight: float = 1.0

    def __post_init__(self) -> None:
        for name, shape in (("reference", (4, 4)), ("offset", (4, 4)), ("bounds", (6, 2))):
            object.__setattr__(self, name, frozen(getattr(self, name), shape, name))

    @classmethod
    def of(cls, spec: WorkspaceTargetArea) -> Wta:
        """The WTA of a task file's ``[[wta]]`` table."""
        return cls(
            name=spec.name,
            hand=spec.hand,
            reference=pose_matrix(spec.reference.position, spec.reference.rpy),
            offset=pose_matrix(spec.offset.position, spec.offset.rpy),
            bounds=np.array(spec.bounds, dtype=float),
            weight=spec.weight,
        )

    def carried_vector(self, hand_pose: np.ndarray) -> np.ndarray:
        """Eqs (22)-(25): the 6-D pose, in the WTA frame, of the frame the hand carries; (..., 6) [m, rad].

        The hand at ``hand_pose`` (..., 4, 4) [m].
        """
        carried = hand_pose @ invert(self.offset)  # eq (22)
        return pose_vector(invert(self.reference) @ carried)  # eqs (24)-(25)

    def distance(self, hand_pose: np.ndarray) -> np.ndarray:
        """Eq (26): |Delta x|, the distance of hand poses (..., 4, 4) to the area (0 inside).

        In the paper's mixed units (m and rad in one norm).
        """
        return np.linalg.norm(displacement(self.carried_vector(hand_pose), self.bounds), axis=-1)

    def sample_vector(self, rng: np.random.Generator) -> np.ndarray:
        """Eq (27): a uniform sample of the bound box, (6,) [m, rad]."""
        lower, upper = self.bounds[:, 0], self.bounds[:, 1]
        return lower + rng.random(6) * (upper - lower)

    def hand_pose(self, x: np.ndarray) -> np.ndarray:
        """Eqs (28)-(29): the hand pose (4, 4) [m] in the base frame that puts the carried frame at ``x``.

        ``x`` (6,) of the WTA frame: ^w T_WTA ^WTA T_rand ^WTA T_e.
        """
        return self.reference @ pose_matrix(x[:3], x[3:]) @ self.offset


def sampling_weights(areas: Sequence[Wta]) -> np.ndarray:
    """Eq (31): each area's weight Z_i, the sum of its six widths times its ``weight``.

    Normalised to sum 1 (in proportion to ``weight`` alone when every area is a single pose).
    """
    widths = np.array([a.weight * float(np.sum(a.bounds[:, 1] - a.bounds[:, 0])) for a in areas])
    if widths.sum() <= 0:
        widths = np.array([a.weight for a in areas])
    return widths / widths.sum()


def sample_hand_pose(areas: Sequence[Wta], rng: np.random.Generator) -> tuple[Wta, np.ndarray]:
    """Eqs (27)-(31): draw one of a hand's ``areas`` by weight, then a pose in it.

    Returns the area and the hand pose (4, 4) [m].
    """
    area = areas[int(rng.choice(len(areas), p=sampling_weights(areas)))] if len(areas) > 1 else areas[0]
    return area, area.hand_pose(area.sample_vector(rng))
