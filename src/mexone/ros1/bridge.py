"""Ros1Bridge: the simulation as a node in a real ROS 1 graph, through rospy (Debian's).

It does what gazebo_ros + gazebo_ros_control did for the seed: sets /robot_description, takes
the controller configuration from the parameter server when none is given (so `rosparam load`
+ the seed's control.launch works), subscribes to every controller's command topic, publishes
/<ns>/joint_states, /clock (sim time, so use_sim_time nodes follow it) and the floating base as
TF world -> <root>, and offers /gazebo/{pause,unpause}_physics, reset_simulation, reset_world.

rospy callbacks run in rospy's threads; they only queue work on the simulation's work queue,
which the simulation thread runs between steps, so ROS never touches the physics.
"""

from __future__ import annotations

import importlib
import logging
import os
import sys
import threading
from collections.abc import Callable

import yaml

from mexone.bus import msgs
from mexone.control.config import parse_control_config
from mexone.control.spec import ControlConfig
from mexone.errors import MexoneError

__all__ = ["import_rospy", "Ros1Bridge", "ROS_INSTALL", "config_from_param_server",
           "CLOCK_PERIOD"]

log = logging.getLogger("mexone.ros")

ROS_INSTALL = ("apt-get install ros-core python3-rospy python3-rostopic python3-std-msgs "
               "python3-sensor-msgs python3-std-srvs python3-tf2-msgs python3-trajectory-msgs "
               "ros-robot-state-publisher")
_DEBIAN_SITE = "/usr/lib/python3/dist-packages"
CLOCK_PERIOD = 0.001  # s of sim time between /clock messages (gazebo_ros: every step)


def import_rospy():
    """rospy from the system's ROS (Debian packages), usable from this environment."""
    try:
        return importlib.import_module("rospy")
    except ImportError:
        pass
    if os.path.isdir(os.path.join(_DEBIAN_SITE, "rospy")) and _DEBIAN_SITE not in sys.path:
        sys.path.append(_DEBIAN_SITE)  # appended: pip's packages keep precedence
        try:
            return importlib.import_module("rospy")
        except ImportError as exc:
            raise MexoneError(f"ROS 1 is installed but rospy fails to import: {exc}",
                              hint=f"reinstall with: {ROS_INSTALL}") from None
    raise MexoneError("ROS 1 (rospy) is not installed", hint=f"install it with: {ROS_INSTALL}")


def config_from_param_server(rospy, namespace: str) -> ControlConfig:
    """The controller configuration a `rosparam load` of the seed's YAML put under /<ns>."""
    key = "/" + namespace.strip("/")
    try:
        params = rospy.get_param(key)
    except KeyError:
        raise MexoneError(f"no controller configuration at {key} on the parameter server",
                          hint="rosparam load your controllers.yaml first, or pass "
                               "--controllers YAML") from None
    return parse_control_config(yaml.safe_dump({namespace.strip("/"): params}))


