"""Two off-the-shelf position-level (pose) IK libraries, wrapped as baselines for one chain.

Each solver is built once per chain and solves one pose target at a time, seeded with the
previous solution, the way a user of the library would run it:

- :class:`TracIkSolver`: TRAC-IK (KDL Newton iterations racing NLopt SQP, random restarts) through
  ``pytracik``;
- :class:`PyBulletIkSolver`: ``pybullet.calculateInverseKinematics`` (damped least squares).

Targets are 4x4 poses of the chain's tip in the chain's base frame [m]. Whatever the library says,
the errors in a :class:`BaselineResult` are measured with the project's own CasADi forward
kinematics (:class:`~dualarm.model.kinematics.ChainKinematics`), so baselines and the project's
methods are scored by the same yardstick.

What the libraries needed (measured with pytracik 0.0.3 and pybullet 3.2.7 on the humanoid):

TRAC-IK
    - It is handed the URDF text without ``<collision>`` (:attr:`UrdfModel.kinematic_xml`). KDL
      does not support a root link with an inertia (it warns on stdout and ignores it), so a
      dummy root link without inertia is prepended when the root has one (the humanoid's
      ``base_link`` has none; the KUKA iiwa's root does). Its C++ code prints straight to stdout
      (that warning, "Couldn't find chain ..."), so construction runs under
      :func:`~dualarm.quiet.c_output_silenced`.
    - pytracik reads the URDF joint limits in single precision (-2.96706 becomes -2.9670600891, a
      little outside the URDF's limit); the robot's double limits are set back with
      ``set_joint_limits``, so solutions stay inside them exactly.
    - For unknown links it builds an empty chain and "succeeds" with zero joints: links are
      checked against the robot first and the chain length against the robot's chain.
    - ``epsilon`` bounds each component of KDL's twist error, so a success guarantees a position
      error up to sqrt(3) epsilon. Orientation cannot be resolved below about 1e-6 rad whatever
      epsilon is: successes were observed with orientation errors up to 7.5e-7 rad at epsilon
      1e-12 while positions met it, consistent with KDL's ``Rotation::GetRot`` taking a rotation
      whose matrix asymmetry is below 1e-6 for the identity (see
      :data:`KDL_ROTATION_RESOLUTION_RAD`).
    - Tight epsilons cost successes within the timeout: on 400 random arm poses seeded 0.1 rad
      (sd) away, 400/400 succeeded at epsilon 1e-7 and 390/400 at 1e-9 (5 ms timeout, idle
      machine; fewer under CPU load, since the timeout is wall-clock).
    - TRAC-IK sometimes reports success for a wrong answer: for one arm pose with the wrist pitch
      near its limit, 10/200 repeated solves at epsilon 1e-7 (Speed; 3/200 with Distance)
      returned "success" with the wrist pitch at its limit, 0.156 m and 2.09 rad off the target
      (its own FK agrees the answer is off). It is not deterministic, so it looks like a race
      between TRAC-IK's two solver threads. A result is therefore ``ok`` only when the project's
      FK confirms the errors are within the tolerances the epsilon promises.

PyBullet
    - It solves for every movable joint of the body. Joints outside the chain are locked with a
      huge per-joint damping (``jointDamping``), which PyBullet's plain DLS step
      ``dq = (J^T J + diag(d))^-1 J^T e`` honours per joint; chain joints get a small damping.
    - The null-space variant (taken as soon as lowerLimits/upperLimits/jointRanges/restPoses are
      given) ignores ``jointDamping``: locked joints drift, and even with the true limits it
      stalls about 2 cm from the targets. Limits are therefore not handed to PyBullet (it treats
      them as soft anyway); revolute results are wrapped by 2 pi into the limits where that helps
      and clipped otherwise, and the errors are measured after clipping.
    - With these settings it converges to about 1e-15 m and 2e-9 rad (median; at worst 3e-11 m
      and 2e-7 rad) when the answer respects the limits; on 200 random arm poses seeded 0.1 rad (sd)
      away, 191 succeeded and all 9 failures were answers outside the joint limits (clipping a wrist
      roll leaves only an orientation error).
    - ``residualThreshold`` stops on the position residual only; it is set tiny so the iteration
      also settles the orientation (the iteration converges in a few steps with small damping).
    - ``solver=IK_SDLS`` segfaults on this 17-DOF body (even position-only), so only DLS is used.
    - Passing the seed as ``currentPositions`` silently changes the frame of the target from the
      world to the root link's centre-of-mass frame (the KUKA iiwa of ``pybullet_data`` missed
      every target by its base's inertial offset, 0.12 m); the seed is therefore set as the
      body's joint state instead, from which the iteration starts.
    - Targets are converted from the chain base frame to PyBullet's world frame with the base
      frame's world pose at the locked configuration, computed by the project's FK in double
      precision; PyBullet's own ``getLinkState`` is single precision (the torso comes out
      7e-8 m off), which would cap the accuracy.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections import OrderedDict
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from dualarm.errors import RobotModelError
from dualarm.model.kinematics import ChainKinematics
from dualarm.model.poses import pose_errors
from dualarm.model.robot import Chain, Robot
from dualarm.quiet import c_output_silenced
from dualarm.sim.world import PyBulletRobot, load_pybullet_robot

with c_output_silenced():
    import pybullet as pb
    import pytracik

KDL_ROTATION_RESOLUTION_RAD = 5e-7
"""Smallest orientation error component KDL resolves [rad]: ``Rotation::GetRot`` returns a zero
rotation when every off-diagonal asymmetry ``|R_ij - R_ji| = 2 sin(angle) |axis_k|`` is below 1e-6."""

TRAC_IK_SOLVE_TYPES = ("Speed", "Distance", "Manip1", "Manip2")
"""TRAC-IK's solve types: first solution found (Speed), or the best found within the timeout by
distance to the seed (Distance) or by a manipulability measure (Manip1, Manip2)."""

PYBULLET_LOCK_DAMPING = 1e10
"""Per-joint damping that locks a joint outside the chain in PyBullet's DLS step [1]."""


