"""Ros2Bridge: the simulation as a participant in a ROS 2 graph, through rclpy from PyPI's ROS 2
wheels (the `ros2` extra), on the default middleware (Fast DDS).

What gazebo_ros and ros2_control's gazebo plug-in offer a ROS 2 user: /clock (sim time, for
`use_sim_time`), /robot_description (transient-local, as robot_state_publisher offers it), every
bus topic whose type has a ROS 2 wheel (joint states, the sensors, balance), commands in under
the ROS 1 names and ros2_control's (`<ctrl>/commands`, `<ctrl>/joint_trajectory`), controller
gains and physics settings as ROS 2 parameters (params.py), and reset/pause/unpause as std_srvs
services. Which bus topic has which ROS type is the shared table `mexone.bus.ros_map`.

rclpy's callbacks run in the executor's thread; they only hand work to the simulation thread
(`sim.work`), so ROS never touches the physics. Outgoing topics are mirrored only while a ROS 2
node subscribes (polled between steps), so nobody pays for what nobody reads.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Callable

from mexone.bus import msgs, ros_map
from mexone.bus.clock import clock_period_ns, respace
from mexone.bus.topics import Relay
from mexone.errors import InputError, MexoneError, install_extra
from mexone.physics.simulation import NS
from mexone.ros2 import cdr, convert

__all__ = ["Ros2Bridge", "import_rclpy", "check_not_both", "ROS2_INSTALL", "DEFAULT_NODE",
           "CLOCK_FREQUENCY"]

log = logging.getLogger("mexone.ros2")

ROS2_INSTALL = install_extra("ros2")
DEFAULT_NODE = "mexone"
CLOCK_FREQUENCY = 1000.0  # Hz of /clock in sim time (gazebo_ros' default), and at most in wall time
FLAT_OUT_CLOCK = 200.0  # Hz of wall time: /clock's rate when running as fast as possible
_PAUSED_CLOCK = 0.1  # s of wall time between /clock messages while paused
_POLL = 0.25  # s of wall time between looks at who subscribes
_START_WAIT = 120.0


def import_rclpy():
    """rclpy from the ROS 2 wheels on PyPI (or a sourced ROS 2 install)."""
    try:
        import rclpy
        import rclpy.executors  # noqa: F401
    except ImportError as exc:
        raise MexoneError(f"ROS 2 (rclpy) is not installed in this Python: {exc}",
                          hint=f"install it with: {ROS2_INSTALL}") from None
    return rclpy


def _qos(q: ros_map.Qos):
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(depth=q.depth,
                      reliability=ReliabilityPolicy.RELIABLE if q.reliable
                      else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if q.latched
                      else DurabilityPolicy.VOLATILE)


class _Mirror:
    """One bus topic published on ROS 2 while ROS 2 nodes subscribe to it."""

    def __init__(self, bridge: Ros2Bridge, topic: str, bus_type: type, cls: type):
        self.bridge, self.topic, self.cls = bridge, topic, cls
        self.publisher = bridge.node.create_publisher(cls, topic, _qos(ros_map.qos_of(bus_type)))
        self.relay = Relay(bridge.lab.bus, topic, self.forward, "ROS 2 bridge")
        encoder = cdr.ENCODERS.get(ros_map.ros_type(bus_type) or "")
        # the busiest types go out as CDR bytes built here (cdr.py says why), the rest as objects
        self.encode = encoder() if encoder is not None else lambda msg: convert.to_ros2(msg, cls)

    def update(self) -> None:  # simulation thread
        self.relay.want(self.publisher.get_subscription_count() > 0)

    def forward(self, msg) -> None:
        self.publisher.publish(self.encode(msg))


class Ros2Bridge:
    """Join the ROS 2 graph (`__init__`), then attach the lab (`attach`); `pump` between steps."""

    def __init__(self, node_name: str = DEFAULT_NODE):
        rclpy = self.rclpy = import_rclpy()
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions

        self.context = rclpy.Context()
        try:
            # warnings go to stderr through mexone's own log already: rcl's copy only to /rosout
            rclpy.init(args=["--ros-args", "--disable-stdout-logs"], context=self.context,
                       signal_handler_options=SignalHandlerOptions.NO)
            # the parameter services start with our check of every set (params.Parameters): a
            # request before it would meet rclpy's own, which lets an empty name through
            self.node = rclpy.create_node(node_name, context=self.context,
                                          start_parameter_services=False)
        except Exception as exc:  # noqa: BLE001 - rcl's errors: a bad domain id, no middleware
            raise MexoneError(f"cannot join the ROS 2 graph: {exc}",
                              hint="check ROS_DOMAIN_ID (0-232) and RMW_IMPLEMENTATION") from None
        self.node_name = node_name
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._spin = threading.Thread(target=self._spin_loop, name="mexone-ros2", daemon=True)
        self._spin.start()
        self._rosout = _RosoutHandler(self.node)
        logging.getLogger("mexone").addHandler(self._rosout)
        self.lab = None
        self.ready = threading.Event()
        self.params = None
        self._skipped: dict[str, list[str]] = {}  # package -> what it left out, in order
        self._started = False  # attach() has finished: what is left out now was at start-up

    def _spin_loop(self) -> None:
        """rclpy's callbacks, woken only by work (a message, a request) or by shutdown: a
        timeout would rebuild the executor's wait set (every subscription and service) for
        nothing, several times a second."""
        with contextlib.suppress(Exception):  # shutdown while spinning
            self.executor.spin()

    # ----- attach ------------------------------------------------------------------------------
    def attach(self, lab, urdf_text: str) -> None:
        from rosgraph_msgs.msg import Clock
        from std_msgs.msg import String

        from mexone.ros2.params import Parameters

        self.lab = lab
        node = self.node
        self._clock_cls = Clock
        self.pub_clock = node.create_publisher(Clock, "/clock", _qos(ros_map.CLOCK))
        description = String(data=urdf_text)
        self._descriptions = []
        for name in dict.fromkeys(("/robot_description", f"{lab.namespace}/robot_description")):
            pub = node.create_publisher(String, name, _qos(ros_map.LATCHED))
            pub.publish(description)
            self._descriptions.append(pub)
        self._mirrors: dict[str, _Mirror] = {}
        self._inbound: dict[str, object] = {}
        self._known_topics = -1
        self._last_poll = 0.0
        self._last_clock_wall = self._bucket_wall = time.perf_counter()
        self._clock_tokens = 1.0
        self._clock_last = (self._bucket_wall, 0)
        self._clock_timer = lab.sim.add_periodic(1.0 / CLOCK_FREQUENCY, self._publish_clock)
        lab.sim.on_reset(self._after_reset)
        self._tf_setup()
        self.sync_topics()
        self._services()
        self._controller_manager()
        self.params = Parameters(self)
        lab.sim.recover_outside = True  # no input from the graph may end the simulation
        self._started = True
        self.ready.set()

    def _services(self) -> None:
        from std_srvs.srv import Empty

        sim = self.lab.sim
        actions: dict[str, Callable[[], None]] = {
            "/reset_simulation": sim.reset, "/reset_world": sim.reset,
            "/pause_physics": sim.pause, "/unpause_physics": sim.resume}
        self._service_handles = []
        for name, action in actions.items():
            def handler(_req, response, _action=action, _name=name):
                try:
                    self.call(_action)
                    self.lab.sim.note_input(_name) if _name.startswith("/reset") else None
                except Exception as exc:  # noqa: BLE001 - a failed call is a warning, never a crash
                    log.warning("%s: %s", _name, _text(exc))
                return response
            self._service_handles.append(self.node.create_service(Empty, name, handler))

    def _controller_manager(self) -> None:
        """ros2_control's services under /controller_manager/ when controller_manager_msgs is
        built (`python -m mexone.ros2.interfaces`: it has no wheel)."""
        self.controller_manager = None
        if self.lab.manager is None:
            return
        if convert.message_class("controller_manager_msgs/ControllerState") is None:
            self._skip_package("/controller_manager/... services", "controller_manager_msgs")
            return
        from mexone.ros2.controller_manager import ControllerManagerServices

        self.controller_manager = ControllerManagerServices(self)

    # ----- topics ------------------------------------------------------------------------------
    def sync_topics(self) -> None:
        """Mirror bus topics that appeared since the last call (simulation thread): outgoing
        ones (lazily), command topics in from ROS 2 under the ROS 1 name and ros2_control's."""
        bus = self.lab.bus
        if len(bus.topics) == self._known_topics:
            return
        self._known_topics = len(bus.topics)
        for name, topic in list(bus.topics.items()):
            if name in ("/clock", "/tf") or name in self._mirrors or name in self._inbound:
                continue
            if topic.publishers and ros_map.can_send(topic.type):
                cls = convert.ros2_class(topic.type)
                if cls is None:
                    self._skip(name, topic.type)
                    continue
                self._mirrors[name] = _Mirror(self, name, topic.type, cls)
            elif topic.subscriptions and ros_map.is_command(topic.type):
                cls = convert.ros2_class(topic.type)
                if cls is None:
                    self._skip(name, topic.type)
                    continue
                subs = [self.node.create_subscription(
                    cls, name, self._relay(name, lambda r, t=topic.type: convert.from_ros2(r, t)),
                    _qos(ros_map.COMMAND))]
                for alias, alias_type in ros_map.ros2_control_aliases(name, topic.type):
                    if name == alias:
                        continue
                    subs.append(self.node.create_subscription(
                        convert.message_class(alias_type), alias,
                        self._relay(name, convert.commands_to(topic.type), alias),
                        _qos(ros_map.COMMAND)))
                self._inbound[name] = subs

    def _skip(self, name: str, bus_type: type) -> None:
        """A type whose message package has no ROS 2 wheel (tf2_msgs, control_msgs,
        gazebo_msgs): left out. What start-up left out is one line (`notes()`, which the CLI
        prints); a topic of such a package that appears later is said once, at info level."""
        self._skip_package(name, ros_map.package_of(bus_type))

    def _skip_package(self, name: str, package: str) -> None:
        left_out = self._skipped.setdefault(package, [])
        left_out.append(name)
        if self._started and len(left_out) == 1:
            log.info("%s is not on ROS 2: %s has no wheel on PyPI%s; see docs/ros2.md", name,
                     package, _builds(package))

    def notes(self) -> list[str]:
        """What the start-up left out of the graph for want of a message package, as one line
        naming each package and what it carries (docs/ros2.md promises it); none when all were
        there."""
        if not self._started or not self._skipped:
            return []
        parts = []
        for package, names in self._skipped.items():
            more = f" and {len(names) - 1} more" if len(names) > 1 else ""
            parts.append(f"{names[0]}{more} ({package})")
        from mexone.ros2 import interfaces

        buildable = [p for p in self._skipped if p in interfaces.PACKAGES]
        build = (f"; python -m mexone.ros2.interfaces (the ros2-build extra) builds "
                 f"{', '.join(buildable)}") if buildable else ""
        return [f"not on ROS 2 (their message packages have no wheel on PyPI): "
                f"{', '.join(parts)}{build} (docs/ros2.md)"]

    def _relay(self, topic: str, build: Callable, via: str | None = None):
        def callback(ros_msg) -> None:  # the executor's thread: hand over, in order
            try:
                msg = build(ros_msg)
            except Exception as exc:  # noqa: BLE001 - a bad message is dropped, never a crash
                log.warning("%s: message dropped: %s", via or topic, _text(exc))
                return

            def deliver() -> None:
                self.lab.sim.note_input(via or topic)
                self.lab.bus.publish(topic, msg)  # the controllers check it (size, limits)
            self.post(deliver, via or topic)
        return callback

    def post(self, fn: Callable[[], object], what: str) -> None:
        """Hand `fn` to the simulation thread; what it raises is a warning on /rosout."""
        def guarded() -> None:
            try:
                fn()
            except Exception as exc:  # noqa: BLE001 - no input from the graph ends the simulation
                log.warning("%s: %s", what, _text(exc))
        self.lab.sim.work.put(guarded)

    def call(self, fn: Callable[[], object], timeout: float = 10.0):
        """Run `fn` in the simulation thread and return its result (service and parameter
        handlers); before attach() has finished, wait for it."""
        if not self.ready.wait(_START_WAIT):
            raise TimeoutError(f"the simulator has not started within {_START_WAIT:g} s")
        return self.lab.sim.work.call(fn, timeout=timeout)

    # ----- TF ----------------------------------------------------------------------------------
    def _tf_setup(self) -> None:
        """/tf with world -> the floating base, as the ROS 1 bridge (robot_state_publisher adds
        the links from joint_states), when tf2_msgs is built (`python -m
        mexone.ros2.interfaces`: it has no wheel)."""
        self.pub_tf = self._tf_timer = None
        tf_class = convert.message_class("tf2_msgs/TFMessage")
        if tf_class is None:
            self._skip("/tf", msgs.TFMessage)
            return
        self._tf_class = tf_class
        self.pub_tf = self.node.create_publisher(tf_class, "/tf", _qos(ros_map.TF))
        self._update_tf()

    def _update_tf(self) -> None:
        """The 50 Hz /tf timer runs only while someone subscribes (polled with the mirrors): a
        timer firing for nobody costs the simulation thread a pause 50 times a sim second."""
        if self.pub_tf is None:
            return
        wanted = self.lab.sim.compiled.free and self.pub_tf.get_subscription_count() > 0
        if wanted and self._tf_timer is None:
            self._tf_timer = self.lab.sim.add_periodic(0.02, self._publish_base_tf)
        elif not wanted and self._tf_timer is not None:
            self.lab.sim.remove_periodic(self._tf_timer)
            self._tf_timer = None

    def _publish_base_tf(self, sim) -> None:
        base = self.lab.base_transform()
        if base is None:
            return
        from geometry_msgs.msg import TransformStamped

        out = TransformStamped(child_frame_id=base.child_frame_id)
        out.header.frame_id = base.header.frame_id
        out.header.stamp.sec, out.header.stamp.nanosec = base.header.stamp.secs, \
            base.header.stamp.nsecs
        t, r = out.transform.translation, out.transform.rotation
        t.x, t.y, t.z = (float(v) for v in base.translation)
        r.w, r.x, r.y, r.z = (float(v) for v in base.rotation)
        self.pub_tf.publish(self._tf_class(transforms=[out]))

    # ----- /clock ------------------------------------------------------------------------------
    def _publish_clock(self, sim) -> None:
        """/clock every 1/CLOCK_FREQUENCY of sim time, no more often than that in wall time;
        flat out (no target RTF) at most FLAT_OUT_CLOCK a wall second. Faster than real time
        the timer fires less often in sim time, from the sim rate since its last firing: a
        1 ms timer would cut every physics step out of MuJoCo's batched mj_step."""
        wall_rate = CLOCK_FREQUENCY if sim.target_rtf else FLAT_OUT_CLOCK
        now, t_ns = time.perf_counter(), sim.time_ns
        last_wall, last_ns = self._clock_last
        if now > last_wall and t_ns > last_ns:
            sim_rate = (t_ns - last_ns) / NS / (now - last_wall)  # sim s per wall s
            respace(self._clock_timer, t_ns, clock_period_ns(sim_rate, CLOCK_FREQUENCY, wall_rate, 0.2))
        self._clock_last = (now, t_ns)
        self._clock_tokens = min(20.0, self._clock_tokens + (now - self._bucket_wall) * wall_rate)
        self._bucket_wall = now
        if self._clock_tokens >= 1.0:
            self._clock_tokens -= 1.0
            self._send_clock(t_ns, now)

    def _send_clock(self, t_ns: int, wall: float) -> None:
        self._last_clock_wall = wall
        self.pub_clock.publish(cdr.clock(t_ns))

    def _after_reset(self) -> None:
        self._send_clock(0, time.perf_counter())

    def pump(self, sim=None) -> None:
        """Call between steps in the simulation thread: new topics, who subscribes, and /clock
        while paused (the periodic publisher runs only while time moves)."""
        self.sync_topics()
        now = time.perf_counter()
        if now - self._last_poll >= _POLL:
            self._last_poll = now
            for mirror in self._mirrors.values():
                mirror.update()
            self._update_tf()
        lab_sim = self.lab.sim
        if lab_sim.paused and now - self._last_clock_wall >= _PAUSED_CLOCK:
            self._send_clock(lab_sim.time_ns, now)

    # ----- lifecycle ---------------------------------------------------------------------------
    def shutdown(self) -> None:
        logging.getLogger("mexone").removeHandler(self._rosout)
        if self.lab is not None:
            self.lab.sim.remove_periodic(self._clock_timer)
            if self._tf_timer is not None:
                self.lab.sim.remove_periodic(self._tf_timer)
        try:
            self.executor.shutdown(timeout_sec=1.0)
            self.node.destroy_node()
            self.rclpy.shutdown(context=self.context)
        except Exception:  # noqa: BLE001 - already down
            pass
        self._spin.join(timeout=2.0)


