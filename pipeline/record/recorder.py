"""The recorder: each stage hands it its product once; it writes ``run.mcap``, ``run.rrd`` and ``foxglove-layout.json``.

MCAP (written with foxglove-sdk, one Context per run so nothing is global): one topic family per
stage (``/task/...`` for the path stage), ``/robot_description`` with the URDF as URDF 1.0 viewers
read it, ``/tf`` with the link frames of one robot, the run's :func:`shown_stage`, under the URDF's
own link names (Foxglove's URDF layer places links by those names, so it can animate one robot),
``/metrics``; the manifest as metadata; the task file, robot.toml and URDF as attachments. Log
time is motion time (each stage from 0), not the wall clock: repetitions and runs line up.

Rerun: the URDF per stage under ``/<stage>/<robot>``, reference paths and each stage's hand traces
in 3D under ``/world``, time series under ``/plots``, and the :func:`blueprint` the run opens on,
sent before any data.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import foxglove
import numpy as np
import orjson
import rerun as rr
import rerun.blueprint as rrb
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

from dualarm.ik.joint_path import JointPath
from dualarm.interrupt import held
from dualarm.model.kinematics import joint_transforms
from dualarm.model.poses import pose_matrix, quaternion_xyzw
from dualarm.model.robot import Robot
from dualarm.model.urdf import viewer_urdf
from dualarm.paths.reference import CartesianReference
from dualarm.record import schemas
from dualarm.record.foxglove_layout import foxglove_layout
from dualarm.record.run_dir import FOXGLOVE_LAYOUT
from dualarm.record.sink import NullSink, shown_stage
from dualarm.retime.trajectory import JointTrajectory
from dualarm.tasks.load import hand_poses

if TYPE_CHECKING:  # pybullet is imported only by runs that execute
    from dualarm.execute.simulate import ExecutionLog


#: MCAP topic family of each stage.
STAGE_TOPICS = {"path": "/task", "ik": "/ik", "plan": "/plan", "retime": "/retime", "smooth": "/smooth", "approach": "/approach", "execute": "/execute"}
TIMELINE = "time"
#: Colour of each hand's reference path.
HAND_COLORS = {"left": (40, 120, 230), "right": (230, 90, 40)}
#: Colour of each stage's hand traces, one per stage so that the traces tell apart where they part.
STAGE_COLORS = {"ik": (60, 170, 80), "plan": (60, 170, 80), "retime": (150, 90, 200), "smooth": (0, 170, 170), "approach": (150, 150, 150), "execute": (220, 40, 40)}
#: Where the 3D views look from: the whole 1.6 m humanoid from its front right.
EYE = rrb.EyeControls3D(position=[2.4, -1.5, 1.5], look_target=[0.2, 0.0, 0.8], eye_up=[0.0, 0.0, 1.0])
#: The limit line of the ratio plots.
LIMIT_LINE = rr.SeriesLines(colors=[(200, 0, 0)], widths=[2.0], names=["limit"])


def blueprint(robot: Robot, stages: Sequence[str], focus: str | None = None) -> rrb.Blueprint:
    """The Rerun layout a run of ``stages`` opens on, centred on the stage ``focus`` (default :func:`shown_stage`).

    Tab "run": the ``focus`` robot with the reference and its hand paths in one 3D view, beside
    plots grouped by quantity: hand errors; velocity, acceleration and jerk over their limits
    (the limit is the line at 1); joint positions, arm angles and contacts. Tab "stages": one 3D
    view per stage, each with its robot and hand traces on its own clock. The URDF's collision
    shapes are logged but hidden.
    """
    focus = focus or shown_stage(stages)
    hidden = [f"- /{stage}/{robot.urdf.name}/collision_geometries/**" for stage in stages]
    scene = ["+ /world/reference/**", "+ /world/environment/**"]

    def view3d(stage: str, name: str) -> rrb.Spatial3DView:
        return rrb.Spatial3DView(origin="/", name=name, contents=[*scene, f"+ /{stage}/**", f"+ /world/{stage}/**", *hidden], eye_controls=EYE)

    def plot(name: str, *paths: str, legend: bool = True) -> rrb.TimeSeriesView:
        return rrb.TimeSeriesView(origin="/plots", name=name, contents=[f"+ /plots/{p}/**" for p in paths], plot_legend=rrb.PlotLegend(corner=rrb.Corner2D.RightTop, visible=legend))

    driven = next((s for s in ("smooth", "retime") if s in stages), focus) if focus == "execute" else focus
    solved = next((s for s in ("ik", "plan") if s in stages), None)
    plots: list[rrb.Container | rrb.View] = [
        plot("hand error [m]", *[f"{s}/hand_error_m" for s in (solved, focus) if s]),
        rrb.Tabs(*[plot(f"{kind} / limit", f"{driven}/{kind}_ratio") for kind in ("velocity", "acceleration", "jerk")]),
        rrb.Tabs(
            plot(f"joint positions [rad] ({driven})", f"{driven}/position", legend=False),
            *([plot("arm angle [rad]", f"{solved}/arm_angle_rad")] if solved == "ik" else []),
            *([plot("contacts", "execute/contacts"), plot("tracking error [rad]", "execute/tracking_error_rad", legend=False)] if focus == "execute" else []),
        ),
    ]
    return rrb.Blueprint(
        rrb.Tabs(
            rrb.Horizontal(view3d(focus, f"{focus}: robot and hand paths"), rrb.Vertical(*plots), column_shares=[3, 2], name="run"),
            rrb.Grid(*[view3d(stage, stage) for stage in stages if stage != "approach"], name="stages"),
        ),
        collapse_panels=True,
    )


#: Period of the robot's animation (/tf and the Rerun URDF) for stages sampled faster [s].
ANIMATION_PERIOD_S = 0.01


def _ns(t: float) -> int:
    """Motion time [s] -> MCAP log time [ns]."""
    return int(round(t * 1e9))


def _encoder(*values: np.ndarray | float) -> Callable[[dict], bytes]:
    """The JSON encoder of messages made of ``values``: orjson's (a few times faster than json's, for the per-sample topics) when all are finite, else json's, which writes NaN and Infinity as Python and Foxglove read them (orjson writes null)."""
    if all(np.isfinite(np.asarray(v, dtype=float)).all() for v in values):
        return orjson.dumps
    return lambda message: json.dumps(message).encode()


