"""A run as ROS 2 sees it: a rosbag2 directory to play on a robot, a CSV for controllers outside ROS.

:func:`export_bag` writes ``metadata.yaml`` and one MCAP file (rosbags' writer, CDR-encoded ``ros2msg`` types of ROS 2
Humble) with:

- ``/joint_trajectory`` (``trajectory_msgs/msg/JointTrajectory``): the timed trajectory the run executed (the smooth
  stage's samples, else the retime stage's), at the control period, one point per sample with positions, velocities,
  accelerations and ``time_from_start``, the joints named as in the URDF: what a joint trajectory controller takes;
- ``/joint_states`` (``sensor_msgs/msg/JointState``): the executed motion, a message per simulation step;
- ``/tf`` and ``/tf_static`` (``tf2_msgs/msg/TFMessage``): the link frames the run recorded (every 0.01 s, the root hung
  from ``world``); a transform that does not change over the run (a fixed joint's, or a joint the task holds) is on
  ``/tf_static`` once, transient-local, as robot_state_publisher offers it;
- ``/robot_description`` (``std_msgs/msg/String``, transient-local): the URDF the run recorded, URDF 1.0 with its
  meshes inside (:func:`~dualarm.record.mcap_sink.robot_description`).

Times are motion time from 0, as in ``run.mcap``: ``ros2 bag play`` keeps their spacing. :func:`export_csv` writes the
trajectory's time and positions. Both are written beside the target and renamed into place, so an interrupted export
leaves nothing that looks complete.

:func:`read_joint_states` reads a robot's ``sensor_msgs/msg/JointState`` messages back from a ROS 2 bag (a rosbag2
directory, MCAP or sqlite3, or a bare MCAP file; rosbags' reader), for ``dualarm analyze``.

Units: times [s] (in the bag, stamps and ``time_from_start`` in s and ns), positions [rad], velocities [rad/s],
accelerations [rad/s^2], translations [m].
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pandas as pd

from dualarm.arrays import frozen
from dualarm.errors import DualarmError, RecordingError, excerpt
from dualarm.files import cause
from dualarm.record.readback import TF_COLUMNS, RunData

#: The ROS 2 distribution whose message definitions the bag carries (rosbags' typestore).
DISTRO = "ROS2_HUMBLE"
#: rosbag2's metadata version the bag is written in (Humble and later read it).
BAG_VERSION: Literal[8] = 8
#: The stages whose samples are the timed trajectory, the first recorded one is used.
TRAJECTORY_STAGES = ("smooth", "retime")
#: A transform whose translation and rotation change less than this over the run is static [m, quaternion units].
STATIC_WITHIN = 1e-12


def trajectory_topic(run: RunData) -> str:
    """The topic of the run's timed trajectory (:data:`TRAJECTORY_STAGES`).

    Raises:
        RecordingError: the run recorded neither stage.
    """
    for stage in TRAJECTORY_STAGES:
        if stage in run.recorded_stages:
            return f"/{stage}/sample"
    raise RecordingError(
        f"{excerpt(run.directory)}: holds no timed trajectory (stages recorded: {', '.join(run.recorded_stages)}); "
        "export needs a run recorded with --record full through retime or smooth"
    )


def _columns(frame: pd.DataFrame, field: str) -> tuple[list[str], np.ndarray]:
    """The joint names of ``field`` (``position.<joint>`` columns) in ``frame``, and their values (N, n)."""
    names = [c.split(".", 1)[1] for c in frame.columns if c.startswith(f"{field}.")]
    return names, np.ascontiguousarray(frame[[f"{field}.{n}" for n in names]].to_numpy(float))


def _ns(t_s: float) -> int:
    """``t_s`` [s] in whole nanoseconds."""
    return int(round(t_s * 1e9))


def _stamp(types: Any, t_s: float, msgtype: str = "builtin_interfaces/msg/Time") -> Any:
    """A ``builtin_interfaces`` Time (or Duration) of ``t_s`` [s]."""
    ns = _ns(t_s)
    return types[msgtype](sec=ns // 10**9, nanosec=ns % 10**9)


def export_bag(run: RunData, target: Path) -> Path:
    """Write ``run`` as the rosbag2 directory ``target`` (module docstring); returns it.

    Raises:
        DualarmError: ``target`` exists, or its parent cannot be written (naming the cause).
        RecordingError: the run holds no timed trajectory, no executed motion or no ``/tf``.
    """
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    trajectory, executed, frames = run[trajectory_topic(run)], run["/execute/sample"], run["/tf"]
    description = run["/robot_description"]["data"].iloc[0]
    store = get_typestore(getattr(Stores, DISTRO))
    types = store.types
    never = QosTime(sec=0, nsec=0)
    latched = Qos(
        QosHistory.KEEP_LAST,
        1,
        QosReliability.RELIABLE,
        QosDurability.TRANSIENT_LOCAL,
        never,
        never,
        QosLiveliness.AUTOMATIC,
        never,
        False,
    )

    def write(writer: Writer) -> None:
        def channel(topic: str, msgtype: str, qos: tuple = ()) -> Callable[[int, Any], None]:
            connection = writer.add_connection(topic, msgtype, typestore=store, offered_qos_profiles=list(qos))
            return lambda time_ns, message: writer.write(connection, time_ns, store.serialize_cdr(message, msgtype))

        header = types["std_msgs/msg/Header"]
        channel("/robot_description", "std_msgs/msg/String", (latched,))(
            0, types["std_msgs/msg/String"](data=description)
        )
        names, q = _columns(trajectory, "position")
        qd, qdd = (_columns(trajectory, field)[1] for field in ("velocity", "acceleration"))
        point = types["trajectory_msgs/msg/JointTrajectoryPoint"]
        points = [
            point(
                positions=q[k],
                velocities=qd[k],
                accelerations=qdd[k],
                effort=np.empty(0),
                time_from_start=_stamp(types, t, "builtin_interfaces/msg/Duration"),
            )
            for k, t in enumerate(trajectory["t"].to_numpy(float))
        ]
        channel("/joint_trajectory", "trajectory_msgs/msg/JointTrajectory")(
            0,
            types["trajectory_msgs/msg/JointTrajectory"](
                header=header(stamp=_stamp(types, 0.0), frame_id=""), joint_names=names, points=points
            ),
        )
        names, q = _columns(executed, "position")
        joint_state = channel("/joint_states", "sensor_msgs/msg/JointState")
        for k, t in enumerate(executed["t"].to_numpy(float)):
            joint_state(
                _ns(t),
                types["sensor_msgs/msg/JointState"](
                    header=header(stamp=_stamp(types, t), frame_id=""),
                    name=names,
                    position=q[k],
                    velocity=np.empty(0),
                    effort=np.empty(0),
                ),
            )
        _write_tf(
            frames,
            types,
            header,
            channel("/tf", "tf2_msgs/msg/TFMessage"),
            channel("/tf_static", "tf2_msgs/msg/TFMessage", (latched,)),
        )

    def storage(part: Path) -> None:
        with Writer(part, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP) as writer:
            write(writer)

    return _into_place(target, storage)


def _write_tf(
    frames: pd.DataFrame,
    types: Any,
    header: Any,
    tf: Callable[[int, Any], None],
    tf_static: Callable[[int, Any], None],
) -> None:
    """The run's ``/tf`` rows (t, parent, child, translation, rotation) as ``/tf`` and ``/tf_static``."""
    values = ["tx", "ty", "tz", "qx", "qy", "qz", "qw"]
    frames = frames.rename(columns=dict(zip(TF_COLUMNS, ["parent", "child", *values], strict=True)))
    spread = frames.groupby(["parent", "child"])[values].agg(np.ptp).max(axis=1)
    static = set(spread.index[spread <= STATIC_WITHIN])

    def message(rows: pd.DataFrame) -> Any:
        transform = types["geometry_msgs/msg/TransformStamped"]
        return types["tf2_msgs/msg/TFMessage"](
            transforms=[
                transform(
                    header=header(stamp=_stamp(types, r.t), frame_id=r.parent),  # type: ignore[arg-type]
                    child_frame_id=r.child,
                    transform=types["geometry_msgs/msg/Transform"](
                        translation=types["geometry_msgs/msg/Vector3"](x=r.tx, y=r.ty, z=r.tz),
                        rotation=types["geometry_msgs/msg/Quaternion"](x=r.qx, y=r.qy, z=r.qz, w=r.qw),
                    ),
                )
                for r in rows.itertuples()
            ]
        )

    is_static = pd.Series([(p, c) in static for p, c in zip(frames["parent"], frames["child"], strict=True)])
    first = frames["t"] == frames["t"].min()
    tf_static(0, message(frames[is_static.to_numpy() & first.to_numpy()]))
    for t, rows in frames[~is_static.to_numpy()].groupby("t", sort=True):
        tf(_ns(float(t)), message(rows))  # type: ignore[arg-type]


