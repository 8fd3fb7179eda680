"""The MCAP sink: each stage's product once into ``run.mcap``, with foxglove-sdk.

And ``foxglove-layout.json``.

One Context per run, so nothing is global: one topic family per stage (``/task/...`` for the path
stage, :data:`STAGE_TOPICS`), ``/robot_description`` with the URDF as URDF 1.0 viewers read it
and its meshes inside (:func:`robot_description`), ``/tf`` with the link frames of one robot, the
run's :func:`~dualarm.record.sink.shown_stage`, under the URDF's own link names (Foxglove's URDF
layer places links by those names, so it can animate one robot), ``/metrics``; the manifest as
metadata; the task file, robot.toml and URDF as attachments. Log time is motion time (each stage
from 0), not the wall clock: repetitions and runs line up.
"""

from __future__ import annotations

import base64
import json
import xml.etree.ElementTree as ET
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import foxglove
import numpy as np
import orjson
from foxglove.channels import FrameTransformsChannel, SceneUpdateChannel
from foxglove.messages import (
    Color,
    CubePrimitive,
    CylinderPrimitive,
    FrameTransform,
    FrameTransforms,
    LinePrimitive,
    LinePrimitiveLineType,
    Point3,
    Pose,
    Quaternion,
    SceneEntity,
    SceneUpdate,
    SpherePrimitive,
    Timestamp,
    Vector3,
)

from dualarm.contracts.joint_path import JointPath
from dualarm.contracts.reference import CartesianReference
from dualarm.contracts.trajectory import JointTrajectory
from dualarm.errors import RobotModelError
from dualarm.model.kinematics import joint_transforms
from dualarm.model.poses import pose_matrix, quaternion_xyzw
from dualarm.model.robot import Robot
from dualarm.model.urdf import viewer_urdf
from dualarm.record import schemas
from dualarm.record.foxglove_layout import foxglove_layout, message_path
from dualarm.record.run_dir import FOXGLOVE_LAYOUT
from dualarm.record.sink import (
    HAND_COLORS,
    OBJECT_COLOR,
    STAGE_COLORS,
    NullSink,
    animation_rows,
    carried_poses,
    extend_range,
    shown_stage,
)
from dualarm.tasks.task import hand_poses_at

if TYPE_CHECKING:  # pybullet is imported only by runs that execute
    from dualarm.contracts.execution import ExecutionLog

#: MCAP topic family of each stage.
STAGE_TOPICS = {
    "path": "/task",
    "ik": "/ik",
    "plan": "/plan",
    "retime": "/retime",
    "smooth": "/smooth",
    "approach": "/approach",
    "execute": "/execute",
}


#: The media type of each mesh file ending Foxglove Studio's 3D panel loads (its ModelCache); other meshes are
#: written as binary STL (trimesh).
MESH_MEDIA_TYPES = {
    ".obj": "model/obj",
    ".stl": "model/stl",
    ".dae": "model/vnd.collada+xml",
    ".glb": "model/gltf-binary",
}


def robot_description(urdf: Path) -> str:
    """The URDF at ``urdf`` as ``/robot_description`` carries it: URDF 1.0, its meshes inside.

    URDF 1.0 as :func:`viewer_urdf` writes it.

    Each ``<mesh filename>`` (``package://``, relative or absolute, found as the robot's init found it,
    :func:`~dualarm.describe.meshes.resolve_mesh`) becomes a ``data:`` URL holding the file. Foxglove's URDF layer
    fetches a mesh from the page it runs in, where a relative path is an invalid URL and ``file://`` or
    ``package://`` cannot be read, so this is how a recording draws a robot with meshes anywhere. A mesh that cannot
    be found is left as named (the viewer then reports it). The collision shapes of links with a visual one, which
    Studio does not draw, are left out (the Panda's description: 1.17 MB with them, 0.6 without).
    """
    from dualarm.describe.meshes import resolve_mesh

    root = ET.fromstring(viewer_urdf(urdf.read_text()))
    for link in root.iter("link"):  # Studio draws a link's collision shapes only when it has no visual one
        if link.find("visual") is not None:
            for collision in link.findall("collision"):
                link.remove(collision)
    embedded: dict[Path, str] = {}
    for mesh in root.iter("mesh"):
        try:
            path, _ = resolve_mesh(mesh.get("filename", ""), urdf)
        except RobotModelError:
            continue
        if path not in embedded:
            media = MESH_MEDIA_TYPES.get(path.suffix.lower())
            data = path.read_bytes() if media else _as_stl(path)
            embedded[path] = f"data:{media or MESH_MEDIA_TYPES['.stl']};base64,{base64.b64encode(data).decode()}"
        mesh.set("filename", embedded[path])
    return ET.tostring(root, encoding="unicode")


