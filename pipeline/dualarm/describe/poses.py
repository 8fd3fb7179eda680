"""``dualarm robot poses``: each hand's pose (and arm angle) at a robot's home poses."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from dualarm.errors import NotSRSError
from dualarm.model.robot import Chain, Robot


@dataclass(frozen=True)
class HandPose:
    """A hand's pose at a home pose.

    Attributes:
        home: the home pose's name.
        hand: the hand.
        position_m: position in the robot base frame (the URDF's root link) [m], (3,).
        rpy_rad: extrinsic x-y-z roll, pitch, yaw in that frame [rad] (as task files), (3,).
        arm_angle_rad: the arm angle psi of MC-Inverse eq (1) (V = +z of the arm's base frame) [rad], None
            where the arm is not S-R-S or psi is undefined (shoulder-wrist line vertical or elbow straight).
    """

    home: str
    hand: str
    position_m: tuple[float, float, float]
    rpy_rad: tuple[float, float, float]
    arm_angle_rad: float | None


#: Below this sine between the shoulder-wrist line and the vertical (or between upper arm and forearm) the
#: arm angle is undefined.
SINGULAR_SINE = 1e-6


def _arm_angle(srs_kinematics, chain: Chain, q: np.ndarray) -> float | None:
    """Psi of eq (1) at ``q`` [rad]; None when psi is undefined.

    None when ``chain`` is not S-R-S, or its shoulder-wrist line is vertical or its elbow straight (psi undefined).
    """
    try:
        kin = srs_kinematics.of(chain)
    except NotSRSError:
        return None
    S, E, W = (np.asarray(v).ravel() for v in kin.points(q))
    sw = (W - S) / np.linalg.norm(W - S)
    se = (E - S) / np.linalg.norm(E - S)
    if np.linalg.norm(np.cross(sw, kin.vertical)) < SINGULAR_SINE or np.linalg.norm(np.cross(se, sw)) < SINGULAR_SINE:
        return None
    return float(kin.arm_angles(q[None, :])[0])


def home_hand_poses(robot: Robot, home: str | None = None) -> tuple[HandPose, ...]:
    """Every hand's pose at each home pose of ``robot`` (or at ``home`` only).

    Raises:
        RobotModelError: ``home`` is not a home pose of the robot.
    """
    from dualarm.model.kinematics import hand_pose
    from dualarm.model.srs import SrsKinematics

    if home is not None:
        robot.home(home)  # refuses an unknown name, listing the homes
    names = [home] if home is not None else list(robot.homes)
    out = []
    for name in names:
        q = robot.home(name)
        for hand in robot.hands:
            T = hand_pose(robot, hand, q)
            chain = robot.hand_chain(hand)
            psi = _arm_angle(SrsKinematics, chain, np.array([q[n] for n in chain.joint_names]))
            x, y, z = (float(v) for v in T[:3, 3])
            roll, pitch, yaw = (float(v) for v in Rotation.from_matrix(T[:3, :3]).as_euler("xyz"))
            out.append(
                HandPose(home=name, hand=hand, position_m=(x, y, z), rpy_rad=(roll, pitch, yaw), arm_angle_rad=psi)
            )
    return tuple(out)