def export_csv(run: RunData, target: Path) -> Path:
    """Write the run's timed trajectory as CSV ``target`` (``t_s``, ``<joint>_rad`` columns); returns it.

    Raises:
        DualarmError: ``target`` exists, or its directory cannot be written.
        RecordingError: the run holds no timed trajectory.
    """
    trajectory = run[trajectory_topic(run)]
    names, q = _columns(trajectory, "position")
    table = pd.DataFrame(q, columns=[f"{n}_rad" for n in names])
    table.insert(0, "t_s", trajectory["t"].to_numpy(float))
    return _into_place(target, lambda part: table.to_csv(part, index=False, float_format="%.17g"))


def _into_place(target: Path, write: Callable[[Path], None]) -> Path:
    """Run ``write`` on ``target``'s name in a staging directory beside it, then rename it to ``target``.

    Nothing is left on failure.

    Raises:
        DualarmError: ``target`` exists, or its parent cannot be written (naming the cause).
    """
    if target.exists() or target.is_symlink():
        raise DualarmError(f"{excerpt(target)}: exists; export writes a new file or directory")
    staging = target.parent / f".{target.name}.part-{os.getpid()}"
    try:
        staging.mkdir(parents=True)
        write(staging / target.name)
        (staging / target.name).rename(target)
    except OSError as error:
        raise DualarmError(f"{excerpt(target)}: cannot write it ({cause(error)})") from error
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return target