def _vec(v) -> dict[str, float]:
    return {"x": float(v[0]), "y": float(v[1]), "z": float(v[2])}


def _quat(q) -> dict[str, float]:
    return {"x": float(q[0]), "y": float(q[1]), "z": float(q[2]), "w": float(q[3])}


class Recorder(NullSink):
    """The sink that writes one run's ``run.mcap`` and ``run.rrd`` into ``directory``.

    Args:
        directory: the (temporary) run directory.
        run_id: the run's id (also the Rerun recording id).
        robot: the robot, for /tf and the URDF.
        attachments: file name -> text, stored in the MCAP (task file, robot.toml, URDF).
        stages: the stages recorded (the others' products are dropped; for the layout the run opens on and the robot on ``/tf``).
        on_begin: called with each stage's name as it begins.
    """

    def __init__(self, directory: Path, run_id: str, robot: Robot, attachments: Mapping[str, str], stages: Sequence[str] = tuple(STAGE_TOPICS), on_begin: Callable[[str], None] | None = None) -> None:
        super().__init__(on_begin)
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
        self._tf_channel = FrameTransformsChannel("/tf", context=self._context)
        with held():  # the layout first, so that the viewer never shows a default one while loading
            self._rr = rr.RecordingStream("dualarm", recording_id=run_id)
            self._rr.save(directory / "run.rrd")
            self._rr.send_blueprint(blueprint(robot, self.stages), make_active=True, make_default=True)
        self._robot_trees: dict[str, rr.urdf.UrdfTree] = {}
        self._closed = False
        for name, text in attachments.items():
            media = "application/xml" if name.endswith(".urdf") else "application/toml"
            self._mcap.attach(log_time=0, create_time=0, name=name, media_type=media, data=text.encode())
        self._json("/robot_description", schemas.ROBOT_DESCRIPTION).log({"data": viewer_urdf(robot.urdf.path.read_text())}, log_time=0)
        self._rr.log("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)

    # -- low level -------------------------------------------------------------------------------
    def _json(self, topic: str, schema: dict, **keys: Sequence[str]) -> foxglove.Channel:
        """The JSON channel ``topic``, opened on first use with ``schema``, its maps keyed by the robot's joints and hands (and ``keys``: kind -> names)."""
        if topic not in self._channels:
            self._channels[topic] = foxglove.Channel(topic, schema=schemas.named(schema, {**self._keys, **keys}), context=self._context)
        return self._channels[topic]

    def _rerun_robot(self, stage: str) -> rr.urdf.UrdfTree:
        """The URDF under ``/<stage>``, with frames prefixed ``<stage>/`` and rooted at the world (logged on first use)."""
        if stage not in self._robot_trees:
            # one static entity per stage robot: static data logged twice to one entity replaces the first
            tree = rr.urdf.UrdfTree.from_file_path(self.robot.urdf.path, entity_path_prefix=stage, frame_prefix=f"{stage}/", static_transform_entity_path=f"/{stage}/tf_static")
            tree.log_urdf_to_recording(self._rr)
            self._rr.log(
                f"{stage}/root",
                rr.Transform3D(parent_frame="tf#/", child_frame=f"{stage}/{self.robot.urdf.root}"),
                static=True,
            )
            self._robot_trees[stage] = tree
        return self._robot_trees[stage]

    # -- products ----------------------------------------------------------------------------------
    def _tf(self, stage: str, t: np.ndarray | float, q: Mapping[str, np.ndarray | float]) -> None:
        """The robot's link frames on ``/tf`` at times ``t`` (K,) [s] (joint name -> (K,) positions [rad]), root hung from ``world``: the shown stage's only."""
        if stage != self.shown:
            return
        t = np.atleast_1d(np.asarray(t, dtype=float))
        q = {name: np.broadcast_to(np.asarray(v, dtype=float), t.shape) for name, v in q.items()}
        links = [("world", self.robot.urdf.root, np.broadcast_to(np.eye(4), (len(t), 4, 4)))] + joint_transforms(self.robot.urdf.joints, q)
        frames = [(parent, child, T[:, :3, 3].tolist(), quaternion_xyzw(T[:, :3, :3]).tolist()) for parent, child, T in links]
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

    def _rerun_motion(self, stage: str, t: np.ndarray, q: Mapping[str, np.ndarray]) -> None:
        """Animate ``stage``'s robot in Rerun: joint name -> positions (N,) at times t (N,) [s]."""
        tree = self._rerun_robot(stage)
        times = rr.TimeColumn(TIMELINE, duration=t)
        for joint in tree.joints():
            if joint.joint_type != "fixed":
                values = q.get(joint.name, np.zeros(len(t)))
                self._rr.send_columns(f"{stage}/transforms/{joint.name}", indexes=[times], columns=joint.compute_transform_columns(np.asarray(values, float).tolist(), clamp=False))

    def _series(self, prefix: str, t: np.ndarray, values: Mapping[str, np.ndarray]) -> None:
        """Rerun time series ``plots/<prefix>/<name>``."""
        times = rr.TimeColumn(TIMELINE, duration=t)
        for name, v in values.items():
            self._rr.send_columns(f"plots/{prefix}/{name}", indexes=[times], columns=rr.Scalars.columns(scalars=np.asarray(v, float)))

    # -- products ----------------------------------------------------------------------------------
    def robot_state(self, stage: str, t: float, q: Mapping[str, float], rep: int = 0) -> None:
        """The robot at configuration ``q`` [rad] at motion time ``t`` [s]: ``/tf`` (frames ``<stage>/<link>``) and ``<family>/joint_state`` in the MCAP, the URDF under ``/<stage>`` in Rerun."""
        if stage not in self.stages:
            return
        self._tf(stage, t, q)
        family = STAGE_TOPICS.get(stage, f"/{stage}")
        self._json(f"{family}/joint_state", schemas.JOINT_STATE).log({"t": t, "rep": rep, "position": {n: float(v) for n, v in q.items()}}, log_time=_ns(t))
        self._rerun_motion(stage, np.array([t]), {n: np.array([v]) for n, v in q.items()})

    def joint_path(self, path: JointPath, velocity_limits: np.ndarray, arm_angles: Mapping[str, np.ndarray], stage: str = "ik") -> None:
        """The IK (or plan) stage's product, under ``stage``'s topics: ``/ik/limits`` once (the robot's position limits and ``velocity_limits`` [rad/s] of the path's joints), ``/ik/sample`` (with each hand's position error [m], orientation error [rad] when measured, and ``arm_angles`` [rad], (N,) per hand) and (TV-GDD) ``/ik/bounds`` per sample, the robot on ``/tf`` as ``ik/<link>``; in Rerun the animated robot under ``/ik`` and every joint's position, velocity and bounds, the hand errors and the arm angles as time series."""
        if stage not in self.stages:
            return
        family = STAGE_TOPICS[stage]
        names = self._joint_names = path.joint_names
        self._limits(stage, names, {"velocity": velocity_limits})
        sample = self._json(f"{family}/sample", schemas.IK_SAMPLE)
        bounds = self._json(f"{family}/bounds", schemas.JOINT_BOUNDS) if path.extras else None
        angle = path.hand_orientation_error_rad
        measured = bool(np.isfinite(angle).all())  # a planner's path measures no orientation: the field is left out
        encode = _encoder(path.q, path.qd, path.solve_time_s, path.hand_error_m, angle if measured else 0.0, *arm_angles.values(), *path.extras.values())
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
                        "position": dict(zip(names, path.q[k].tolist())),
                        "velocity": dict(zip(names, path.qd[k].tolist())),
                        "hand_error_m": dict(zip(path.hands, path.hand_error_m[k].tolist())),
                        **({"hand_orientation_error_rad": dict(zip(path.hands, angle[k].tolist())), "task_space": path.task_space} if measured else {}),
                        "arm_angle_rad": {hand: float(psi[k]) for hand, psi in arm_angles.items()},
                    }
                ),
                log_time=_ns(t),
            )
            if bounds is not None:
                bounds.log(encode({"t": t, "rep": rep, **{key: dict(zip(names, v[k].tolist())) for key, v in path.extras.items()}}), log_time=_ns(t))
        self._animation(stage, path.t, names, path.q, path.fixed)
        self._series(f"{stage}/position", path.t, dict(zip(names, path.q.T)))
        self._series(f"{stage}/velocity", path.t, dict(zip(names, path.qd.T)))
        for key, v in path.extras.items():
            self._series(f"{stage}/{key}", path.t, dict(zip(names, v.T)))
        self._series(f"{stage}/hand_error_m", path.t, dict(zip(path.hands, path.hand_error_m.T)))
        if measured:
            self._series(f"{stage}/hand_orientation_error_rad", path.t, dict(zip(path.hands, angle.T)))
        self._series(f"{stage}/solve_time_s", path.t, {"all": path.solve_time_s})
        self._series(f"{stage}/arm_angle_rad", path.t, arm_angles)
        self._hand_traces(stage, {hand: T[:, :3, 3] for hand, T in hand_poses(self.robot, path.hands, path.joint_names, path.q, {**dict.fromkeys(self.robot.joint_names, 0.0), **path.fixed}).items()})

    def _animation(self, stage: str, t: np.ndarray, names: tuple[str, ...], q: np.ndarray, fixed: Mapping[str, float]) -> None:
        """The robot of ``stage`` on ``/tf`` and in Rerun, every :data:`ANIMATION_PERIOD_S` and at the last sample."""
        stride = max(1, int(round(ANIMATION_PERIOD_S / float(np.median(np.diff(t))))) if len(t) > 1 else 1)
        rows = np.unique(np.r_[np.arange(0, len(t), stride), len(t) - 1])
        self._tf(stage, t[rows], {**fixed, **dict(zip(names, q[rows].T))})
        self._rerun_motion(stage, t[rows], {**{n: np.full(len(rows), v) for n, v in fixed.items()}, **dict(zip(names, q[rows].T))})

    def _limits(self, stage: str, names: tuple[str, ...], limits: Mapping[str, np.ndarray]) -> None:
        lower, upper = self.robot.lower_upper(names)
        values = {"lower": lower, "upper": upper, **limits}
        self._json(f"{STAGE_TOPICS[stage]}/limits", schemas.JOINT_LIMITS).log(
            {"t": 0.0, "rep": 0, **{key: dict(zip(names, np.asarray(v, dtype=float).tolist())) for key, v in values.items()}}, log_time=0
        )

    def _hand_traces(self, stage: str, positions: Mapping[str, np.ndarray]) -> None:
        """Each hand's path (M, 3) [m] in ``stage``: in Rerun under ``/world/<stage>/<hand>``, in the stage's colour; the shown stage's also on ``/<stage>/hand_path`` (Foxglove lines)."""
        color = STAGE_COLORS.get(stage, (200, 200, 200))
        for hand, p in positions.items():
            self._rr.log(f"world/{stage}/{hand}", rr.LineStrips3D([p], colors=[color], radii=0.0015), static=True)
        if stage == self.shown:
            self._lines(f"{STAGE_TOPICS[stage]}/hand_path", "world", positions, Color(r=color[0] / 255, g=color[1] / 255, b=color[2] / 255, a=1.0))

    def _lines(self, topic: str, frame: str, positions: Mapping[str, np.ndarray], color: Color | None = None) -> None:
        """Paths (name -> (M, 3) [m]) as Foxglove line strips in ``frame``, once at t = 0 on ``topic`` (each hand in its colour unless ``color``)."""
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
            entities.append(SceneEntity(timestamp=Timestamp.from_epoch_secs(0.0), frame_id=frame, id=name, lines=[line]))
        SceneUpdateChannel(topic, context=self._context).log(SceneUpdate(entities=entities), log_time=0)

    def trajectory(
        self,
        traj: JointTrajectory,
        limits: Mapping[str, np.ndarray],
        hand_positions: Mapping[str, np.ndarray],
        extras: Mapping[str, np.ndarray] = {},
    ) -> None:
        """A retime, smooth or approach stage's product (``traj.stage``; the approach on its own clock).

        MCAP: ``/<stage>/limits`` once (position limits and ``limits``: kind -> (n,) values, kinds
        ``velocity`` [rad/s], ``acceleration`` [rad/s^2], ``jerk`` [rad/s^3]), ``/<stage>/sample``
        per sample (with ``extras``: name -> (M, n), e.g. ``jerk``, ``deviation_rad``, and the
        hands' ``hand_positions``: hand -> (M, 3) [m]), the robot on ``/tf`` as ``<stage>/<link>``.
        Rerun: the robot under ``/<stage>``, the hand traces under ``/world/<stage>``, and under
        ``/plots/<stage>`` the positions and each quantity's ratio to its limit (|x| / limit,
        with the limit as the line ``limit`` at 1).
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
                        "position": dict(zip(names, traj.q[k].tolist())),
                        **{key: dict(zip(names, v[k].tolist())) for key, v in series.items()},
                        "hand_position": {hand: _vec(p[k]) for hand, p in hand_positions.items()},
                    }
                ),
                log_time=_ns(t),
            )
        self._animation(stage, traj.t, names, traj.q, traj.fixed)
        self._hand_traces(stage, hand_positions)
        self._series(f"{stage}/position", traj.t, dict(zip(names, traj.q.T)))
        for kind, limit in limits.items():
            ratio = np.abs(series[kind]) / np.asarray(limit, dtype=float)
            self._series(f"{stage}/{kind}_ratio", traj.t, {**dict(zip(names, ratio.T)), "limit": np.ones(len(traj))})
            self._rr.log(f"plots/{stage}/{kind}_ratio/limit", LIMIT_LINE, static=True)
        if "deviation_rad" in extras:
            self._series(f"{stage}/deviation_rad", traj.t, dict(zip(names, extras["deviation_rad"].T)))

    def execution(self, log: "ExecutionLog") -> None:
        """The execute stage's product.

        MCAP: ``/execute/sample`` per physics step (measured joints, the command, hand positions,
        ``hand_error_m``: hand -> [m], contact counts), ``/execute/contacts`` per step and pair
        that touched (both names, the depth, whether the task expects it), the robot on ``/tf`` as
        ``execute/<link>``; the approach played before, on its own clock, as
        ``/approach/executed`` and ``/approach/contacts``. Rerun: the robot under ``/execute``,
        the measured hand traces under ``/world/execute``, and under ``/plots/execute`` the hand
        errors, contacts and the joints' tracking error (``/plots/approach/executed_*`` for the
        approach).
        """
        if "execute" not in self.stages:
            return
        self._executed(log, f"{STAGE_TOPICS['execute']}/sample", f"{STAGE_TOPICS['execute']}/contacts", "execute/")
        if len(log.t):
            self._animation("execute", log.t, log.joint_names, log.q, log.fixed)
        self._hand_traces("execute", {hand: T[:, :3, 3] for hand, T in log.hand_poses.items()})
        if log.approach is not None:
            self._executed(log.approach, f"{STAGE_TOPICS['approach']}/executed", f"{STAGE_TOPICS['approach']}/contacts", "approach/executed_")

    def _executed(self, log: "ExecutionLog", samples: str, contacts: str, plots: str) -> None:
        """One played trajectory's steps on topic ``samples``, its contacts on ``contacts``, its plots named ``plots/<plots><quantity>``."""
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
                        "position": dict(zip(names, log.q[k].tolist())),
                        "velocity": dict(zip(names, log.qd[k].tolist())),
                        "command": dict(zip(names, log.q_command[k].tolist())),
                        "hand_position": {hand: _vec(p[k]) for hand, p in positions.items()},
                        "hand_error_m": {hand: float(e[k]) for hand, e in log.hand_error_m.items()},
                        "self_contacts": int(log.self_contacts[k]),
                        "environment_contacts": int(log.environment_contacts[k]),
                        "expected_contacts": int(log.expected_contacts[k]),
                    }
                ),
                log_time=_ns(t),
            )
        touching = self._json(contacts, schemas.CONTACT)
        for e in log.contact_events:
            touching.log({"t": e.t_s, "rep": e.rep, "first": e.first, "second": e.second, "depth_m": e.depth_m, "expected": e.expected}, log_time=_ns(e.t_s))
        self._series(f"{plots}hand_error_m", log.t, dict(log.hand_error_m))
        self._series(f"{plots}tracking_error_rad", log.t, dict(zip(names, np.abs(log.q - log.q_command).T)))
        self._series(f"{plots}contacts", log.t, {"self": log.self_contacts, "environment": log.environment_contacts, "expected": log.expected_contacts})

    def environment(self, objects) -> None:
        """A task's fixed objects (:class:`~dualarm.tasks.schema.EnvironmentObject`, poses in the robot base frame, ``world``): once on ``/task/environment`` (Foxglove SceneUpdate) and in Rerun under ``/world/environment/<name>``."""
        if "path" not in self.stages:
            return
        entities = []
        for obj in objects:
            T = pose_matrix(obj.pose.position, obj.pose.rpy)
            x, y, z, w = quaternion_xyzw(T[:3, :3]).tolist()
            pose = Pose(position=Vector3(x=T[0, 3], y=T[1, 3], z=T[2, 3]), orientation=Quaternion(x=x, y=y, z=z, w=w))
            color = Color(r=0.55, g=0.45, b=0.35, a=0.8)
            path = f"world/environment/{obj.name}"
            archetype: rr.Boxes3D | rr.Cylinders3D | rr.Ellipsoids3D
            if obj.shape == "box":
                size = obj.size_m
                cube = CubePrimitive(pose=pose, size=Vector3(x=size[0], y=size[1], z=size[2]), color=color)
                entity = SceneEntity(timestamp=Timestamp.from_epoch_secs(0.0), frame_id="world", id=obj.name, cubes=[cube])
                archetype = rr.Boxes3D(half_sizes=[[s / 2 for s in size]], centers=[T[:3, 3]], quaternions=[[x, y, z, w]], fill_mode="solid")
            elif obj.shape == "cylinder":
                d = 2 * obj.radius_m
                cylinder = CylinderPrimitive(pose=pose, size=Vector3(x=d, y=d, z=obj.height_m), bottom_scale=1.0, top_scale=1.0, color=color)
                entity = SceneEntity(timestamp=Timestamp.from_epoch_secs(0.0), frame_id="world", id=obj.name, cylinders=[cylinder])
                archetype = rr.Cylinders3D(lengths=[obj.height_m], radii=[obj.radius_m], centers=[T[:3, 3]], quaternions=[[x, y, z, w]], fill_mode="solid")
            else:
                d = 2 * obj.radius_m
                sphere = SpherePrimitive(pose=pose, size=Vector3(x=d, y=d, z=d), color=color)
                entity = SceneEntity(timestamp=Timestamp.from_epoch_secs(0.0), frame_id="world", id=obj.name, spheres=[sphere])
                archetype = rr.Ellipsoids3D(half_sizes=[[obj.radius_m] * 3], centers=[T[:3, 3]], fill_mode="solid")
            entities.append(entity)
            self._rr.log(path, archetype, static=True)
        if entities:
            SceneUpdateChannel(f"{STAGE_TOPICS['path']}/environment", context=self._context).log(SceneUpdate(entities=entities), log_time=0)

    def reference(self, ref: CartesianReference) -> None:
        """The path stage's product: one ``/task/reference/<hand>`` message per sample, the hands' whole paths once on ``/task/reference_path`` (Foxglove line strips in the reference's frame), and in Rerun the paths as 3D line strips and the position components as time series."""
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
            self._rr.log(
                f"world/reference/{hand}",
                rr.LineStrips3D([hr.position], colors=[HAND_COLORS.get(hand, (200, 200, 200))], radii=0.003),
                static=True,
            )
            self._series(f"reference/{hand}", ref.t, {**{f"position/{a}": hr.position[:, i] for i, a in enumerate("xyz")}, "rep": ref.rep})
        self._lines(f"{family}/reference_path", frame, {hand: hr.position for hand, hr in ref.hands.items()})

    def metrics(self, values: Mapping[str, float], t: float) -> None:
        """The run's metrics on ``/metrics`` at motion time ``t`` [s]."""
        self._json("/metrics", schemas.METRICS, metrics=list(values)).log({"t": t, "rep": 0, "values": dict(values)}, log_time=_ns(t))

    def close(self, manifest: Mapping[str, object]) -> None:
        """Write the manifest as MCAP metadata, finish both files, and write the Foxglove layout (``foxglove-layout.json``)."""
        if self._closed:
            return
        self._closed = True
        layout = foxglove_layout(self.robot, self.stages, self._hands, self._joint_names)
        (self.directory / FOXGLOVE_LAYOUT).write_text(json.dumps(layout, indent=1) + "\n")
        self._mcap.write_metadata("manifest", {k: json.dumps(v) for k, v in manifest.items()})
        self._mcap.close()
        self._rr.flush()
        self._rr.disconnect()
        self.finish()