def _as_stl(path: Path) -> bytes:
    """The mesh file ``path`` as binary STL (trimesh reads it), for a format Foxglove does not load."""
    import trimesh

    return bytes(trimesh.load(path, force="mesh").export(file_obj=None, file_type="stl"))


def _pose(T: np.ndarray) -> Pose:
    """The transform ``T`` (4, 4) [m] as a Foxglove pose."""
    x, y, z, w = quaternion_xyzw(T[:3, :3]).tolist()
    return Pose(position=Vector3(x=T[0, 3], y=T[1, 3], z=T[2, 3]), orientation=Quaternion(x=x, y=y, z=z, w=w))


def _ns(t: float) -> int:
    """Motion time [s] -> MCAP log time [ns]."""
    return int(round(t * 1e9))


def _encoder(*values: np.ndarray | float) -> Callable[[dict], bytes]:
    """The JSON encoder of messages made of ``values``: orjson's when all are finite, else json's.

    orjson's is a few times faster than json's, for the per-sample topics; json writes NaN and
    Infinity as Python and Foxglove read them (orjson writes null).
    """
    if all(np.isfinite(np.asarray(v, dtype=float)).all() for v in values):
        return orjson.dumps
    return lambda message: json.dumps(message).encode()


def _vec(v) -> dict[str, float]:
    return {"x": float(v[0]), "y": float(v[1]), "z": float(v[2])}


def _quat(q) -> dict[str, float]:
    return {"x": float(q[0]), "y": float(q[1]), "z": float(q[2]), "w": float(q[3])}