#: The message type :func:`read_joint_states` reads.
JOINT_STATE = "sensor_msgs/msg/JointState"


@dataclass(frozen=True)
class JointStates:
    """A joint-state topic read from a bag: the messages that carry at least one of the joints asked for.

    Attributes:
        t_s: each message's header stamp, or its log time where the stamp is 0 (N,) [s], in the bag's order.
        joint_names: the joints asked for (URDF names).
        q_rad: their positions (N, n) [rad]; NaN where a message lacks the joint.
        topic: the topic read.
        skipped: messages on the topic that carry none of the joints.
    """

    t_s: np.ndarray
    joint_names: tuple[str, ...]
    q_rad: np.ndarray
    topic: str
    skipped: int = 0

    def __post_init__(self) -> None:
        N = len(self.t_s)
        object.__setattr__(self, "t_s", frozen(self.t_s, (N,), "t_s"))
        object.__setattr__(self, "q_rad", frozen(self.q_rad, (N, len(self.joint_names)), "q_rad"))


def read_joint_states(
    bag: Path, joints: tuple[str, ...], topic: str = "/joint_states", rename: Mapping[str, str] | None = None
) -> JointStates:
    """The positions of ``joints`` on ``topic`` of the ROS 2 bag ``bag``, names mapped by ``rename``.

    ``rename``: bag joint name -> URDF joint name, for names the robot's driver gives otherwise.

    Raises:
        RecordingError: ``bag`` is no ROS 2 bag (or a ROS 1 one), lacks ``topic``, whose type is not
            :data:`JOINT_STATE`, or no message of it names one of ``joints``.
    """
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    rename = dict(rename or {})
    column = {name: k for k, name in enumerate(joints)}
    try:
        reader = AnyReader([Path(bag)], default_typestore=get_typestore(getattr(Stores, DISTRO)))
        if not reader.is2:
            raise RecordingError(f"{excerpt(bag)}: a ROS 1 bag; analyze reads ROS 2 bags (rosbag2 or MCAP)")
        reader.open()
    except RecordingError:
        raise
    except Exception as error:  # rosbags raises its own errors, OSError, and yaml's or mcap's on a corrupt file
        raise RecordingError(f"{excerpt(bag)}: not a readable ROS 2 bag ({_why(error)})") from error
    try:
        connections = [c for c in reader.connections if c.topic == topic]
        if not connections:
            states = sorted({c.topic for c in reader.connections if c.msgtype == JOINT_STATE})
            raise RecordingError(
                f"{excerpt(bag)}: no topic {excerpt(topic, 80)} (its {JOINT_STATE} topics: "
                f"{', '.join(states) or 'none'}); name it with --topic"
            )
        if any(c.msgtype != JOINT_STATE for c in connections):
            raise RecordingError(f"{excerpt(bag)}: {excerpt(topic, 80)} is {connections[0].msgtype}, not {JOINT_STATE}")
        t, rows, skipped, seen = [], [], 0, set()
        places: dict[tuple[str, ...], tuple[np.ndarray, np.ndarray]] = {}  # a message's names -> (its indices, ours)
        try:
            for connection, log_ns, raw in reader.messages(connections=connections):
                message: Any = reader.deserialize(raw, connection.msgtype)
                names = tuple(message.name)
                if names not in places:
                    mapped = [rename.get(n, n) for n in names]
                    seen.update(mapped)
                    mine = [k for k, n in enumerate(mapped) if n in column]
                    places[names] = (np.array(mine, dtype=int), np.array([column[mapped[k]] for k in mine], dtype=int))
                theirs, ours = places[names]
                position = np.asarray(message.position, dtype=np.float64)
                if not len(ours) or len(position) != len(names):
                    skipped += 1
                    continue
                row = np.full(len(joints), np.nan)
                row[ours] = position[theirs]
                rows.append(row)
                stamp = message.header.stamp.sec + 1e-9 * message.header.stamp.nanosec
                t.append(stamp if stamp > 0 else log_ns * 1e-9)
        except Exception as error:
            raise RecordingError(f"{excerpt(bag)}: cannot read {excerpt(topic, 80)} ({_why(error)})") from error
    finally:
        reader.close()
    if not rows:
        raise RecordingError(
            f"{excerpt(bag)}: no message on {excerpt(topic, 80)} names one of the robot's arm joints "
            f"({', '.join(joints[:4])}{', ...' if len(joints) > 4 else ''}; the bag's: "
            f"{excerpt(', '.join(sorted(seen)) or 'none', 200)}); map names with --joint-map BAG_NAME=URDF_NAME"
        )
    return JointStates(np.asarray(t), joints, np.asarray(rows), topic, skipped)


def _why(error: Exception) -> str:
    """What a reader's exception says, in one line."""
    if isinstance(error, FileNotFoundError) and not error.strerror:  # rosbags' own: a directory without metadata
        return excerpt(" ".join(str(error).split()) or "no such file or directory", 200)
    if isinstance(error, OSError | ValueError):
        return cause(error)
    return excerpt(" ".join(str(error).split()) or type(error).__name__, 200)
