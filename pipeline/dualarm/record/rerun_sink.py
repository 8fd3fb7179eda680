"""The Rerun sink: each stage's product once into ``run.rrd``.

And the :func:`blueprint` the run opens on.

The URDF per stage under ``/<stage>/<robot>``, reference paths and each stage's hand traces in 3D
under ``/world``, time series under ``/plots``; the blueprint is sent before any data, and again at
the end with each plot's value range (activated last).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from dualarm.contracts.joint_path import JointPath
from dualarm.contracts.reference import CartesianReference
from dualarm.contracts.run import ALL_STAGES
from dualarm.contracts.trajectory import JointTrajectory
from dualarm.interrupt import held
from dualarm.model.poses import pose_matrix, quaternion_xyzw
from dualarm.model.robot import Robot
from dualarm.record.sink import (
    HAND_COLORS,
    OBJECT_COLOR,
    SERIES_COLORS,
    STAGE_COLORS,
    NullSink,
    animation_rows,
    carried_poses,
    extend_range,
    plot_range,
    robot_box,
    shown_stage,
)
from dualarm.tasks.task import hand_poses_at

if TYPE_CHECKING:  # pybullet is imported only by runs that execute
    from dualarm.contracts.execution import ExecutionLog

#: Rerun's timeline of motion time.
TIMELINE = "time"
#: Where the 3D views look, per metre of the robot's largest side (:func:`~dualarm.record.sink.robot_box`): at the
#: box's centre moved forward by TARGET_AHEAD, from EYE_OFFSET away (its front right, a little above). For the 1.59 m
#: humanoid: at (0.2, 0, 0.8) from (2.4, -1.5, 1.5), the whole robot in view.
TARGET_AHEAD = np.array([0.126, 0.0, 0.0])
EYE_OFFSET = np.array([1.384, -0.943, 0.440])
#: The quantities each stage's plots give as ratios to their limits: the IK's (or plan's) velocity by finite
#: differences of its samples, the timed stages' velocity, acceleration and jerk.
RATIOS = {
    "ik": ("velocity",),
    "plan": ("velocity",),
    "retime": ("velocity", "acceleration", "jerk"),
    "smooth": ("velocity", "acceleration", "jerk"),
}
#: The limit line of the ratio plots.
LIMIT_LINE = rr.SeriesLines(colors=[(200, 0, 0)], widths=[2.0], names=["limit"])


def blueprint(
    robot: Robot,
    stages: Sequence[str],
    focus: str | None = None,
    ranges: Mapping[str, tuple[float, float]] | None = None,
    clocks: Mapping[str, tuple[float, float]] | None = None,
) -> rrb.Blueprint:
    """The Rerun layout a run of ``stages`` opens on, centred on the stage ``focus``.

    ``focus`` defaults to :func:`shown_stage`. ``ranges``: the lowest and highest value logged under each
    ``/plots/<path>``; each plot then shows its values' range, no narrower than its unit's floor
    (:func:`~dualarm.record.sink.plot_range`); None: Rerun's own range (the layout sent before the data).
    ``clocks``: each stage's first and last time [s]. Each stage runs on its own clock from 0 (the IK on the task's,
    the timed and executed motion on theirs: 20 s against 6.3 s on carry_box), so each plot's time axis then spans
    its stage's times alone; None: Rerun's own (the whole timeline, shared).

    Tab "run": the ``focus`` robot with the reference and its hand paths in one 3D view, beside
    plots grouped by quantity, each only where the run logs it: the execution's and the IK's hand
    errors (a tab each); the quantities of :data:`RATIOS` over their limits (the limit is the line at 1); joint
    positions, arm angles, the planner's distance to its target, and contacts. Tab "stages": one 3D
    view per stage, each with its robot and hand traces on its own clock. The URDF's collision
    shapes are logged but hidden.
    """
    focus = focus or shown_stage(stages)
    centre, size = robot_box(robot)
    target = centre + size * TARGET_AHEAD
    eye = rrb.EyeControls3D(position=target + size * EYE_OFFSET, look_target=target, eye_up=[0.0, 0.0, 1.0])
    hidden = [f"- /{stage}/{robot.urdf.name}/collision_geometries/**" for stage in stages]
    scene = ["+ /world/reference/**", "+ /world/environment/**"]

    def view3d(stage: str, name: str) -> rrb.Spatial3DView:
        return rrb.Spatial3DView(
            origin="/",
            name=name,
            contents=[*scene, f"+ /{stage}/**", f"+ /world/{stage}/**", *hidden],
            eye_controls=eye,
        )

    def plot(name: str, unit: str, *paths: str, legend: bool = True) -> rrb.TimeSeriesView:
        logged = [ranges[p] for p in paths if ranges and p in ranges]
        clock = (clocks or {}).get(paths[0].split("/")[0])  # a plot's paths are one stage's
        return rrb.TimeSeriesView(
            origin="/plots",
            name=name,
            contents=[f"+ /plots/{p}/**" for p in paths],
            plot_legend=rrb.PlotLegend(corner=rrb.Corner2D.RightTop, visible=legend),
            axis_y=rrb.ScalarAxis(range=plot_range(logged, unit)) if logged else None,
            axis_x=_time_axis(*clock) if clock else None,
        )

    driven = next((s for s in ("smooth", "retime") if s in stages), focus) if focus == "execute" else focus
    solved = next((s for s in ("ik", "plan") if s in stages), None)
    # a hand's pose error: the execution's, the IK's, each on its stage's clock (a planner's is its distance to the
    # target, plotted apart)
    errors = [s for s in dict.fromkeys((focus, solved)) if s in ("ik", "execute")]
    plots: list[rrb.Container | rrb.View] = [
        *([rrb.Tabs(*[plot(f"hand error [m] ({s})", "m", f"{s}/hand_error_m") for s in errors])] if errors else []),
        *(
            [rrb.Tabs(*[plot(f"{kind} / limit", "ratio", f"{driven}/{kind}_ratio") for kind in RATIOS[driven]])]
            if driven in RATIOS
            else []
        ),
        rrb.Tabs(
            *([plot(f"joint positions [rad] ({driven})", "rad", f"{driven}/position")] if driven != "path" else []),
            *([plot("arm angle [rad]", "rad", f"{solved}/arm_angle_rad")] if solved == "ik" else []),
            *([plot("plan: hand to target [m]", "m", "plan/hand_error_m")] if solved == "plan" else []),
            *(
                [
                    plot("contacts", "count", "execute/contacts"),
                    plot("tracking error [rad]", "rad", "execute/tracking_error_rad"),
                ]
                if focus == "execute"
                else []
            ),
        ),
    ]
    return rrb.Blueprint(
        rrb.Tabs(
            rrb.Horizontal(
                view3d(focus, f"{focus}: robot and hand paths"), rrb.Vertical(*plots), column_shares=[3, 2], name="run"
            ),
            rrb.Grid(*[view3d(stage, stage) for stage in stages if stage != "approach"], name="stages"),
        ),
        rrb.TimePanel(timeline=TIMELINE),  # the motion's clock, not the viewer's log_time
        collapse_panels=True,
    )


def _time_axis(start_s: float, end_s: float) -> rrb.TimeAxis:
    """A plot's time axis over [``start_s``, ``end_s``], not linked to the other plots'."""
    return rrb.TimeAxis(
        link=rrb.components.LinkAxis.Independent,
        view_range=rrb.TimeRange(
            start=rrb.TimeRangeBoundary.absolute(seconds=start_s), end=rrb.TimeRangeBoundary.absolute(seconds=end_s)
        ),
    )


class RerunSink(NullSink):
    """The sink that writes one run's ``run.rrd`` into ``directory``.

    Args:
        directory: the (temporary) run directory.
        run_id: the run's id (the Rerun recording id).
        robot: the robot, for the URDF.
        stages: the stages recorded (the others' products are dropped; for the blueprint).
    """

    def __init__(self, directory: Path, run_id: str, robot: Robot, stages: Sequence[str] = ALL_STAGES) -> None:
        super().__init__()
        self.stages = tuple(stages)
        self.robot = robot
        with held():  # the layout first, so that the viewer never shows a default one while loading
            self._rr = rr.RecordingStream("dualarm", recording_id=run_id)
            self._rr.save(directory / "run.rrd")
            self._rr.send_blueprint(blueprint(robot, self.stages), make_active=True, make_default=True)
            self._rr.flush()  # in the file before any data, whatever Rerun's batcher does next
        self._robot_trees: dict[str, rr.urdf.UrdfTree] = {}
        self._ranges: dict[str, tuple[float, float]] = {}  # /plots/<prefix> -> its values' lowest and highest
        self._clocks: dict[str, tuple[float, float]] = {}  # stage -> its first and last time [s]
        self._carried: Any | None = None  # the object both hands carry (environment)
        self._rr.log("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)

    def _rerun_robot(self, stage: str) -> rr.urdf.UrdfTree:
        """The URDF under ``/<stage>``, with frames prefixed ``<stage>/`` and rooted at the world.

        Logged on first use.
        """
        if stage not in self._robot_trees:
            # one static entity per stage robot: static data logged twice to one entity replaces the first
            tree = rr.urdf.UrdfTree.from_file_path(
                self.robot.urdf.path,
                entity_path_prefix=stage,
                frame_prefix=f"{stage}/",
                static_transform_entity_path=f"/{stage}/tf_static",
            )
            tree.log_urdf_to_recording(self._rr)
            self._rr.log(
                f"{stage}/root",
                rr.Transform3D(parent_frame="tf#/", child_frame=f"{stage}/{self.robot.urdf.root}"),
                static=True,
            )
            self._robot_trees[stage] = tree
        return self._robot_trees[stage]

    def _rerun_motion(self, stage: str, t: np.ndarray, q: Mapping[str, np.ndarray]) -> None:
        """Animate ``stage``'s robot in Rerun: joint name -> positions (N,) at times t (N,) [s]."""
        tree = self._rerun_robot(stage)
        extend_range(self._clocks, stage, t)
        times = rr.TimeColumn(TIMELINE, duration=t)
        for joint in tree.joints():
            if joint.joint_type != "fixed":
                values = q.get(joint.name, np.zeros(len(t)))
                self._rr.send_columns(
                    f"{stage}/transforms/{joint.name}",
                    indexes=[times],
                    columns=joint.compute_transform_columns(np.asarray(values, float).tolist(), clamp=False),
                )

    def _series(self, prefix: str, t: np.ndarray, values: Mapping[str, np.ndarray], first_color: int = 0) -> None:
        """Rerun time series ``plots/<prefix>/<name>``."""
        times = rr.TimeColumn(TIMELINE, duration=t)
        for i, (name, v) in enumerate(values.items()):
            if name != "limit":  # a colour of its own in its plot (Rerun's default, from the path's hash, repeats)
                color = SERIES_COLORS[(first_color + i) % len(SERIES_COLORS)]
                self._rr.log(f"plots/{prefix}/{name}", rr.SeriesLines(colors=[color], names=[name]), static=True)
            self._rr.send_columns(
                f"plots/{prefix}/{name}", indexes=[times], columns=rr.Scalars.columns(scalars=np.asarray(v, float))
            )
            extend_range(self._ranges, prefix, v)
        extend_range(self._clocks, prefix.split("/")[0], t)

    def _ratio(
        self, stage: str, kind: str, t: np.ndarray, names: Sequence[str], values: np.ndarray, limit: np.ndarray
    ) -> None:
        """``plots/<stage>/<kind>_ratio``: each joint's |value| / limit, ``values`` (N, n) at ``t`` (N,).

        And the limit, the line at 1.
        """
        ratio = np.abs(values) / np.asarray(limit, dtype=float)
        self._series(f"{stage}/{kind}_ratio", t, {**dict(zip(names, ratio.T, strict=False)), "limit": np.ones(len(t))})
        self._rr.log(f"plots/{stage}/{kind}_ratio/limit", LIMIT_LINE, static=True)

    def robot_state(self, stage: str, t: float, q: Mapping[str, float], rep: int = 0) -> None:
        """The robot at configuration ``q`` [rad] at motion time ``t`` [s]: the URDF under ``/<stage>``."""
        if stage not in self.stages:
            return
        self._rerun_motion(stage, np.array([t]), {n: np.array([v]) for n, v in q.items()})

    def joint_path(
        self, path: JointPath, velocity_limits: np.ndarray, arm_angles: Mapping[str, np.ndarray], stage: str = "ik"
    ) -> None:
        """The IK (or plan) stage's product: the animated robot under ``/<stage>``, time series, hand traces.

        Every joint's position, velocity and bounds, the hand errors and the arm angles as time
        series, and the hand traces.
        """
        if stage not in self.stages:
            return
        names = path.joint_names
        angle = path.hand_orientation_error_rad
        measured = bool(np.isfinite(angle).all())  # a planner's path measures no orientation
        self._animation(stage, path.t, names, path.q, path.fixed)
        self._series(f"{stage}/position", path.t, dict(zip(names, path.q.T, strict=True)))
        self._series(f"{stage}/velocity", path.t, dict(zip(names, path.qd.T, strict=True)))
        if len(path.t) > 1:  # the velocity the samples ask, whatever the method commanded (qd is 0 for some)
            with np.errstate(divide="ignore", invalid="ignore"):  # samples at one time: a gap in the plot
                qd = np.gradient(path.q, axis=0) / np.gradient(path.t)[:, None]
            self._ratio(stage, "velocity", path.t, names, np.where(np.isfinite(qd), qd, np.nan), velocity_limits)
        for key, v in path.extras.items():
            self._series(f"{stage}/{key}", path.t, dict(zip(names, v.T, strict=True)))
        self._series(f"{stage}/hand_error_m", path.t, dict(zip(path.hands, path.hand_error_m.T, strict=True)))
        if measured:
            self._series(f"{stage}/hand_orientation_error_rad", path.t, dict(zip(path.hands, angle.T, strict=True)))
        self._series(f"{stage}/solve_time_s", path.t, {"all": path.solve_time_s})
        self._series(f"{stage}/arm_angle_rad", path.t, arm_angles)
        poses = hand_poses_at(
            self.robot,
            path.hands,
            path.joint_names,
            path.q,
            {**dict.fromkeys(self.robot.joint_names, 0.0), **path.fixed},
        )
        self._hand_traces(stage, {hand: T[:, :3, 3] for hand, T in poses.items()})
        self._carried_object(stage, path.t, poses)

    def _animation(
        self, stage: str, t: np.ndarray, names: tuple[str, ...], q: np.ndarray, fixed: Mapping[str, float]
    ) -> None:
        """The robot of ``stage`` at :func:`~dualarm.record.sink.animation_rows`."""
        rows = animation_rows(t)
        self._rerun_motion(
            stage,
            t[rows],
            {**{n: np.full(len(rows), v) for n, v in fixed.items()}, **dict(zip(names, q[rows].T, strict=True))},
        )

    def _carried_object(self, stage: str, t: np.ndarray, hand_poses: Mapping[str, np.ndarray]) -> None:
        """The object both hands carry under ``/world/<stage>/<name>``, moved with its master hand.

        At the :func:`~dualarm.record.sink.animation_rows` of times ``t`` (K,) [s]; ``hand_poses``: hand -> (K, 4,
        4) [m]. Nothing without one.
        """
        carried, poses = self._carried, carried_poses(self._carried, hand_poses)
        if carried is None or poses is None or not len(t):
            return
        rows = animation_rows(t)
        entity = f"world/{stage}/{carried.name}"
        half = [s / 2 for s in carried.size_m]
        self._rr.log(entity, rr.Boxes3D(half_sizes=[half], colors=[OBJECT_COLOR], fill_mode="solid"), static=True)
        self._rr.send_columns(
            entity,
            indexes=[rr.TimeColumn(TIMELINE, duration=t[rows])],
            columns=rr.Transform3D.columns(
                translation=poses[rows, :3, 3], quaternion=quaternion_xyzw(poses[rows, :3, :3])
            ),
        )

    def _hand_traces(self, stage: str, positions: Mapping[str, np.ndarray]) -> None:
        """Each hand's path (M, 3) [m] in ``stage`` under ``/world/<stage>/<hand>``, in the stage's colour."""
        color = STAGE_COLORS.get(stage, (200, 200, 200))
        for hand, p in positions.items():
            self._rr.log(f"world/{stage}/{hand}", rr.LineStrips3D([p], colors=[color], radii=0.0015), static=True)

    def trajectory(
        self,
        traj: JointTrajectory,
        limits: Mapping[str, np.ndarray],
        hand_positions: Mapping[str, np.ndarray],
        extras: Mapping[str, np.ndarray] = {},
    ) -> None:
        """A retime, smooth or approach stage's product (``traj.stage``; the approach on its own clock).

        The robot under ``/<stage>``, the hand traces under ``/world/<stage>``, and under
        ``/plots/<stage>`` the positions and each quantity's ratio to its limit (|x| / limit,
        with the limit as the line ``limit`` at 1).
        """
        stage, names = traj.stage, traj.joint_names
        if stage not in self.stages:
            return
        series = {"velocity": traj.qd, "acceleration": traj.qdd, **extras}
        self._animation(stage, traj.t, names, traj.q, traj.fixed)
        self._hand_traces(stage, hand_positions)
        self._series(f"{stage}/position", traj.t, dict(zip(names, traj.q.T, strict=True)))
        for kind, limit in limits.items():
            self._ratio(stage, kind, traj.t, names, series[kind], limit)
        if "deviation_rad" in extras:
            self._series(f"{stage}/deviation_rad", traj.t, dict(zip(names, extras["deviation_rad"].T, strict=False)))

    def execution(self, log: ExecutionLog) -> None:
        """The execute stage's product: the robot under ``/execute``, measured hand traces, plots.

        The measured hand traces under ``/world/execute``, and under ``/plots/execute`` the hand
        errors, contacts and the joints' tracking error (``/plots/approach/executed_*`` for the
        approach).
        """
        if "execute" not in self.stages:
            return
        self._executed(log, "execute/")
        if len(log.t):
            self._animation("execute", log.t, log.joint_names, log.q, log.fixed)
        self._hand_traces("execute", {hand: T[:, :3, 3] for hand, T in log.hand_poses.items()})
        self._carried_object("execute", log.t, log.hand_poses)
        if log.approach is not None:
            self._executed(log.approach, "approach/executed_")

    def _executed(self, log: ExecutionLog, plots: str) -> None:
        """One played trajectory's plots, named ``plots/<plots><quantity>``."""
        names = log.joint_names
        self._series(f"{plots}hand_error_m", log.t, dict(log.hand_error_m), first_color=2)  # beside the IK's
        self._series(
            f"{plots}tracking_error_rad", log.t, dict(zip(names, np.abs(log.q - log.q_command).T, strict=True))
        )
        self._series(
            f"{plots}contacts",
            log.t,
            {"self": log.self_contacts, "environment": log.environment_contacts, "expected": log.expected_contacts},
        )

    def environment(self, objects, carried=None) -> None:
        """A task's fixed objects under ``/world/environment/<name>``; the carried one is kept for the stages.

        The objects: :class:`~dualarm.tasks.schema.EnvironmentObject`, poses in the robot base
        frame; ``carried``: a :class:`~dualarm.tasks.schema.CarriedObject` or None, drawn with each
        stage's hands (:meth:`_carried_object`).
        """
        self._carried = carried
        if "path" not in self.stages:
            return
        for obj in objects:
            T = pose_matrix(obj.pose.position, obj.pose.rpy)
            x, y, z, w = quaternion_xyzw(T[:3, :3]).tolist()
            archetype: rr.Boxes3D | rr.Cylinders3D | rr.Ellipsoids3D
            if obj.shape == "box":
                archetype = rr.Boxes3D(
                    half_sizes=[[s / 2 for s in obj.size_m]],
                    centers=[T[:3, 3]],
                    quaternions=[[x, y, z, w]],
                    fill_mode="solid",
                )
            elif obj.shape == "cylinder":
                archetype = rr.Cylinders3D(
                    lengths=[obj.height_m],
                    radii=[obj.radius_m],
                    centers=[T[:3, 3]],
                    quaternions=[[x, y, z, w]],
                    fill_mode="solid",
                )
            else:
                archetype = rr.Ellipsoids3D(half_sizes=[[obj.radius_m] * 3], centers=[T[:3, 3]], fill_mode="solid")
            self._rr.log(f"world/environment/{obj.name}", archetype, static=True)

    def reference(self, ref: CartesianReference) -> None:
        """The path stage's product: the hands' paths as 3D line strips.

        And the position components as time series.
        """
        if "path" not in self.stages:
            return
        for hand, hr in ref.hands.items():
            self._rr.log(
                f"world/reference/{hand}",
                rr.LineStrips3D([hr.position], colors=[HAND_COLORS.get(hand, (200, 200, 200))], radii=0.003),
                static=True,
            )
            self._series(
                f"reference/{hand}",
                ref.t,
                {**{f"position/{a}": hr.position[:, i] for i, a in enumerate("xyz")}, "rep": ref.rep},
            )

    def close(self, manifest: Mapping[str, object]) -> None:
        """Send the layout again with each plot's value range (:func:`blueprint`), then finish the file."""
        self._rr.send_blueprint(
            blueprint(self.robot, self.stages, ranges=self._ranges, clocks=self._clocks),
            make_active=True,
            make_default=True,
        )
        self._rr.flush()
        self._rr.disconnect()
