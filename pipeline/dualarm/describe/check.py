"""``dualarm robot check``: verify a robot's CasADi kinematics against independent computations.

For every chain, over random configurations within the joint limits (fixed seed):

- forward kinematics against adam-robotics (an independent URDF -> CasADi rigid-body library, in
  double precision): the acceptance test at 1e-9 m / 1e-9 rad;
- forward kinematics against PyBullet's link frames, which PyBullet reports in single precision,
  so this comparison can only hold to about 1e-7 and is accepted at ``PYBULLET_TOLERANCE``;
- the geometric Jacobian against central finite differences of the forward kinematics.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as cs
import numpy as np
from scipy.spatial.transform import Rotation

from dualarm.errors import RobotModelError, excerpt
from dualarm.model.kinematics import ChainKinematics
from dualarm.model.poses import pose_errors
from dualarm.model.robot import Chain, Robot, random_configurations
from dualarm.model.urdf import parser_warnings_silenced
from dualarm.sim.world import load_pybullet_robot

FK_TOLERANCE = 1e-9
"""Largest accepted FK difference against the double-precision reference [m] and [rad]."""
PYBULLET_TOLERANCE = 1e-6
"""Largest accepted FK difference against PyBullet's single-precision link frames [m] and [rad]."""
JACOBIAN_TOLERANCE = 1e-6
"""Largest accepted Jacobian difference against central finite differences."""
FD_STEP = 1e-6
"""Finite-difference step [rad]."""


@dataclass(frozen=True)
class ChainCheck:
    """Result of checking one chain.

    Attributes:
        chain: chain name.
        dof: movable joints.
        samples: configurations tried.
        fk_position_error_m: largest tip position difference against adam-robotics [m].
        fk_rotation_error_rad: largest tip rotation difference against adam-robotics [rad].
        pybullet_position_error_m: largest tip position difference against PyBullet [m].
        pybullet_rotation_error_rad: largest tip rotation difference against PyBullet [rad].
        jacobian_error: largest entry-wise Jacobian difference against finite differences.
    """

    chain: str
    dof: int
    samples: int
    fk_position_error_m: float
    fk_rotation_error_rad: float
    pybullet_position_error_m: float
    pybullet_rotation_error_rad: float
    jacobian_error: float

    @property
    def passed(self) -> bool:
        """Every figure within its tolerance."""
        return (
            self.fk_position_error_m <= FK_TOLERANCE
            and self.fk_rotation_error_rad <= FK_TOLERANCE
            and self.pybullet_position_error_m <= PYBULLET_TOLERANCE
            and self.pybullet_rotation_error_rad <= PYBULLET_TOLERANCE
            and self.jacobian_error <= JACOBIAN_TOLERANCE
        )


def require_limits(robot: Robot) -> None:
    """Refuse a robot whose chain joints lack a finite velocity, acceleration or jerk limit.

    A robot described by a robot.toml; retiming needs all three; a missing one is ``inf`` in
    :class:`~dualarm.model.robot.JointLimits`.

    A bare URDF (``--urdf``, no robot.toml) is not refused: it has no place for them.

    Raises:
        RobotModelError: one line naming robot.toml, the joint, its chain and the table to add it to.
    """
    if robot.directory is None:
        return
    for chain in robot.chains.values():
        for joint in chain.joint_names:
            for kind, unit in (("velocity", "rad/s"), ("acceleration", "rad/s^2"), ("jerk", "rad/s^3")):
                if not np.isfinite(getattr(robot.limits[joint], kind)):
                    where = "the URDF's <limit velocity> or " if kind == "velocity" else ""
                    raise RobotModelError(
                        f"{excerpt(robot.directory / 'robot.toml')}: joint '{excerpt(joint, 40)}' "
                        f"of chain '{excerpt(chain.name, 40)}' has no {kind} limit: "
                        f"add it to {where}[limits.{kind}] [{unit}]"
                    )