class _RosoutHandler(logging.Handler):
    """mexone's warnings and errors on /rosout too (rqt_console, `ros2 topic echo /rosout`)."""

    def __init__(self, node) -> None:
        super().__init__(logging.WARNING)
        self.node = node

    def emit(self, record: logging.LogRecord) -> None:
        try:
            logger = self.node.get_logger()
            (logger.error if record.levelno >= logging.ERROR else logger.warning)(
                record.getMessage())
        except Exception:  # noqa: BLE001 - logging must never take the simulation down
            pass


def _builds(package: str) -> str:
    from mexone.ros2 import interfaces

    return " (python -m mexone.ros2.interfaces, the ros2-build extra, builds it)" \
        if package in interfaces.PACKAGES else ""


def _text(exc: BaseException) -> str:
    return exc.one_line() if isinstance(exc, MexoneError) else f"{type(exc).__name__}: {exc}"


def check_not_both(ros1: bool, ros2: bool) -> None:
    """ROS 1's and ROS 2's Python message packages share names: one process takes one."""
    if ros1 and ros2:
        raise InputError("--ros and --ros2 cannot run in one process (ROS 1's and ROS 2's "
                         "message packages have the same Python names)",
                         hint="run one simulator with --ros2 and bridge with ros1_bridge, or "
                              "pick one")