@dataclass(frozen=True)
class BaselineResult:
    """One IK solve of a baseline.

    Attributes:
        q: the chain's joint positions, base to tip, shape (n,) [rad] (read-only). On failure the
            library's last answer (inside the limits), never None.
        ok: the solve succeeded: both errors within the solver's tolerances (and, for TRAC-IK,
            the library reported success).
        position_error_m: distance of the tip from the target's position, by the project's FK [m].
        orientation_error_rad: angle of the rotation from the tip's to the target's orientation,
            by the project's FK [rad].
    """

    q: np.ndarray
    ok: bool
    position_error_m: float
    orientation_error_rad: float

    def __post_init__(self) -> None:
        q = np.array(self.q, dtype=float)
        if q.ndim != 1:
            raise ValueError(f"q: expected shape (n,), got {q.shape}")
        q.setflags(write=False)
        object.__setattr__(self, "q", q)
        object.__setattr__(self, "ok", bool(self.ok))
        object.__setattr__(self, "position_error_m", float(self.position_error_m))
        object.__setattr__(self, "orientation_error_rad", float(self.orientation_error_rad))


def _tip_errors(kinematics: ChainKinematics, q: np.ndarray, target: np.ndarray) -> tuple[float, float]:
    """Position [m] and orientation [rad] error of the chain's tip at ``q`` from ``target`` (4x4)."""
    position, orientation = pose_errors(kinematics.pose(q)[None], np.asarray(target)[None])
    return float(position[0]), float(orientation[0])


def _check_target(target: np.ndarray) -> np.ndarray:
    target = np.asarray(target, dtype=float)
    if target.shape != (4, 4) or not np.isfinite(target).all():
        raise ValueError(f"target: expected a finite 4x4 pose, got shape {target.shape}")
    return target


def _check_seed(seed: np.ndarray, n: int) -> np.ndarray:
    seed = np.asarray(seed, dtype=float)
    if seed.shape != (n,) or not np.isfinite(seed).all():
        raise ValueError(f"seed: expected {n} finite joint positions, got shape {seed.shape}")
    return seed


def _chain(robot: Robot, base: str, tip: str) -> Chain:
    chain = robot.chain_between(base, tip)  # RobotModelError for unknown links / tip not below base
    if chain.dof == 0:
        raise RobotModelError(f"{robot.urdf.path}: no movable joint between links '{base}' and '{tip}'")
    return chain