def _adam_xml(xml: str) -> str:
    """``xml`` with an identity ``<origin>`` in every ``<inertial>`` and ``<joint>`` that has none.

    URDF makes it optional (a PR2's joints leave it out); adam-robotics needs it.
    """
    import xml.etree.ElementTree as ET

    root = ET.fromstring(xml)
    for element in [*root.iter("inertial"), *root.findall("joint")]:
        if element.find("origin") is None:
            ET.SubElement(element, "origin", {"xyz": "0 0 0", "rpy": "0 0 0"})
    return ET.tostring(root, encoding="unicode")


def adam_poses(robot: Robot, chain: Chain, Q: np.ndarray) -> np.ndarray:
    """Tip poses in the chain base frame computed by adam-robotics; (N, 4, 4)."""
    from adam.casadi import KinDynComputations

    with parser_warnings_silenced():  # adam-robotics parses with urdf_parser_py too
        kd = KinDynComputations(_adam_xml(robot.urdf.kinematic_xml), list(chain.joint_names))
    base = kd.forward_kinematics_fun(chain.base)
    tip = kd.forward_kinematics_fun(chain.tip)
    H = cs.DM.eye(4)
    out = np.empty((Q.shape[0], 4, 4))
    for i, q in enumerate(Q):
        out[i] = np.linalg.solve(np.asarray(base(H, q)), np.asarray(tip(H, q)))
    return out


def pybullet_poses(robot: Robot, chain: Chain, Q: np.ndarray) -> np.ndarray:
    """Tip poses in the chain base frame from PyBullet's link frames; (N, 4, 4)."""
    out = np.empty((Q.shape[0], 4, 4))
    with load_pybullet_robot(robot.urdf.path) as sim:
        for i, q in enumerate(Q):
            sim.set_positions(chain.joint_names, q)
            out[i] = np.linalg.solve(sim.link_pose(chain.base), sim.link_pose(chain.tip))
    return out


def finite_difference_jacobians(kin: ChainKinematics, Q: np.ndarray, h: float = FD_STEP) -> np.ndarray:
    """Central-difference geometric Jacobians (N, 6, n).

    Linear rows from positions, angular rows from the rotation vector of R(q + h e_i) R(q - h e_i)^T.
    """
    N, n = Q.shape
    J = np.empty((N, 6, n))
    for i in range(n):
        step = np.zeros(n)
        step[i] = h
        plus, minus = kin.poses(Q + step), kin.poses(Q - step)
        J[:, :3, i] = (plus[:, :3, 3] - minus[:, :3, 3]) / (2 * h)
        relative = np.einsum("nij,nkj->nik", plus[:, :3, :3], minus[:, :3, :3])
        J[:, 3:, i] = Rotation.from_matrix(relative).as_rotvec() / (2 * h)
    return J


def check_chain(robot: Robot, chain: Chain, samples: int = 1000, seed: int = 0) -> ChainCheck:
    """Compare ``chain``'s kinematics with adam-robotics, PyBullet and finite differences."""
    kin = ChainKinematics.of(chain)
    Q = random_configurations(robot, chain, samples, seed)
    ours = kin.poses(Q)
    fk_pos, fk_rot = pose_errors(ours, adam_poses(robot, chain, Q))
    pb_pos, pb_rot = pose_errors(ours, pybullet_poses(robot, chain, Q))
    jac_err = np.abs(kin.jacobians(Q) - finite_difference_jacobians(kin, Q)).max() if chain.dof else 0.0
    return ChainCheck(
        chain=chain.name,
        dof=chain.dof,
        samples=samples,
        fk_position_error_m=float(fk_pos.max()),
        fk_rotation_error_rad=float(fk_rot.max()),
        pybullet_position_error_m=float(pb_pos.max()),
        pybullet_rotation_error_rad=float(pb_rot.max()),
        jacobian_error=float(jac_err),
    )
