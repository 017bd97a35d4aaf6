"""Bags a ROS user can open: every topic of a run, stamped with sim time.

``.mcap``: one MCAP file laid out as rosbag2 writes it (ros2msg schemas, CDR payloads), which
Foxglove, PlotJuggler and ``ros2 bag`` read. ``.bag``: a ROS 1 bag. Messages are serialised by
``rosbags``; the MCAP container is written by the ``mcap`` library.

A recording goes to ``BAG.active`` (as ``rosbag record`` does), renamed to BAG when it is closed,
so a half-written bag never has the name of a finished one and --force replaces an old bag only
once the new one is complete. Ctrl-C or SIGTERM close it cleanly, and no second signal interrupts
the closing (`mexone.signals`). A chunk is written to disk every 0.25 s of sim time, so after a
SIGKILL, a crash or a routine's ``os._exit`` everything older than that is in ``BAG.active`` and
``mexone record --recover BAG`` (`mexone.record.recover`) rebuilds a valid bag from it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from mexone import signals
from mexone.bus import msgs
from mexone.errors import InputError, OutputExistsError
from mexone.files import check_output, move_into_place
from mexone.lab import Lab

__all__ = ["BagRecorder", "ROS_NAMES", "to_ros", "typestore_for", "BAG_SUFFIXES", "active_path",
           "FLUSH_PERIOD"]

#: the recordings mexone writes and reads: MCAP (ROS 2) and ROS 1 bags
BAG_SUFFIXES = (".mcap", ".bag")
#: each message class -> its type name in a bag ("sensor_msgs/msg/JointState")
ROS_NAMES = {cls: name.replace("/", "/msg/", 1) for cls, name in msgs.ROS_TYPES.items()}
_TF_MSG = "geometry_msgs/TransformStamped[] transforms\n"
FLUSH_PERIOD = 0.25  #: s of sim time between chunks written to disk: what a SIGKILL can lose
_SMALL_CHUNK = 16 * 1024  # bytes: the chunk size where the mcap library cannot flush on demand


def active_path(path: Path) -> Path:
    """Where a recording is written until it is closed (ROS 1's name for it)."""
    return path.with_name(path.name + ".active")


_CONTACT_STATE_MSG = """string info
string collision1_name
string collision2_name
geometry_msgs/Wrench[] wrenches
geometry_msgs/Wrench total_wrench
geometry_msgs/Vector3[] contact_positions
geometry_msgs/Vector3[] contact_normals
float64[] depths
"""
_CONTACTS_STATE_MSG = "std_msgs/Header header\ngazebo_msgs/ContactState[] states\n"
_CONTROLLER_STATE_MSG = """std_msgs/Header header
float64 set_point
float64 process_value
float64 process_value_dot
float64 error
float64 time_step
float64 command
float64 p
float64 i
float64 d
float64 i_clamp
bool antiwindup
"""  # control_msgs 1.5's JointControllerState (ros_controllers' `state` topics)


def typestore_for(ros1: bool) -> Any:
    """rosbags' type store for a ROS 1 .bag (Noetic) or an MCAP (ROS 2), with mexone's message
    types it lacks added."""
    # here, not at the top: the page's Topics panel imports this module, and rosbags costs
    # every lab ~6 MB it needs only when it records
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    missing = {}
    if "tf2_msgs/msg/TFMessage" not in store.types:
        missing |= get_types_from_msg(_TF_MSG, "tf2_msgs/msg/TFMessage")
    if "gazebo_msgs/msg/ContactsState" not in store.types:  # gazebo_msgs' official definitions
        missing |= get_types_from_msg(_CONTACT_STATE_MSG, "gazebo_msgs/msg/ContactState")
        missing |= get_types_from_msg(_CONTACTS_STATE_MSG, "gazebo_msgs/msg/ContactsState")
    if "control_msgs/msg/JointControllerState" not in store.types:
        missing |= get_types_from_msg(_CONTROLLER_STATE_MSG, "control_msgs/msg/JointControllerState")
    if missing:
        store.register(missing)
    return store


def to_ros(msg, store, ros1: bool):
    """Our dataclass message -> the typestore's class of the same ROS interface."""
    T = store.types

    def time(t: msgs.Time):
        return T["builtin_interfaces/msg/Time"](sec=t.secs, nanosec=t.nsecs)

    def header(h: msgs.Header):
        if ros1:
            return T["std_msgs/msg/Header"](seq=h.seq, stamp=time(h.stamp), frame_id=h.frame_id)
        return T["std_msgs/msg/Header"](stamp=time(h.stamp), frame_id=h.frame_id)

    def array(values):
        return np.asarray(values, dtype=np.float64)

    def vector(v: msgs.Vector3):
        return T["geometry_msgs/msg/Vector3"](x=v.x, y=v.y, z=v.z)

    def quaternion(q: msgs.Quaternion):
        return T["geometry_msgs/msg/Quaternion"](x=q.x, y=q.y, z=q.z, w=q.w)

    def wrench(w: msgs.Wrench):
        return T["geometry_msgs/msg/Wrench"](force=vector(w.force), torque=vector(w.torque))

    def pose(p: msgs.Pose):
        position = T["geometry_msgs/msg/Point"](x=p.position.x, y=p.position.y, z=p.position.z)
        return T["geometry_msgs/msg/Pose"](position=position, orientation=quaternion(p.orientation))

    def pose_stamped(p: msgs.PoseStamped):
        return T["geometry_msgs/msg/PoseStamped"](header=header(p.header), pose=pose(p.pose))

    match msg:
        case msgs.Float64(data):
            return T["std_msgs/msg/Float64"](data=float(data))
        case msgs.Float64MultiArray(data):
            layout = T["std_msgs/msg/MultiArrayLayout"](dim=[], data_offset=0)
            return T["std_msgs/msg/Float64MultiArray"](layout=layout, data=array(data))
        case msgs.JointState():
            return T["sensor_msgs/msg/JointState"](
                header=header(msg.header), name=list(msg.name), position=array(msg.position),
                velocity=array(msg.velocity), effort=array(msg.effort))
        case msgs.Clock(clock):
            return T["rosgraph_msgs/msg/Clock"](clock=time(clock))
        case msgs.JointTrajectory():
            duration = T["builtin_interfaces/msg/Duration"]
            points = [T["trajectory_msgs/msg/JointTrajectoryPoint"](
                positions=array(p.positions), velocities=array(p.velocities),
                accelerations=array(p.accelerations), effort=array(p.effort),
                time_from_start=duration(sec=p.time_from_start.secs,
                                         nanosec=p.time_from_start.nsecs)) for p in msg.points]
            return T["trajectory_msgs/msg/JointTrajectory"](
                header=header(msg.header), joint_names=list(msg.joint_names), points=points)
        case msgs.TFMessage(transforms):
            out = []
            for tf in transforms:
                vec = T["geometry_msgs/msg/Vector3"](x=tf.translation[0], y=tf.translation[1],
                                                     z=tf.translation[2])
                w, x, y, z = tf.rotation
                quat = T["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w)
                out.append(T["geometry_msgs/msg/TransformStamped"](
                    header=header(tf.header), child_frame_id=tf.child_frame_id,
                    transform=T["geometry_msgs/msg/Transform"](translation=vec, rotation=quat)))
            return T["tf2_msgs/msg/TFMessage"](transforms=out)
        case msgs.Imu():
            return T["sensor_msgs/msg/Imu"](
                header=header(msg.header), orientation=quaternion(msg.orientation),
                orientation_covariance=array(msg.orientation_covariance),
                angular_velocity=vector(msg.angular_velocity),
                angular_velocity_covariance=array(msg.angular_velocity_covariance),
                linear_acceleration=vector(msg.linear_acceleration),
                linear_acceleration_covariance=array(msg.linear_acceleration_covariance))
        case msgs.WrenchStamped():
            return T["geometry_msgs/msg/WrenchStamped"](header=header(msg.header),
                                                        wrench=wrench(msg.wrench))
        case msgs.ContactsState():
            states = [T["gazebo_msgs/msg/ContactState"](
                info=c.info, collision1_name=c.collision1_name, collision2_name=c.collision2_name,
                wrenches=[wrench(w) for w in c.wrenches], total_wrench=wrench(c.total_wrench),
                contact_positions=[vector(v) for v in c.contact_positions],
                contact_normals=[vector(v) for v in c.contact_normals], depths=array(c.depths))
                for c in msg.states]
            return T["gazebo_msgs/msg/ContactsState"](header=header(msg.header), states=states)
        case msgs.JointControllerState():
            values = {k: float(getattr(msg, k)) for k in (
                "set_point", "process_value", "process_value_dot", "error", "time_step",
                "command", "p", "i", "d", "i_clamp")}
            return T["control_msgs/msg/JointControllerState"](
                header=header(msg.header), antiwindup=bool(msg.antiwindup), **values)
        case msgs.PointStamped():
            return T["geometry_msgs/msg/PointStamped"](
                header=header(msg.header), point=T["geometry_msgs/msg/Point"](
                    x=msg.point.x, y=msg.point.y, z=msg.point.z))
        case msgs.PolygonStamped():
            points = [T["geometry_msgs/msg/Point32"](x=p.x, y=p.y, z=p.z)
                      for p in msg.polygon.points]
            return T["geometry_msgs/msg/PolygonStamped"](
                header=header(msg.header), polygon=T["geometry_msgs/msg/Polygon"](points=points))
        case msgs.Twist():
            return T["geometry_msgs/msg/Twist"](linear=vector(msg.linear),
                                                angular=vector(msg.angular))
        case msgs.PoseStamped():
            return pose_stamped(msg)
        case msgs.PoseArray():
            return T["geometry_msgs/msg/PoseArray"](header=header(msg.header),
                                                    poses=[pose(p) for p in msg.poses])
        case msgs.Path():
            return T["nav_msgs/msg/Path"](header=header(msg.header),
                                          poses=[pose_stamped(p) for p in msg.poses])
        case msgs.Image():
            return T["sensor_msgs/msg/Image"](
                header=header(msg.header), height=msg.height, width=msg.width,
                encoding=msg.encoding, is_bigendian=msg.is_bigendian, step=msg.step,
                data=np.frombuffer(msg.data, dtype=np.uint8))
        case msgs.CameraInfo():
            roi = T["sensor_msgs/msg/RegionOfInterest"](
                x_offset=msg.roi.x_offset, y_offset=msg.roi.y_offset, height=msg.roi.height,
                width=msg.roi.width, do_rectify=msg.roi.do_rectify)
            matrices = {"D": msg.D, "K": msg.K, "R": msg.R, "P": msg.P}
            names = {k: (k if ros1 else k.lower()) for k in matrices}  # ROS 2 spells them d k r p
            return T["sensor_msgs/msg/CameraInfo"](
                header=header(msg.header), height=msg.height, width=msg.width,
                distortion_model=msg.distortion_model, binning_x=msg.binning_x,
                binning_y=msg.binning_y, roi=roi,
                **{names[k]: array(v) for k, v in matrices.items()})
        case msgs.PointCloud2():
            fields = [T["sensor_msgs/msg/PointField"](name=f.name, offset=f.offset,
                                                      datatype=f.datatype, count=f.count)
                      for f in msg.fields]
            return T["sensor_msgs/msg/PointCloud2"](
                header=header(msg.header), height=msg.height, width=msg.width, fields=fields,
                is_bigendian=msg.is_bigendian, point_step=msg.point_step, row_step=msg.row_step,
                data=np.frombuffer(msg.data, dtype=np.uint8), is_dense=msg.is_dense)
    raise TypeError(f"no ROS type for {type(msg).__name__}")


class BagRecorder:
    """Taps every message on the lab's bus and writes it; also asks for /clock and /tf."""

    def __init__(self, lab: Lab, path: Path | str, force: bool = False):
        self.path = Path(path)
        suffix = self.path.suffix.lower()
        if suffix not in BAG_SUFFIXES:
            raise InputError(f"cannot record to '{suffix or self.path.name}'", file=self.path,
                             hint="name the bag .mcap (ROS 2) or .bag (ROS 1)")
        try:
            check_output(self.path, force)
        except OutputExistsError:
            raise OutputExistsError("already exists; nothing was recorded", file=self.path,
                                    hint="pass --force to overwrite it, or pick another name"
                                    ) from None
        self.active = active_path(self.path)
        if self.active.exists() and not force:
            raise OutputExistsError("a killed recording is still here; nothing was recorded",
                                    file=self.active, hint=f"'mexone record --recover {self.path}' "
                                    "rebuilds it; --force discards it")
        self.force = force
        self.lab = lab
        self.ros1 = suffix == ".bag"
        self.store = typestore_for(self.ros1)
        self.counts: dict[str, int] = {}
        self._connections: dict[str, object] = {}
        self._last_flush = lab.sim.time
        self.closed = False
        signals.hold(str(self.path))
        try:
            self._open()
        except OSError as exc:
            signals.release(str(self.path))
            raise InputError(f"cannot write: {exc.strerror or exc}", file=self.path) from None
        except BaseException:
            signals.release(str(self.path))
            raise
        lab.bus.add_tap(self._write)
        # make the periodic publishers run while we record
        node = f"recorder ({self.path.name})"
        self._subs = [lab.bus.subscribe("/clock", msgs.Clock, lambda _m: None, node=node),
                      lab.bus.subscribe("/tf", msgs.TFMessage, lambda _m: None, node=node)]
        sensors = lab.sensors.topics  # every sensor but the cameras' images and clouds
        self._subs += [lab.bus.subscribe(t, sensors[t], lambda _m: None, node=node)
                       for t in lab.sensors.light_topics]

    def _open(self) -> None:
        self.active.unlink(missing_ok=True)  # only with force: a killed recording discarded
        try:
            if self.ros1:
                from rosbags.rosbag1 import Writer

                self.writer = Writer(self.active)
                self.writer.open()
            else:
                from mcap.writer import CompressionType, Writer

                self._file = self.active.open("xb")
                can_flush = hasattr(Writer, "flush")
                self.writer = Writer(self._file, compression=CompressionType.NONE,
                                     **({} if can_flush else {"chunk_size": _SMALL_CHUNK}))
                self.writer.start(profile="ros2", library="mexone")
            self._flush()  # the header is on disk from the start: a killed file is an MCAP
        except BaseException:
            self.active.unlink(missing_ok=True)
            raise

    def _flush(self) -> None:
        """Write the chunk in progress to the file (the OS keeps it across a SIGKILL)."""
        if self.ros1:
            self.writer.write_chunk(self.writer.chunks[-1])
            self.writer.bio.flush()
        else:
            if hasattr(self.writer, "flush"):
                self.writer.flush()
            self._file.flush()

    def _connection(self, topic: str, typename: str):
        conn = self._connections.get(topic)
        if conn is None:
            if self.ros1:
                conn = self.writer.add_connection(topic, typename, typestore=self.store)
            else:
                text, _ = self.store.generate_msgdef(typename, ros_version=2)
                schema = self.writer.register_schema(typename, "ros2msg", text.encode())
                conn = self.writer.register_channel(topic, "cdr", schema)
            self._connections[topic] = conn
        return conn

    def _write(self, topic: str, msg) -> None:
        if self.closed:
            return
        typename = ROS_NAMES.get(type(msg))
        if typename is None:
            return
        now = self.lab.sim.time
        stamp = int(round(now * 1e9))
        ros_msg = to_ros(msg, self.store, self.ros1)
        if self.ros1:
            data = bytes(self.store.serialize_ros1(ros_msg, typename))
        else:
            data = bytes(self.store.serialize_cdr(ros_msg, typename))
        with signals.uninterrupted:  # Ctrl-C inside the library's record writing corrupts it
            conn = self._connection(topic, typename)
            if self.ros1:
                self.writer.write(conn, stamp, data)
            else:
                self.writer.add_message(conn, log_time=stamp, data=data, publish_time=stamp,
                                        sequence=self.counts.get(topic, 0))
            self.counts[topic] = self.counts.get(topic, 0) + 1
            if not 0 <= now - self._last_flush < FLUSH_PERIOD:  # (a GUI reset turns time back)
                self._last_flush = now
                self._flush()

    def close(self) -> None:
        """Finish the bag and rename it into place; no signal interrupts this."""
        if self.closed:
            return
        self.closed = True
        try:
            with signals.finishing():
                self.lab.bus.remove_tap(self._write)
                for sub in self._subs:
                    sub.unregister()
                if self.ros1:
                    self.writer.close()
                else:
                    self.writer.finish()
                    self._file.close()
                try:
                    move_into_place(self.active, self.path, self.force)
                except OutputExistsError:
                    raise OutputExistsError("appeared while recording; it was left alone",
                                            file=self.path,
                                            hint=f"the recording is kept as {self.active}") from None
        finally:
            signals.release(str(self.path))