class McapSink(NullSink):
    """The sink that writes one run's ``run.mcap`` into ``directory``.

    And, when closed, ``foxglove-layout.json``.

    Args:
        directory: the (temporary) run directory.
        robot: the robot, for /tf and the URDF.
        attachments: file name -> text, stored in the MCAP (task file, robot.toml, URDF).
        stages: the stages recorded (the others' products are dropped; for the layout the run
            opens on and the robot on ``/tf``).
    """

    def __init__(
        self, directory: Path, robot: Robot, attachments: Mapping[str, str], stages: Sequence[str] = tuple(STAGE_TOPICS)
    ) -> None:
        super().__init__()
        self.stages = tuple(stages)
        self.shown = shown_stage(self.stages)
        self.directory = directory
        self.robot = robot
        self._keys = {"joints": robot.joint_names, "hands": robot.hands}
        self._hands: tuple[str, ...] = robot.hands  # the task's, once the reference is recorded
        self._joint_names: tuple[str, ...] | None = None  # the moving joints, once a stage hands them
        self._context = foxglove.Context()
        self._mcap = foxglove.open_mcap(directory / "run.mcap", context=self._context)
        self._channels: dict[str, foxglove.Channel] = {}
        self._ranges: dict[str, tuple[float, float]] = {}  # message path -> its values' lowest and highest
        self._carried: Any | None = None  # the object both hands carry (environment)
        self._tf_channel = FrameTransformsChannel("/tf", context=self._context)
        for name, text in attachments.items():
            media = "application/xml" if name.endswith(".urdf") else "application/toml"
            self._mcap.attach(log_time=0, create_time=0, name=name, media_type=media, data=text.encode())
        self._description = robot_description(robot.urdf.path)
        self._json("/robot_description", schemas.ROBOT_DESCRIPTION).log({"data": self._description}, log_time=0)

    def _json(self, topic: str, schema: dict, **keys: Sequence[str]) -> foxglove.Channel:
        """The JSON channel ``topic``, opened on first use with ``schema``.

        Its maps keyed by the robot's joints and hands (and ``keys``: kind -> names).
        """
        if topic not in self._channels:
            self._channels[topic] = foxglove.Channel(
                topic, schema=schemas.named(schema, {**self._keys, **keys}), context=self._context
            )
        return self._channels[topic]

    def _extents(self, topic: str, t: np.ndarray, **fields: Mapping[str, np.ndarray]) -> None:
        """Note the range of each of ``fields`` (field -> key -> values) on ``topic``, for the layout's plots.

        And of its times ``t`` [s], its stage's clock. By message path
        (:func:`~dualarm.record.foxglove_layout.message_path`).
        """
        extend_range(self._ranges, message_path(topic, "t"), t)
        for field, values in fields.items():
            for key, v in values.items():
                extend_range(self._ranges, message_path(topic, field, key), v)

    def _tf(self, stage: str, t: np.ndarray | float, q: Mapping[str, np.ndarray | float]) -> None:
        """The robot's link frames on ``/tf`` at times ``t`` (K,) [s]: the shown stage's only.

        ``q``: joint name -> (K,) positions [rad]; the root hung from ``world``.
        """
        if stage != self.shown:
            return
        t = np.atleast_1d(np.asarray(t, dtype=float))
        q = {name: np.broadcast_to(np.asarray(v, dtype=float), t.shape) for name, v in q.items()}
        links = [("world", self.robot.urdf.root, np.broadcast_to(np.eye(4), (len(t), 4, 4)))] + joint_transforms(
            self.robot.urdf.joints, q
        )
        frames = [
            (parent, child, T[:, :3, 3].tolist(), quaternion_xyzw(T[:, :3, :3]).tolist()) for parent, child, T in links
        ]
        for k, time in enumerate(t.tolist()):
            stamp = Timestamp(sec=_ns(time) // 10**9, nsec=_ns(time) % 10**9)  # the log time, to the nanosecond
            self._tf_channel.log(
                FrameTransforms(
                    transforms=[
                        FrameTransform(
                            timestamp=stamp,
                            parent_frame_id=parent,
                            child_frame_id=child,
                            translation=Vector3(x=p[k][0], y=p[k][1], z=p[k][2]),
                            rotation=Quaternion(x=r[k][0], y=r[k][1], z=r[k][2], w=r[k][3]),
                        )
                        for parent, child, p, r in frames
                    ]
                ),
                log_time=_ns(time),
            )

    def robot_state(self, stage: str, t: float, q: Mapping[str, float], rep: int = 0) -> None:
        """The robot at configuration ``q`` [rad] at motion time ``t`` [s].

        On ``/tf`` and ``<family>/joint_state``.
        """
        if stage not in self.stages:
            return
        self._tf(stage, t, q)
        family = STAGE_TOPICS.get(stage, f"/{stage}")
        self._json(f"{family}/joint_state", schemas.JOINT_STATE).log(
            {"t": t, "rep": rep, "position": {n: float(v) for n, v in q.items()}}, log_time=_ns(t)
        )

    def joint_path(
        self, path: JointPath, velocity_limits: np.ndarray, arm_angles: Mapping[str, np.ndarray], stage: str = "ik"
    ) -> None:
        """The IK (or plan) stage's product, under ``stage``'s topics.

        ``/ik/limits`` once (the robot's position limits and ``velocity_limits`` [rad/s] of the
        path's joints), ``/ik/sample`` (with each hand's position error [m], orientation error
        [rad] when measured, and ``arm_angles`` [rad], (N,) per hand) and (TV-GDD) ``/ik/bounds``
        per sample, the robot on ``/tf`` and, for the shown stage, the hands' paths.
        """
        if stage not in self.stages:
            return
        family = STAGE_TOPICS[stage]
        names = self._joint_names = path.joint_names
        self._limits(stage, names, {"velocity": velocity_limits})
        sample = self._json(f"{family}/sample", schemas.IK_SAMPLE)
        bounds = self._json(f"{family}/bounds", schemas.JOINT_BOUNDS) if path.extras else None
        angle = path.hand_orientation_error_rad
        measured = bool(np.isfinite(angle).all())  # a planner's path measures no orientation: the field is left out
        encode = _encoder(
            path.q,
            path.qd,
            path.solve_time_s,
            path.hand_error_m,
            angle if measured else 0.0,
            *arm_angles.values(),
            *path.extras.values(),
        )
        for k in range(len(path)):
            t, rep = float(path.t[k]), int(path.rep[k])
            sample.log(
                encode(
                    {
                        "t": t,
                        "rep": rep,
                        "method": path.method,
                        "status": int(path.status[k]),
                        "solve_time_s": float(path.solve_time_s[k]),
                        "position": dict(zip(names, path.q[k].tolist(), strict=True)),
                        "velocity": dict(zip(names, path.qd[k].tolist(), strict=True)),
                        "hand_error_m": dict(zip(path.hands, path.hand_error_m[k].tolist(), strict=True)),
                        **(
                            {
                                "hand_orientation_error_rad": dict(zip(path.hands, angle[k].tolist(), strict=True)),
                                "task_space": path.task_space,
                            }
                            if measured
                            else {}
                        ),
                        "arm_angle_rad": {hand: float(psi[k]) for hand, psi in arm_angles.items()},
                    }
                ),
                log_time=_ns(t),
            )
            if bounds is not None:
                bounds.log(
                    encode(
                        {
                            "t": t,
                            "rep": rep,
                            **{key: dict(zip(names, v[k].tolist(), strict=True)) for key, v in path.extras.items()},
                        }
                    ),
                    log_time=_ns(t),
                )
        self._extents(
            f"{family}/sample",
            path.t,
            position=dict(zip(names, path.q.T, strict=True)),
            hand_error_m=dict(zip(path.hands, path.hand_error_m.T, strict=True)),
            arm_angle_rad=dict(arm_angles),
        )
        self._animation(stage, path.t, names, path.q, path.fixed)
        if stage == self.shown:
            fixed = {**dict.fromkeys(self.robot.joint_names, 0.0), **path.fixed}
            poses = hand_poses_at(self.robot, path.hands, path.joint_names, path.q, fixed)
            self._hand_path(stage, {hand: T[:, :3, 3] for hand, T in poses.items()})
            self._carried_object(stage, path.t, poses)

    def _animation(
        self, stage: str, t: np.ndarray, names: tuple[str, ...], q: np.ndarray, fixed: Mapping[str, float]
    ) -> None:
        """The robot of ``stage`` on ``/tf`` at :func:`~dualarm.record.sink.animation_rows`."""
        rows = animation_rows(t)
        self._tf(stage, t[rows], {**fixed, **dict(zip(names, q[rows].T, strict=True))})

    def _limits(self, stage: str, names: tuple[str, ...], limits: Mapping[str, np.ndarray]) -> None:
        lower, upper = self.robot.lower_upper(names)
        values = {"lower": lower, "upper": upper, **limits}
        self._json(f"{STAGE_TOPICS[stage]}/limits", schemas.JOINT_LIMITS).log(
            {
                "t": 0.0,
                "rep": 0,
                **{
                    key: dict(zip(names, np.asarray(v, dtype=float).tolist(), strict=False))
                    for key, v in values.items()
                },
            },
            log_time=0,
        )

    def _carried_object(self, stage: str, t: np.ndarray, hand_poses: Mapping[str, np.ndarray]) -> None:
        """The carried object on ``/<stage>/object``: a SceneUpdate cube in ``world``, the shown stage's only.

        Moved with its master hand (``hand_poses``: hand -> (K, 4, 4) [m]) at the animation's times of ``t``.
        """
        carried, poses = self._carried, carried_poses(self._carried, hand_poses)
        if stage != self.shown or carried is None or poses is None or not len(t):
            return
        channel = SceneUpdateChannel(f"{STAGE_TOPICS[stage]}/object", context=self._context)
        size = Vector3(x=carried.size_m[0], y=carried.size_m[1], z=carried.size_m[2])
        color = Color(**{c: v / 255 for c, v in zip("rgb", OBJECT_COLOR, strict=True)}, a=1.0)
        rows = animation_rows(t)
        for T, time in zip(poses[rows], t[rows].tolist(), strict=True):
            pose = _pose(T)
            entity = SceneEntity(
                timestamp=Timestamp(sec=_ns(time) // 10**9, nsec=_ns(time) % 10**9),
                frame_id="world",
                id=carried.name,
                cubes=[CubePrimitive(pose=pose, size=size, color=color)],
            )
            channel.log(SceneUpdate(entities=[entity]), log_time=_ns(time))

    def _hand_path(self, stage: str, positions: Mapping[str, np.ndarray]) -> None:
        """Each hand's path (M, 3) [m] in ``stage`` on ``/<stage>/hand_path``: the shown stage's.

        Foxglove lines, the stage's colour.
        """
        if stage == self.shown:
            color = STAGE_COLORS.get(stage, (200, 200, 200))
            self._lines(
                f"{STAGE_TOPICS[stage]}/hand_path",
                "world",
                positions,
                Color(r=color[0] / 255, g=color[1] / 255, b=color[2] / 255, a=1.0),
            )

    def _lines(self, topic: str, frame: str, positions: Mapping[str, np.ndarray], color: Color | None = None) -> None:
        """Paths (name -> (M, 3) [m]) as Foxglove line strips in ``frame``, once at t = 0 on ``topic``.

        Each hand in its colour unless ``color``.
        """
        entities = []
        for name, p in positions.items():
            r, g, b = HAND_COLORS.get(name, (200, 200, 200))
            line = LinePrimitive(
                type=LinePrimitiveLineType.LineStrip,
                pose=Pose(position=Vector3(x=0.0, y=0.0, z=0.0), orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
                thickness=3.0,
                scale_invariant=True,
                points=[Point3(x=float(x), y=float(y), z=float(z)) for x, y, z in np.asarray(p, dtype=float)],
                color=color or Color(r=r / 255, g=g / 255, b=b / 255, a=1.0),
            )
            entities.append(
                SceneEntity(timestamp=Timestamp.from_epoch_secs(0.0), frame_id=frame, id=name, lines=[line])
            )
        SceneUpdateChannel(topic, context=self._context).log(SceneUpdate(entities=entities), log_time=0)

    def trajectory(
        self,
        traj: JointTrajectory,
        limits: Mapping[str, np.ndarray],
        hand_positions: Mapping[str, np.ndarray],
        extras: Mapping[str, np.ndarray] = {},
    ) -> None:
        """A retime, smooth or approach stage's product (``traj.stage``; the approach on its own clock).

        ``/<stage>/limits`` once (position limits and ``limits``: kind -> (n,) values, kinds
        ``velocity`` [rad/s], ``acceleration`` [rad/s^2], ``jerk`` [rad/s^3]), ``/<stage>/sample``
        per sample (with ``extras``: name -> (M, n), e.g. ``jerk``, ``deviation_rad``, and the
        hands' ``hand_positions``: hand -> (M, 3) [m]), the robot on ``/tf``.
        """
        stage, names = traj.stage, traj.joint_names
        if stage not in self.stages:
            return
        self._limits(stage, names, limits)
        channel = self._json(f"{STAGE_TOPICS[stage]}/sample", schemas.TRAJECTORY_SAMPLE)
        series = {"velocity": traj.qd, "acceleration": traj.qdd, **extras}
        encode = _encoder(traj.q, *series.values(), *hand_positions.values())
        for k in range(len(traj)):
            t = float(traj.t[k])
            channel.log(
                encode(
                    {
                        "t": t,
                        "rep": int(traj.rep[k]),
                        "position": dict(zip(names, traj.q[k].tolist(), strict=True)),
                        **{key: dict(zip(names, v[k].tolist(), strict=False)) for key, v in series.items()},
                        "hand_position": {hand: _vec(p[k]) for hand, p in hand_positions.items()},
                    }
                ),
                log_time=_ns(t),
            )
        self._extents(f"{STAGE_TOPICS[stage]}/sample", traj.t, position=dict(zip(names, traj.q.T, strict=True)))
        self._animation(stage, traj.t, names, traj.q, traj.fixed)
        self._hand_path(stage, hand_positions)

    def execution(self, log: ExecutionLog) -> None:
        """The execute stage's product.

        ``/execute/sample`` per physics step (measured joints, the command, hand positions,
        ``hand_error_m``: hand -> [m], contact counts), ``/execute/contacts`` per step and pair
        that touched (both names, the depth, whether the task expects it), the robot on ``/tf``;
        the approach played before, on its own clock, as ``/approach/executed`` and
        ``/approach/contacts``.
        """
        if "execute" not in self.stages:
            return
        self._executed(log, f"{STAGE_TOPICS['execute']}/sample", f"{STAGE_TOPICS['execute']}/contacts")
        if len(log.t):
            self._animation("execute", log.t, log.joint_names, log.q, log.fixed)
        self._hand_path("execute", {hand: T[:, :3, 3] for hand, T in log.hand_poses.items()})
        self._carried_object("execute", log.t, log.hand_poses)
        if log.approach is not None:
            self._executed(log.approach, f"{STAGE_TOPICS['approach']}/executed", f"{STAGE_TOPICS['approach']}/contacts")

    def _executed(self, log: ExecutionLog, samples: str, contacts: str) -> None:
        """One played trajectory's steps on topic ``samples``, its contacts on ``contacts``."""
        names = log.joint_names
        channel = self._json(samples, schemas.EXECUTED_SAMPLE)
        positions = {hand: T[:, :3, 3] for hand, T in log.hand_poses.items()}
        encode = _encoder(log.q, log.qd, log.q_command, *positions.values(), *log.hand_error_m.values())
        for k in range(len(log.t)):
            t = float(log.t[k])
            channel.log(
                encode(
                    {
                        "t": t,
                        "rep": int(log.rep[k]),
                        "position": dict(zip(names, log.q[k].tolist(), strict=True)),
                        "velocity": dict(zip(names, log.qd[k].tolist(), strict=True)),
                        "command": dict(zip(names, log.q_command[k].tolist(), strict=True)),
                        "hand_position": {hand: _vec(p[k]) for hand, p in positions.items()},
                        "hand_error_m": {hand: float(e[k]) for hand, e in log.hand_error_m.items()},
                        "self_contacts": int(log.self_contacts[k]),
                        "environment_contacts": int(log.environment_contacts[k]),
                        "expected_contacts": int(log.expected_contacts[k]),
                    }
                ),
                log_time=_ns(t),
            )
        self._extents(
            samples, log.t, position=dict(zip(names, log.q.T, strict=True)), hand_error_m=dict(log.hand_error_m)
        )
        for kind in ("self", "environment", "expected"):
            extend_range(self._ranges, message_path(samples, f"{kind}_contacts"), getattr(log, f"{kind}_contacts"))
        touching = self._json(contacts, schemas.CONTACT)
        for e in log.contact_events:
            touching.log(
                {
                    "t": e.t_s,
                    "rep": e.rep,
                    "first": e.first,
                    "second": e.second,
                    "depth_m": e.depth_m,
                    "expected": e.expected,
                },
                log_time=_ns(e.t_s),
            )

    def environment(self, objects, carried=None) -> None:
        """A task's fixed objects once on ``/task/environment`` (SceneUpdate); the carried one is kept.

        The objects: :class:`~dualarm.tasks.schema.EnvironmentObject`, poses in the robot base
        frame, ``world``; ``carried``: a :class:`~dualarm.tasks.schema.CarriedObject` or None, drawn
        with the shown stage's hands (:meth:`_carried_object`).
        """
        self._carried = carried
        if "path" not in self.stages:
            return
        entities = []
        for obj in objects:
            T = pose_matrix(obj.pose.position, obj.pose.rpy)
            pose = _pose(T)
            color = Color(r=0.55, g=0.45, b=0.35, a=0.8)
            if obj.shape == "box":
                size = obj.size_m
                cube = CubePrimitive(pose=pose, size=Vector3(x=size[0], y=size[1], z=size[2]), color=color)
                entity = SceneEntity(
                    timestamp=Timestamp.from_epoch_secs(0.0), frame_id="world", id=obj.name, cubes=[cube]
                )
            elif obj.shape == "cylinder":
                d = 2 * obj.radius_m
                cylinder = CylinderPrimitive(
                    pose=pose, size=Vector3(x=d, y=d, z=obj.height_m), bottom_scale=1.0, top_scale=1.0, color=color
                )
                entity = SceneEntity(
                    timestamp=Timestamp.from_epoch_secs(0.0), frame_id="world", id=obj.name, cylinders=[cylinder]
                )
            else:
                d = 2 * obj.radius_m
                sphere = SpherePrimitive(pose=pose, size=Vector3(x=d, y=d, z=d), color=color)
                entity = SceneEntity(
                    timestamp=Timestamp.from_epoch_secs(0.0), frame_id="world", id=obj.name, spheres=[sphere]
                )
            entities.append(entity)
        if entities:
            SceneUpdateChannel(f"{STAGE_TOPICS['path']}/environment", context=self._context).log(
                SceneUpdate(entities=entities), log_time=0
            )

    def reference(self, ref: CartesianReference) -> None:
        """The path stage's product: one ``/task/reference/<hand>`` message per sample.

        The hands' whole paths once on ``/task/reference_path`` (Foxglove line strips in the
        reference's frame).
        """
        if "path" not in self.stages:
            return
        family = STAGE_TOPICS["path"]
        frame = ref.frame_in(self.robot)
        self._hands = tuple(ref.hands)
        for hand, hr in ref.hands.items():
            channel = self._json(f"{family}/reference/{hand}", schemas.HAND_REFERENCE)
            quats = quaternion_xyzw(hr.rotation)
            encode = _encoder(hr.position, quats, hr.linear_velocity, hr.angular_velocity)
            for k in range(len(ref)):
                channel.log(
                    encode(
                        {
                            "t": float(ref.t[k]),
                            "rep": int(ref.rep[k]),
                            "segment": int(ref.segment[k]),
                            "frame_id": frame,
                            "position": _vec(hr.position[k]),
                            "orientation": _quat(quats[k]),
                            "linear_velocity": _vec(hr.linear_velocity[k]),
                            "angular_velocity": _vec(hr.angular_velocity[k]),
                        }
                    ),
                    log_time=_ns(ref.t[k]),
                )
        self._lines(f"{family}/reference_path", frame, {hand: hr.position for hand, hr in ref.hands.items()})

    def metrics(self, values: Mapping[str, float], t: float) -> None:
        """The run's metrics on ``/metrics`` at motion time ``t`` [s]."""
        self._json("/metrics", schemas.METRICS, metrics=list(values)).log(
            {"t": t, "rep": 0, "values": dict(values)}, log_time=_ns(t)
        )

    def close(self, manifest: Mapping[str, object]) -> None:
        """Write the Foxglove layout and the manifest as MCAP metadata, and finish the file.

        The layout: ``foxglove-layout.json``.
        """
        layout = foxglove_layout(
            self.robot,
            self.stages,
            self._hands,
            self._joint_names,
            self._ranges,
            self._carried is not None,
            self._description,
        )
        (self.directory / FOXGLOVE_LAYOUT).write_text(json.dumps(layout, indent=1) + "\n")
        self._mcap.write_metadata("manifest", {k: json.dumps(v) for k, v in manifest.items()})
        self._mcap.close()