def _xml_for_kdl(robot: Robot) -> str:
    """The URDF text for KDL: no <collision>, and a dummy root link if the root has an inertia."""
    root = ET.fromstring(robot.urdf.kinematic_xml)
    root_link = next(link for link in root.iter("link") if link.get("name") == robot.urdf.root)
    if root_link.find("inertial") is None:
        return robot.urdf.kinematic_xml
    dummy = "dualarm_kdl_root"
    while dummy in robot.urdf.links:
        dummy += "_"
    joint = ET.Element("joint", name=f"{dummy}_joint", type="fixed")
    ET.SubElement(joint, "parent", link=dummy)
    ET.SubElement(joint, "child", link=robot.urdf.root)
    root.insert(0, joint)
    root.insert(0, ET.Element("link", name=dummy))
    return ET.tostring(root, encoding="unicode")


@dataclass(frozen=True, eq=False)
class TracIkSolver:
    """TRAC-IK for one chain (build with :meth:`of`).

    Attributes:
        chain: the chain; ``q`` follows ``chain.joint_names``.
        kinematics: the project's FK of the chain, used to measure the errors.
        timeout_s: TRAC-IK's time budget per solve [s].
        epsilon: TRAC-IK's tolerance on each component of the twist error [m] and [rad].
        solve_type: one of :data:`TRAC_IK_SOLVE_TYPES`.
        lower: lower joint limits handed to TRAC-IK, shape (n,) [rad].
        upper: upper joint limits handed to TRAC-IK, shape (n,) [rad].
    """

    chain: Chain
    kinematics: ChainKinematics
    timeout_s: float
    epsilon: float
    solve_type: str
    lower: np.ndarray
    upper: np.ndarray
    _solver: object = field(repr=False)

    def __repr__(self) -> str:
        return (
            f"TracIkSolver({self.chain.name}, timeout_s={self.timeout_s}, epsilon={self.epsilon}, "
            f"solve_type={self.solve_type!r})"
        )

    @classmethod
    def of(
        cls,
        robot: Robot,
        base: str,
        tip: str,
        *,
        timeout_s: float = 0.005,
        epsilon: float = 1e-9,
        solve_type: str = "Speed",
    ) -> TracIkSolver:
        """Build TRAC-IK for the chain from link ``base`` to link ``tip``.

        Args:
            robot: the robot.
            base: base link; targets are poses in its frame.
            tip: tip link.
            timeout_s: time budget per solve [s] (TRAC-IK's default, 5 ms).
            epsilon: tolerance on each twist error component [m], [rad]; 1e-9 by default (TRAC-IK's
                own default is 1e-5). Orientation is resolved to about 1e-6 rad at best.
            solve_type: ``Speed`` (first solution), ``Distance``, ``Manip1`` or ``Manip2``.

        Raises:
            RobotModelError: unknown link, ``tip`` not below ``base``, no movable joint between
                them, or TRAC-IK built a chain that does not match the robot's.
            ValueError: a non-positive timeout or epsilon, or an unknown solve type.
        """
        if solve_type not in TRAC_IK_SOLVE_TYPES:
            raise ValueError(f"solve_type: {solve_type!r} is not one of {', '.join(TRAC_IK_SOLVE_TYPES)}")
        if not (timeout_s > 0 and epsilon > 0):
            raise ValueError(f"timeout_s and epsilon must be positive, got {timeout_s} and {epsilon}")
        chain = _chain(robot, base, tip)
        with c_output_silenced():
            kind = getattr(pytracik.SolveType, solve_type)
            solver = pytracik.TRAC_IK(base, tip, _xml_for_kdl(robot), float(timeout_s), float(epsilon), kind)
            dof = pytracik.get_num_joints(solver)
        if dof != chain.dof:
            raise RobotModelError(
                f"{robot.urdf.path}: TRAC-IK found {dof} joints from '{base}' to '{tip}', the URDF has {chain.dof}"
            )
        lower, upper = robot.lower_upper(chain.joint_names)
        # pytracik parsed the limits in single precision; continuous joints keep TRAC-IK's own.
        lower = np.where(np.isfinite(lower), lower, pytracik.get_joint_lower_bounds(solver))
        upper = np.where(np.isfinite(upper), upper, pytracik.get_joint_upper_bounds(solver))
        pytracik.set_joint_limits(solver, lower.tolist(), upper.tolist())
        for a in (lower, upper):
            a.setflags(write=False)
        return cls(chain, ChainKinematics.of(chain), float(timeout_s), float(epsilon), solve_type, lower, upper, solver)

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The chain's movable joints, base to tip: the order of ``q``."""
        return self.chain.joint_names

    @property
    def position_tolerance_m(self) -> float:
        """Largest position error of a successful solve: every component below epsilon [m]."""
        return math.sqrt(3) * self.epsilon

    @property
    def orientation_tolerance_rad(self) -> float:
        """Largest orientation error of a successful solve [rad].

        Every component of the rotation vector below epsilon or KDL's resolution, whichever is larger.
        """
        return math.sqrt(3) * max(self.epsilon, KDL_ROTATION_RESOLUTION_RAD)

    def solve(self, target: np.ndarray, seed: np.ndarray) -> BaselineResult:
        """Solve for the tip pose ``target`` starting from ``seed``.

        Args:
            target: 4x4 pose of the tip in the base frame [m].
            seed: start configuration, shape (n,) [rad] (typically the previous solution). TRAC-IK
                returns it unchanged when it already meets the target.

        Returns:
            The library's answer, with errors measured by the project's FK; ``ok`` when TRAC-IK
            reports success and the errors are within :attr:`position_tolerance_m` and
            :attr:`orientation_tolerance_rad` (TRAC-IK sometimes reports success for a wrong
            answer, see the module docstring).
        """
        target = _check_target(target)
        seed = _check_seed(seed, self.chain.dof)
        x, y, z = target[:3, 3]
        qx, qy, qz, qw = Rotation.from_matrix(target[:3, :3]).as_quat()
        answer = np.asarray(pytracik.ik(self._solver, seed, x, y, z, qx, qy, qz, qw), dtype=float)
        claimed = answer[0] >= 0  # TRAC-IK's CartToJnt: number of solutions found, negative on failure
        q = answer[1:] if np.isfinite(answer[1:]).all() else seed
        q = np.clip(q, self.lower, self.upper)  # a no-op for TRAC-IK's answers, kept as a guarantee
        position, orientation = _tip_errors(self.kinematics, q, target)
        ok = claimed and position <= self.position_tolerance_m and orientation <= self.orientation_tolerance_rad
        return BaselineResult(q, ok, position, orientation)