class Ros1Bridge:
    """Connect first (the controller configuration may live on the parameter server), then
    attach the lab."""

    def __init__(self, node_name: str = "mexone"):
        self.rospy = rospy = import_rospy()
        import rosgraph

        uri = os.environ.get("ROS_MASTER_URI", "http://localhost:11311")
        if not rosgraph.Master(f"/{node_name}").is_online():
            raise MexoneError(f"no ROS master at {uri}",
                              hint="start roscore, or set ROS_MASTER_URI to where it runs")
        rospy.init_node(node_name, disable_signals=True)
        self.lab = None

    def attach(self, lab, urdf_text: str) -> None:
        rospy = self.rospy
        from geometry_msgs.msg import TransformStamped
        from rosgraph_msgs.msg import Clock
        from sensor_msgs.msg import JointState
        from std_srvs.srv import Empty, EmptyResponse
        from tf2_msgs.msg import TFMessage

        self.lab = lab
        self._types = {"JointState": JointState, "Clock": Clock, "TFMessage": TFMessage,
                       "TransformStamped": TransformStamped}
        rospy.set_param("/robot_description", urdf_text)
        if not rospy.has_param("/use_sim_time"):
            rospy.set_param("/use_sim_time", True)  # as gazebo_ros' empty_world.launch does
        ns = lab.namespace
        self.pub_states = rospy.Publisher(f"{ns}/joint_states", JointState, queue_size=10)
        self.pub_clock = rospy.Publisher("/clock", Clock, queue_size=10)
        self.pub_tf = rospy.Publisher("/tf", TFMessage, queue_size=10)
        self._subs = []
        if lab.controllers:
            for name, ctrl in lab.controllers.controllers.items():
                if ctrl.kind == "state":
                    continue
                topic = lab.controllers.topic(name)
                self._subs.append(rospy.Subscriber(topic, _ros_class(ctrl.msg_type),
                                                   self._relay(topic)))
        lab.bus.subscribe(f"{ns}/joint_states", msgs.JointState, self._forward_states)
        self._services = []
        for name, action in (("pause_physics", lab.sim.pause), ("unpause_physics", lab.sim.resume),
                             ("reset_simulation", self._reset), ("reset_world", self._reset)):
            self._services.append(rospy.Service(f"/gazebo/{name}", Empty,
                                                self._service(action, EmptyResponse)))
        self._tf_timer = lab.sim.add_periodic(0.02, self._publish_base_tf)
        self._last_clock = -1
        self.master_ok = True
        self._watch = threading.Thread(target=self._watch_master, daemon=True)
        self._watch.start()

    # ----- ROS -> simulation ------------------------------------------------------------------
    def _relay(self, topic: str):
        def callback(ros_msg) -> None:  # rospy's thread: hand over, in order, to the sim thread
            msg = _from_ros(ros_msg)
            self.lab.sim.work.put(lambda: self.lab.bus.publish(topic, msg))
        return callback

    def _service(self, action: Callable[[], None], response):
        def handler(_request):
            self.lab.sim.work.call(action, timeout=10.0)
            return response()
        return handler

    def _reset(self) -> None:
        self.lab.sim.reset()  # the controllers restart with it, holding home

    def _stamp(self, nanoseconds: int):
        return self.rospy.Time(*divmod(nanoseconds, 1_000_000_000))

    def pump(self, sim=None) -> None:
        """Publish /clock: call between steps, in the sim thread."""
        t = self.lab.sim.time_ns
        if t != self._last_clock and not self.rospy.is_shutdown():
            self._last_clock = t
            self.pub_clock.publish(self._types["Clock"](clock=self._stamp(t)))

    # ----- simulation -> ROS ------------------------------------------------------------------
    def _forward_states(self, msg: msgs.JointState) -> None:
        ros_msg = self._types["JointState"]()
        ros_msg.header.stamp = self.rospy.Time(msg.header.stamp.secs, msg.header.stamp.nsecs)
        ros_msg.name, ros_msg.position = list(msg.name), list(msg.position)
        ros_msg.velocity, ros_msg.effort = list(msg.velocity), list(msg.effort)
        self.pub_states.publish(ros_msg)

    def _publish_base_tf(self, sim) -> None:
        """World -> floating base; robot_state_publisher adds the links from joint_states."""
        if not sim.compiled.free:
            return
        body = sim.compiled.root_body
        tf = self._types["TransformStamped"]()
        tf.header.stamp = self._stamp(sim.time_ns)
        tf.header.frame_id = "world"
        tf.child_frame_id = sim.robot.base_link
        x, y, z = sim.data.xpos[body]
        tf.transform.translation.x, tf.transform.translation.y, tf.transform.translation.z = x, y, z
        w, qx, qy, qz = sim.data.xquat[body]
        rot = tf.transform.rotation
        rot.w, rot.x, rot.y, rot.z = w, qx, qy, qz
        self.pub_tf.publish(self._types["TFMessage"](transforms=[tf]))

    # ----- lifecycle --------------------------------------------------------------------------
    def _watch_master(self) -> None:
        import rosgraph

        master = rosgraph.Master("/mexone_watch")
        while not self.rospy.is_shutdown():
            online = master.is_online()
            if self.master_ok and not online:
                log.warning("the ROS master at %s is gone at sim time %.3f s: the simulation goes "
                            "on, but ROS nodes started from now on cannot find it; restart "
                            "'mexone sim --ros' once roscore is back",
                            os.environ.get("ROS_MASTER_URI", "?"), self.lab.sim.time)
            elif online and not self.master_ok:
                log.warning("the ROS master is back; nodes that registered before it went away "
                            "must be restarted (ROS 1 masters keep no state across restarts)")
            self.master_ok = online
            threading.Event().wait(1.0)

    def shutdown(self) -> None:
        if self.lab is not None:
            self.lab.sim.remove_periodic(self._tf_timer)
        self.rospy.signal_shutdown("mexone stopped")


def _ros_class(msg_type: type):
    """The rospy class of one of mexone's message types (named in msgs.ROS_TYPES)."""
    from roslib.message import get_message_class

    return get_message_class(msgs.ROS_TYPES[msg_type])


def _from_ros(ros_msg):
    kind = ros_msg._type
    if kind == "std_msgs/Float64":
        return msgs.Float64(float(ros_msg.data))
    if kind == "std_msgs/Float64MultiArray":
        return msgs.Float64MultiArray([float(v) for v in ros_msg.data])
    points = [msgs.JointTrajectoryPoint(list(p.positions), list(p.velocities),
                                        list(p.accelerations), list(p.effort),
                                        msgs.Duration.from_sec(p.time_from_start.to_sec()))
              for p in ros_msg.points]
    header = msgs.Header(ros_msg.header.seq, msgs.Time.from_sec(ros_msg.header.stamp.to_sec()),
                         ros_msg.header.frame_id)
    return msgs.JointTrajectory(header, list(ros_msg.joint_names), points)
