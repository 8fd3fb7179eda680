"""The frames a task's poses are given in, and its ``scale``.

The frames: the robot's base, a link, the shoulders' centre.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from pydantic import ValidationError

from dualarm.errors import NotSRSError, RobotModelError, TaskFileError, excerpt
from dualarm.files import listing
from dualarm.model.kinematics import ChainKinematics
from dualarm.model.poses import pose_matrix
from dualarm.model.robot import Chain, Robot
from dualarm.model.srs import srs_geometry
from dualarm.tasks.schema import FRAME_ROLES, REFERENCE_ARM_M, Pose, TaskSpec


def frame_pose(robot: Robot, name: str, q: Mapping[str, float]) -> np.ndarray:
    """The pose (4, 4) [m] of frame ``name`` in the robot base frame at configuration ``q`` [rad].

    ``name`` is a role of :data:`~dualarm.tasks.schema.FRAME_ROLES` (checked first) or a URDF link.

    ``left.shoulder`` / ``right.shoulder``: that hand's shoulder centre S (:func:`shoulder_position`);
    ``shoulders``: the midpoint of the two; both with the robot base frame's axes (so a role only moves the origin).
    A link: its frame, the joints between the root and it at ``q``.

    Raises:
        NotSRSError: an arm of fewer than two movable joints for a shoulder role; KeyError: an unknown name.
    """
    if name in FRAME_ROLES:
        hands = ("left", "right") if name == "shoulders" else (name.split(".")[0],)
        T = np.eye(4)
        T[:3, 3] = np.mean([shoulder_position(robot, hand, q) for hand in hands], axis=0)
        return T
    if name not in robot.urdf.links:
        raise KeyError(name)
    chain = robot.chain_between(robot.urdf.root, name)
    return ChainKinematics.of(chain).pose(np.array([q[n] for n in chain.joint_names]))


def shoulder_position(robot: Robot, hand: str, q: Mapping[str, float]) -> np.ndarray:
    """The shoulder centre S of ``hand``'s arm in the robot base frame at configuration ``q`` [m], (3,).

    Where an S-R-S arm's joints 1-3 meet, else the SEW angle's S on joint 1's axis
    (:mod:`dualarm.ik.analytic.sew`: where joints 1-3 meet, or the point of joint 1's axis nearest where joints 2
    and 3 meet), else the point of joint 1's axis nearest joint 2's (:func:`_nearest_axes`).
    """
    arm = robot.hand_chain(hand)
    to_arm = robot.chain_between(robot.urdf.root, arm.base)
    T = ChainKinematics.of(to_arm).pose(np.array([q[n] for n in to_arm.joint_names]))
    return T[:3, :3] @ _shoulder_and_length(arm)[0] + T[:3, 3]


def arm_scale(robot: Robot, hands: Sequence[str]) -> float:
    """``scale = "arm"``'s factor: the mean arm length of ``hands``' arms over the reference arm's.

    Arm length: S-R-S: upper arm + forearm, L2 + L3; else |SE| + |EW| at q = 0 of the SEW angle's points; else
    :func:`_nearest_axes`'. Over :data:`~dualarm.tasks.schema.REFERENCE_ARM_M` (the humanoid's).
    """
    return float(np.mean([_shoulder_and_length(robot.hand_chain(hand))[1] for hand in hands])) / REFERENCE_ARM_M


def _shoulder_and_length(arm: Chain) -> tuple[np.ndarray, float]:
    """The shoulder centre S [m] (3,) in the arm's base frame and the arm's length [m].

    An S-R-S arm's S and L2 + L3; else those of the SEW angle's points at q = 0 (S, and |SE| + |EW|), which on an
    S-R-S arm are the same; else (any other arm: a Baxter's, a 6-joint arm) :func:`_nearest_axes`'.
    """
    from dualarm.model.sew import sew_chain

    try:
        geometry = srs_geometry(arm)
        return geometry.shoulder, geometry.reach
    except NotSRSError:
        pass
    try:
        sew = sew_chain(arm)
    except NotSRSError:
        return _nearest_axes(arm)
    return sew.shoulder, float(np.linalg.norm(sew.elbow - sew.shoulder) + np.linalg.norm(sew.wrist - sew.elbow))


def _nearest_axes(arm: Chain) -> tuple[np.ndarray, float]:
    """The shoulder and length of any arm at q = 0, in its base frame [m].

    S: the point of joint 1's axis nearest joint 2's (on a parallel axis: nearest joint 2's origin), as the SEW
    angle's S is on joint 1's axis; W likewise on the last axis, nearest the one before. The length: the polyline
    from S through the origins of the joints between to W (L2 + L3 on an S-R-S arm whose joint origins lie at S,
    E and W).
    """
    from dualarm.model.srs import _axis_lines

    lines = _axis_lines(arm, np.zeros(arm.dof))
    if len(lines) < 2:
        raise NotSRSError(f"chain '{arm.name}' has {len(lines)} movable joint: no shoulder")

    def nearest(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
        (p, d), (r, e) = a, b
        n = np.cross(d, e)
        if np.linalg.norm(n) < 1e-9:
            return p + d * np.dot(r - p, d)
        # the foot on line a of the common perpendicular: (r - p) . (e x n) / |n|^2 along d
        return p + d * np.dot(np.cross(r - p, e), n) / np.dot(n, n)

    shoulder, wrist = nearest(lines[0], lines[1]), nearest(lines[-1], lines[-2])
    points = [shoulder, *(p for p, _ in lines[1:-1]), wrist]
    return shoulder, float(sum(np.linalg.norm(b - a) for a, b in zip(points, points[1:], strict=False)))


def _in_frame(spec: TaskSpec, robot: Robot, q: Mapping[str, float], source: str) -> TaskSpec:
    """``spec`` with its waypoints, ``by`` displacements and arcs taken into the robot base frame.

    Taken from its ``frame`` (and ``scale``), at configuration ``q``; ``frame`` and ``scale`` then None.

    A pose (p, R) in the frame F becomes F (s p, R): the position scaled by s, then both moved by F.
    A role frame has the base frame's axes, so a waypoint's rpy is kept as written (bit for bit).
    """
    if spec.frame is None and spec.scale is None:
        return spec
    from scipy.spatial.transform import Rotation

    hands = tuple(h for h in spec.hands if h in robot.hands) or tuple(robot.hands)  # no hand driven: every arm
    try:
        F = np.eye(4) if spec.frame is None else frame_pose(robot, spec.frame, q)
        s = arm_scale(robot, hands) if spec.scale == "arm" else 1.0
    except KeyError:
        ends = dict.fromkeys(link for chain in robot.chains.values() for link in (chain.base, chain.tip))
        raise TaskFileError(
            f"{source}:frame: robot '{excerpt(robot.name, 40)}' has no frame '{excerpt(spec.frame, 40)}' "
            f"(roles: {listing(FRAME_ROLES)}; or a link: the chains' {listing(ends, 6)}, "
            f"or another of its {len(robot.urdf.links)} links)"
        ) from None
    except (NotSRSError, RobotModelError) as exc:
        key = "scale" if spec.frame is None or spec.frame not in FRAME_ROLES else "frame"
        raise TaskFileError(f"{source}:{key}: needs the shoulder centre of every driven arm: {exc}") from None
    R, o = F[:3, :3], F[:3, 3]
    rotated = not np.array_equal(R, np.eye(3))

    def point(p: tuple[float, float, float]) -> tuple[float, float, float]:
        return tuple(float(v) for v in R @ (s * np.asarray(p)) + o)  # type: ignore[return-value]

    def vector(v: tuple[float, float, float], length: float) -> tuple[float, float, float]:
        return tuple(float(x) for x in R @ (length * np.asarray(v)))  # type: ignore[return-value]

    waypoints = {}
    for name, wp in spec.waypoints.items():
        rpy = (
            tuple(float(a) for a in Rotation.from_matrix(R @ pose_matrix(wp.position, wp.rpy)[:3, :3]).as_euler("xyz"))
            if rotated
            else wp.rpy
        )
        try:
            waypoints[name] = Pose(position=point(wp.position), rpy=rpy)  # type: ignore[arg-type]
        except ValidationError:
            raise TaskFileError(
                f"{source}:waypoints.{excerpt(name, 40)}: in the robot base frame its position {point(wp.position)} m "
                "is outside [-100, 100] m"
            ) from None
    moves = []
    for move in spec.moves:
        update = {}
        for hand in ("left", "right"):
            m = move.for_hand(hand)
            if m is not None and m.by is not None:
                update[hand] = m.model_copy(update={"by": vector(m.by, s)})
            elif m is not None and m.arc_center is not None and m.arc_axis is not None:
                update[hand] = m.model_copy(
                    update={"arc_center": point(m.arc_center), "arc_axis": vector(m.arc_axis, 1.0)}
                )
        moves.append(move.model_copy(update=update))
    return spec.model_copy(update={"waypoints": waypoints, "moves": tuple(moves), "frame": None, "scale": None})


def _transferred(spec: TaskSpec, robot: Robot) -> TaskSpec:
    """``spec`` transferred to ``robot``, when it is not the one ``transfer.written_for`` names.

    ``transfer.initial``, ``transfer.gesture`` and ``transfer.limits`` in place of ``initial``, ``gesture`` and
    ``limits``, ``transfer.arm_angle`` (when given) in place of ``arm_angle``, and its moves' durations times
    ``transfer.duration_scale``, when ``robot`` is not the one ``transfer.written_for`` names (by robot.toml's
    ``name``).
    """
    if spec.transfer is None or robot.name == spec.transfer.written_for:
        return spec
    k, period = spec.transfer.duration_scale, spec.control_period_s
    moves = (
        tuple(m.model_copy(update={"duration_s": round(m.duration_s * k / period) * period}) for m in spec.moves)
        if k != 1.0
        else spec.moves
    )
    return spec.model_copy(
        update={
            "initial": spec.transfer.initial,
            "gesture": spec.transfer.gesture,
            "limits": spec.transfer.limits,
            "moves": moves,
            **({"arm_angle": spec.transfer.arm_angle} if spec.transfer.arm_angle is not None else {}),
        }
    )