#: Most PyBullet solvers (each its own client) :meth:`PyBulletIkSolver.shared` keeps open in a process.
SHARED_PYBULLET_SOLVERS = 8
_shared_pybullet: OrderedDict[tuple[object, ...], PyBulletIkSolver] = OrderedDict()


@dataclass(frozen=True, eq=False)
class PyBulletIkSolver:
    """PyBullet's damped-least-squares IK for one chain, in its own DIRECT client.

    Build with :meth:`of`; close with :meth:`close` or use as a context manager.

    Attributes:
        chain: the chain; ``q`` follows ``chain.joint_names``.
        kinematics: the project's FK of the chain, used to measure the errors.
        world: the PyBullet client and body the solver owns.
        base_in_world: 4x4 pose of the chain's base link in PyBullet's world frame at the locked
            configuration [m].
        max_iterations: PyBullet's ``maxNumIterations``.
        residual_threshold_m: PyBullet's ``residualThreshold`` (on the position residual only) [m].
        joint_damping: PyBullet's ``jointDamping`` for the chain's joints (added to the diagonal of
            J^T J) [1].
        position_tolerance_m: largest position error counted as a success [m].
        orientation_tolerance_rad: largest orientation error counted as a success [rad].
        lower: lower joint limits, shape (n,) [rad].
        upper: upper joint limits, shape (n,) [rad].
    """

    chain: Chain
    kinematics: ChainKinematics
    world: PyBulletRobot
    base_in_world: np.ndarray
    max_iterations: int
    residual_threshold_m: float
    joint_damping: float
    position_tolerance_m: float
    orientation_tolerance_rad: float
    lower: np.ndarray
    upper: np.ndarray
    _chain_dofs: np.ndarray = field(repr=False)  # indices of the chain's joints among PyBullet's DOFs
    _damping: tuple[float, ...] = field(repr=False)
    _revolute: np.ndarray = field(repr=False)  # chain joints that may be wrapped by 2 pi
    _tip_index: int = field(repr=False)

    def __repr__(self) -> str:
        return (
            f"PyBulletIkSolver({self.chain.name}, max_iterations={self.max_iterations}, "
            f"residual_threshold_m={self.residual_threshold_m}, joint_damping={self.joint_damping})"
        )

    @classmethod
    def of(
        cls,
        robot: Robot,
        base: str,
        tip: str,
        *,
        locked: Mapping[str, float] | None = None,
        max_iterations: int = 100,
        residual_threshold_m: float = 1e-12,
        joint_damping: float = 1e-6,
        position_tolerance_m: float = 1e-9,
        orientation_tolerance_rad: float = 1e-6,
    ) -> PyBulletIkSolver:
        """Load the robot into a new PyBullet client and prepare IK for the chain ``base`` -> ``tip``.

        Args:
            robot: the robot (its URDF file is loaded with a fixed base at the origin).
            base: base link; targets are poses in its frame.
            tip: tip link.
            locked: positions of joints outside the chain [rad] (default 0, clipped into the
                limits); they stay there during every solve.
            max_iterations: PyBullet's ``maxNumIterations`` (its default is 20; with the small
                damping the iteration settled within 20 on every sample tried, 5 was too few).
            residual_threshold_m: PyBullet's ``residualThreshold`` on the position residual [m]
                (its default is 1e-4); tiny so the orientation settles too.
            joint_damping: damping of the chain's joints in the DLS step (PyBullet's default is
                0.1, which leaves centimetres of error); a little keeps singular steps bounded.
            position_tolerance_m: largest position error counted as a success [m] (default: TRAC-IK's
                guarantee at its default epsilon, in round numbers).
            orientation_tolerance_rad: largest orientation error counted as a success [rad].

        Raises:
            RobotModelError: unknown link or joint, ``tip`` not below ``base``, no movable joint
                between them, or a locked joint that belongs to the chain.
        """
        chain = _chain(robot, base, tip)
        locked = dict(locked or {})
        for name in locked:
            if name not in robot.limits:
                raise RobotModelError(f"locked.{name}: no movable joint of that name in {robot.urdf.path}")
            if name in chain.joint_names:
                raise RobotModelError(
                    f"locked.{name}: the joint belongs to the chain {chain.name} and cannot be locked"
                )
        world = load_pybullet_robot(robot.urdf.path)
        try:
            dofs = tuple(
                name
                for name, index in sorted(world.joint_index.items(), key=lambda item: item[1])
                if pb.getJointInfo(world.body, index, physicsClientId=world.client)[2] != pb.JOINT_FIXED
            )
            if set(dofs) != set(robot.limits):
                raise RobotModelError(f"{robot.urdf.path}: PyBullet's movable joints differ from the URDF's")
            rest = np.array([np.clip(locked.get(n, 0.0), robot.limits[n].lower, robot.limits[n].upper) for n in dofs])
            chain_dofs = np.array([dofs.index(n) for n in chain.joint_names])
            rest[chain_dofs] = 0.0
            world.set_positions(dofs, rest)
            damping = np.full(len(dofs), PYBULLET_LOCK_DAMPING)
            damping[chain_dofs] = joint_damping
            # The base frame in PyBullet's world: PyBullet's root pose times the project's FK to the base.
            to_base = robot.chain_between(robot.urdf.root, base)
            base_in_world = world.link_pose(robot.urdf.root)
            if to_base.joints:
                values = np.array([rest[dofs.index(n)] for n in to_base.joint_names])
                base_in_world = base_in_world @ ChainKinematics.of(to_base).pose(values)
        except BaseException:
            world.close()
            raise
        lower, upper = robot.lower_upper(chain.joint_names)
        revolute = np.array([j.type != "prismatic" for j in chain.joints if j.movable])
        for a in (base_in_world, lower, upper, chain_dofs, revolute):
            a.setflags(write=False)
        return cls(
            chain,
            ChainKinematics.of(chain),
            world,
            base_in_world,
            int(max_iterations),
            float(residual_threshold_m),
            float(joint_damping),
            float(position_tolerance_m),
            float(orientation_tolerance_rad),
            lower,
            upper,
            chain_dofs,
            tuple(damping.tolist()),
            revolute,
            world.link_index[tip],
        )

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The chain's movable joints, base to tip: the order of ``q``."""
        return self.chain.joint_names

    def solve(self, target: np.ndarray, seed: np.ndarray) -> BaselineResult:
        """Solve for the tip pose ``target`` starting from ``seed``.

        The chain's joints are set to ``seed`` in PyBullet, where the iteration starts (not passed as
        ``currentPositions``, which moves the target's frame, see the module docstring); the answer
        is wrapped by 2 pi into the limits where possible (revolute joints) and clipped.

        Args:
            target: 4x4 pose of the tip in the base frame [m].
            seed: start configuration, shape (n,) [rad] (typically the previous solution).

        Returns:
            PyBullet's answer inside the limits; ``ok`` when both errors, measured by the
            project's FK, are within the solver's tolerances.
        """
        target = _check_target(target)
        seed = _check_seed(seed, self.chain.dof)
        world = self.world
        world.set_positions(self.chain.joint_names, seed)  # the other joints stay locked where `of` put them
        goal = self.base_in_world @ target
        answer = pb.calculateInverseKinematics(
            world.body,
            self._tip_index,
            goal[:3, 3].tolist(),
            Rotation.from_matrix(goal[:3, :3]).as_quat().tolist(),  # x, y, z, w
            jointDamping=list(self._damping),
            maxNumIterations=self.max_iterations,
            residualThreshold=self.residual_threshold_m,
            physicsClientId=world.client,
        )
        q = np.asarray(answer, dtype=float)[self._chain_dofs]
        if not np.isfinite(q).all():
            q = seed.copy()
        q = self._into_limits(q, seed)
        position, orientation = _tip_errors(self.kinematics, q, target)
        ok = position <= self.position_tolerance_m and orientation <= self.orientation_tolerance_rad
        return BaselineResult(q, ok, position, orientation)

    def _into_limits(self, q: np.ndarray, seed: np.ndarray) -> np.ndarray:
        """Wrap revolute joints by multiples of 2 pi into their limits (closest to the seed), then clip."""
        q = q.copy()
        for i in np.flatnonzero(self._revolute & ((q < self.lower) | (q > self.upper))):
            candidates = q[i] + 2 * np.pi * np.arange(-3, 4)
            inside = candidates[(candidates >= self.lower[i]) & (candidates <= self.upper[i])]
            if inside.size:
                q[i] = inside[np.argmin(np.abs(inside - seed[i]))]
        return np.clip(q, self.lower, self.upper)

    @classmethod
    def shared(
        cls, robot: Robot, base: str, tip: str, *, locked: Mapping[str, float] | None = None, **settings: Any
    ) -> PyBulletIkSolver:
        """:meth:`of`'s solver, built once per robot, chain, locked joints and settings and kept open.

        Built once in a process (a study's worker loads the robot into PyBullet once, not per trial); the least
        recently used beyond :data:`SHARED_PYBULLET_SOLVERS` are closed. Not to be closed by the caller.

        Every answer is :meth:`of`'s: :meth:`solve` sets the chain's joints to its seed, and nothing changes the others.
        """
        key = (robot, base, tip, tuple(sorted((locked or {}).items())), tuple(sorted(settings.items())))
        solver = _shared_pybullet.pop(key, None) or cls.of(robot, base, tip, locked=locked, **settings)
        _shared_pybullet[key] = solver
        while len(_shared_pybullet) > SHARED_PYBULLET_SOLVERS:
            _shared_pybullet.popitem(last=False)[1].close()
        return solver

    def close(self) -> None:
        """Disconnect the PyBullet client."""
        self.world.close()

    def __enter__(self) -> PyBulletIkSolver:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
