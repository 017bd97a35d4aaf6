"""Ros1Bridge: the simulation as a node in a real ROS 1 graph, through rospy (Debian's).

It does what gazebo_ros + gazebo_ros_control did for the seed: sets /robot_description, takes
the controller configuration from the parameter server when none is given (so `rosparam load`
+ the seed's control.launch works), mirrors the in-process topics (every bus topic whose
message type has a ROS name, see `convert.py`: joint_states, controller states, the sensors'
IMU, force-torque, contacts, cameras and clouds, balance; commands in),
publishes /clock (sim time, so use_sim_time nodes follow it, also while paused) and the
floating base as TF world -> <root>, sends mexone's warnings to /rosout, and starts the
controller manager's services (controller_manager.py) and gazebo_ros' (gazebo.py).

rospy callbacks run in rospy's threads; they only queue work on the simulation's work queue,
which the simulation thread runs between steps, so ROS never touches the physics. Outgoing
topics are mirrored only while a ROS node subscribes, so nobody pays for what nobody reads.
"""

from __future__ import annotations

import collections
import importlib
import logging
import os
import sys
import threading
import time
from collections.abc import Callable

from mexone.bus import msgs, ros_map
from mexone.bus.clock import clock_period_ns, respace
from mexone.bus.topics import Relay
from mexone.errors import InputError, MexoneError
from mexone.ros1 import convert, interfaces

__all__ = ["import_rospy", "Ros1Bridge", "ROS_INSTALL", "CLOCK_PERIOD", "DEFAULT_NODE",
           "CLOCK_FREQUENCY"]

log = logging.getLogger("mexone.ros")

ROS_INSTALL = ("apt-get install ros-core python3-rospy python3-rostopic python3-std-msgs "
               "python3-sensor-msgs python3-std-srvs python3-tf2-msgs python3-trajectory-msgs "
               "ros-robot-state-publisher python3-actionlib python3-dynamic-reconfigure")
_DEBIAN_SITE = "/usr/lib/python3/dist-packages"
DEFAULT_NODE = "mexone"
CLOCK_FREQUENCY = 1000.0  # Hz of /clock (gazebo_ros' pub_clock_frequency), in sim AND wall time
CLOCK_PERIOD = 1.0 / CLOCK_FREQUENCY
FLAT_OUT_CLOCK = 200.0  # Hz of wall time: /clock's rate when running as fast as possible
_MAX_STRIDE = 200.0  # at most 200 clock periods of sim time between /clock messages
_CLOCK_BURST = 20.0  # /clock messages that may go out at once after a pause in wall time (pacing)
_PAUSED_CLOCK = 0.1  # s of wall time between /clock messages while paused (Gazebo keeps publishing)
_NOT_MIRRORED = {"/clock", "/tf"}  # the bridge publishes these itself (see _publish_clock, TF)
_HEAVY = (msgs.Image, msgs.PointCloud2)
_START_WAIT = 120.0  # s a service call made while the simulator starts waits for it


def import_rospy():
    """rospy from the system's ROS (Debian packages), usable from this environment, with
    mexone's generated message packages (gazebo_msgs, controller_manager_msgs, control_msgs)."""
    _refuse_ros2_messages()
    try:
        rospy = importlib.import_module("rospy")
    except ImportError:
        if not os.path.isdir(os.path.join(_DEBIAN_SITE, "rospy")):
            raise MexoneError("ROS 1 (rospy) is not installed",
                              hint=f"install it with: {ROS_INSTALL}") from None
        if _DEBIAN_SITE not in sys.path:
            sys.path.append(_DEBIAN_SITE)  # appended: pip's packages keep precedence
        try:
            rospy = importlib.import_module("rospy")
        except ImportError as exc:
            raise MexoneError(f"ROS 1 is installed but rospy fails to import: {exc}",
                              hint=f"reinstall with: {ROS_INSTALL}") from None
    interfaces.use_generated()
    return rospy


def _refuse_ros2_messages() -> None:
    """ROS 2's message wheels (the ros2 extra) install `std_msgs`, `sensor_msgs`, ... under the
    names ROS 1's packages have: in one environment Python finds only one of each. rospy with
    ROS 2's messages fails deep inside; say so at once instead."""
    import importlib.util

    spec = importlib.util.find_spec("rosgraph_msgs")
    origin = spec.submodule_search_locations[0] if spec and spec.submodule_search_locations \
        else None
    if origin and os.path.exists(os.path.join(origin, "msg", "_clock.py")):  # rosidl's naming
        raise MexoneError(f"this Python environment has ROS 2's message packages ({origin}), "
                          "which hide ROS 1's of the same names",
                          hint="run --ros from an environment without the ros2 extra (a venv), or "
                               "use --ros2")


class _Mirror:
    """One bus topic published on ROS while ROS nodes subscribe to it (rospy tells us)."""

    def __init__(self, bridge: Ros1Bridge, topic: str, bus_type: type):
        rospy = bridge.rospy
        self.bridge, self.topic, self.cls = bridge, topic, convert.ros_class(bus_type)
        self.relay = Relay(bridge.lab.bus, topic, self.forward, "ROS 1 bridge")
        # images and clouds are MBs each: a subscriber that falls behind gets the latest ones
        queue = 2 if bus_type in _HEAVY else 100
        self.publisher = rospy.Publisher(topic, self.cls, queue_size=queue,
                                         subscriber_listener=self._Listener(self))

    class _Listener:
        def __init__(self, mirror: _Mirror):
            self.mirror = mirror

        def peer_subscribe(self, topic_name, topic_publish, peer_publish):
            self.mirror.bridge.lab.sim.work.put(self.mirror.start)

        def peer_unsubscribe(self, topic_name, num_peers):
            if num_peers == 0:
                self.mirror.bridge.lab.sim.work.put(self.mirror.stop)

    def start(self) -> None:  # simulation thread
        self.relay.want(True)

    def stop(self) -> None:  # simulation thread
        self.relay.want(self.publisher.get_num_connections() > 0)

    def forward(self, msg) -> None:
        self.publisher.publish(convert.to_ros(msg, self.cls))


class Ros1Bridge:
    """Connect first (the controller configuration may live on the parameter server), then
    attach the lab."""

    def __init__(self, node_name: str = DEFAULT_NODE, gazebo_namespace: str | None = None,
                 clock_frequency: float | None = None):
        self.rospy = rospy = import_rospy()
        import rosgraph

        uri = os.environ.get("ROS_MASTER_URI", "http://localhost:11311")
        master = rosgraph.Master(f"/{node_name}_probe")
        if not master.is_online():
            raise MexoneError(f"no ROS master at {uri}",
                              hint="start roscore, or set ROS_MASTER_URI to where it runs")
        if _node_alive(master, f"/{node_name}"):
            raise InputError(f"a node named /{node_name} already runs on the ROS master at {uri} "
                             "(another 'mexone sim --ros'?)",
                             hint="give this simulator another --name (and --namespace)")
        rospy.init_node(node_name, disable_signals=True)
        self.node_name = node_name
        # gazebo_ros' services live under its node name, /gazebo; a second simulator under its own
        self.gazebo_ns = "/" + (gazebo_namespace or ("gazebo" if node_name == DEFAULT_NODE
                                                     else node_name)).strip("/")
        if clock_frequency is None:
            clock_frequency = float(rospy.get_param(f"{self.gazebo_ns}/pub_clock_frequency",
                                                    CLOCK_FREQUENCY))
        if not 0 < clock_frequency <= 1e6:
            raise InputError(f"pub_clock_frequency {clock_frequency} must be > 0 and <= 1e6 Hz")
        self.clock_frequency = clock_frequency
        self._rosout = _RosoutHandler()
        logging.getLogger("mexone").addHandler(self._rosout)
        self.lab = None
        self.ready = threading.Event()  # attach() finished: the simulation thread takes calls
        self._direct = False
        self._owner: threading.Thread | None = None
        from mexone.ros1.gazebo import GazeboNode

        # gazebo_ros' services come with the world, before any robot (Gazebo offers them before
        # it spawns one): a script that calls spawn_urdf_model as soon as the node is up works;
        # calls made while the robot still compiles wait for attach()
        self.gazebo = GazeboNode(self)
        self.services: list = [self.gazebo]

    def attach(self, lab, urdf_text: str) -> None:
        from rosgraph_msgs.msg import Clock
        from tf2_msgs.msg import TFMessage

        rospy = self.rospy
        self.lab = lab
        self._owner = threading.current_thread()
        self._direct = True  # until attach returns, this thread is the one that steps the sim
        self._types = {"Clock": Clock, "TFMessage": TFMessage}
        rospy.set_param(f"{lab.namespace}/robot_description", urdf_text)
        if self.node_name == DEFAULT_NODE or not rospy.has_param("/robot_description"):
            rospy.set_param("/robot_description", urdf_text)
        if not rospy.has_param("/use_sim_time"):
            rospy.set_param("/use_sim_time", True)  # as gazebo_ros' empty_world.launch does
        self.pub_clock = rospy.Publisher("/clock", Clock, queue_size=10)
        self.pub_tf = rospy.Publisher("/tf", TFMessage, queue_size=10)
        self._mirrors: dict[str, _Mirror] = {}
        self._unsendable: set[str] = set()  # topics whose ROS message package is missing
        self._inbound: dict[str, object] = {}
        self._known_topics = -1
        self._clock_pending: collections.deque[int] = collections.deque()
        self._clock_wake = threading.Event()
        threading.Thread(target=self._clock_loop, name="mexone-clock", daemon=True).start()
        self._last_clock_wall = self._bucket_wall = time.perf_counter()
        self._clock_tokens = _CLOCK_BURST
        self._last_clock_ns = -1
        self._clock_timer = lab.sim.add_periodic(1.0 / self.clock_frequency, self._publish_clock)
        self._tf_timer = lab.sim.add_periodic(0.02, self._publish_base_tf)
        lab.sim.on_reset(self._after_reset)
        self.sync_topics()
        from mexone.ros1.controller_manager import ControllerManagerNode

        if lab.manager is not None:
            self.services.append(ControllerManagerNode(self))
        self.gazebo.attach()
        lab.sim.recover_outside = True  # no input from the graph may end the simulation
        self._direct = False
        self.ready.set()
        self.master_ok = True
        self._watch = threading.Thread(target=self._watch_master, daemon=True)
        self._watch.start()

    # ----- topics ------------------------------------------------------------------------------
    def sync_topics(self) -> None:
        """Mirror bus topics that appeared since the last call (simulation thread): advertised
        ones out to ROS (lazily), subscribed command topics in from ROS."""
        bus = self.lab.bus
        if len(bus.topics) == self._known_topics:
            return
        self._known_topics = len(bus.topics)
        for name, topic in list(bus.topics.items()):
            if name in _NOT_MIRRORED or name in self._mirrors or name in self._inbound:
                continue
            if topic.publishers and convert.can_send(topic.type):
                if convert.ros_class(topic.type) is None:  # its package is not installed
                    if name not in self._unsendable:
                        self._unsendable.add(name)
                        ros_type = msgs.ROS_TYPES[topic.type]
                        log.warning("%s (%s) is not published on ROS: this ROS has no %s "
                                    "(apt install python3-%s)", name, ros_type,
                                    ros_type.split("/")[0],
                                    ros_type.split("/")[0].replace("_", "-"))
                    continue
                self._mirrors[name] = _Mirror(self, name, topic.type)
            elif topic.subscriptions and ros_map.is_command(topic.type):
                # commands: ask publishers for TCP_NODELAY (no Nagle batching of small messages)
                self._inbound[name] = self.rospy.Subscriber(name, convert.ros_class(topic.type),
                                                            self._relay(name), queue_size=100,
                                                            tcp_nodelay=True)

    def _relay(self, topic: str):
        def callback(ros_msg) -> None:  # rospy's thread: hand over, in order, to the sim thread
            try:
                msg = convert.from_ros(ros_msg)
            except Exception as exc:  # noqa: BLE001 - a bad message is dropped, never a crash
                log.warning("%s: message dropped: %s", topic, exc)
                return

            def deliver() -> None:
                self.lab.sim.note_input(topic)
                self.lab.bus.publish(topic, msg)  # the controllers check it (finite, size, limits)
            self.post(deliver, topic)
        return callback

    def post(self, fn: Callable[[], object], what: str) -> None:
        """Hand `fn` to the simulation thread without waiting; what it raises is a warning on
        /rosout naming `what`, never the end of the simulation loop."""
        def guarded() -> None:
            try:
                fn()
            except Exception as exc:  # noqa: BLE001 - no input from the graph ends the simulation
                log.warning("%s: %s", what, exc.one_line() if isinstance(exc, MexoneError)
                            else f"{type(exc).__name__}: {exc}")
        self.lab.sim.work.put(guarded)

    def call(self, fn: Callable[[], object], timeout: float = 10.0):
        """Run `fn` in the simulation thread and return its result (for service handlers);
        before attach() has finished, wait for it (the robot may still be compiling)."""
        if self._direct and threading.current_thread() is self._owner:
            return fn()
        if not self.ready.wait(_START_WAIT):
            raise TimeoutError(f"the simulator has not started within {_START_WAIT:g} s")
        return self.lab.sim.work.call(fn, timeout=timeout)

    # ----- /clock ------------------------------------------------------------------------------
    def _publish_clock(self, sim) -> None:
        """/clock every 1/pub_clock_frequency of sim time, and no more often than that in wall
        time; flat out (no target RTF), at most FLAT_OUT_CLOCK a wall second. Every node with
        use_sim_time (rosout, robot_state_publisher, ...) subscribes, so each message costs a
        serialisation and a socket write: at 1 kHz per wall second that was 2/3 of a flat-out
        run. Nodes still see time advance in steps of at most 1/FLAT_OUT_CLOCK wall seconds."""
        wall_rate = self.clock_frequency if sim.target_rtf else min(self.clock_frequency,
                                                                    FLAT_OUT_CLOCK)
        # faster than real time, fire less often in sim time: about wall_rate per wall second,
        # on the run loop's batch boundaries (bus.clock)
        respace(self._clock_timer, sim.time_ns,
                clock_period_ns(sim.rtf.value, self.clock_frequency, wall_rate,
                                _MAX_STRIDE / self.clock_frequency))
        now = time.perf_counter()  # a token bucket: wall_rate tokens per wall second
        self._clock_tokens = min(_CLOCK_BURST, self._clock_tokens
                                 + (now - self._bucket_wall) * wall_rate)
        self._bucket_wall = now
        if self._clock_tokens >= 1.0:
            self._clock_tokens -= 1.0
            self._send_clock(sim.time_ns, now)

    def _send_clock(self, t_ns: int, wall: float) -> None:
        """Queue a /clock value: a thread of its own publishes it, because rospy yields the CPU
        (time.sleep(0)) on every publish to a connected subscriber, which on a busy machine cost
        the simulation thread a scheduler quantum per message."""
        self._last_clock_wall, self._last_clock_ns = wall, t_ns
        pending = self._clock_pending
        pending.append(t_ns)
        if len(pending) > _CLOCK_BURST:  # the publisher fell behind: the latest times matter
            pending.popleft()
        self._clock_wake.set()

    def _clock_loop(self) -> None:
        clock_cls = self._types["Clock"]
        while not self.rospy.is_shutdown():
            self._clock_wake.wait(0.5)
            self._clock_wake.clear()
            while self._clock_pending:
                try:
                    t_ns = self._clock_pending.popleft()
                    self.pub_clock.publish(clock_cls(clock=convert.ros_time(t_ns)))
                except (IndexError, self.rospy.ROSException):
                    break

    def _after_reset(self) -> None:
        """Sim time is 0 again: say so at once (nodes waiting on /clock see one clean jump)."""
        self._send_clock(0, time.perf_counter())

    def pump(self, sim=None) -> None:
        """Call between steps in the simulation thread (the run's on_tick): new topics, and
        /clock while paused (the periodic publisher runs only while time moves)."""
        self.sync_topics()
        lab_sim = self.lab.sim
        now = time.perf_counter()
        if lab_sim.paused and now - self._last_clock_wall >= _PAUSED_CLOCK:
            self._send_clock(lab_sim.time_ns, now)

    # ----- TF ----------------------------------------------------------------------------------
    def _publish_base_tf(self, sim) -> None:
        """World -> floating base; robot_state_publisher adds the links from joint_states."""
        if not sim.compiled.free or self.pub_tf.get_num_connections() == 0:
            return
        # robot_state_publisher's tf_prefix is the user's to set: frames are the links' names
        base = msgs.TFMessage([self.lab.base_transform()])
        self.pub_tf.publish(convert.to_ros(base, self._types["TFMessage"]))

    # ----- lifecycle ---------------------------------------------------------------------------
    def _watch_master(self) -> None:
        import rosgraph

        master = rosgraph.Master(f"/{self.node_name}_watch")
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
        logging.getLogger("mexone").removeHandler(self._rosout)
        if self.lab is not None:
            self.lab.sim.remove_periodic(self._tf_timer)
            self.lab.sim.remove_periodic(self._clock_timer)
        self.rospy.signal_shutdown("mexone stopped")


class _RosoutHandler(logging.Handler):
    """mexone's warnings and errors on /rosout too (rqt_console), besides stderr."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)

    def emit(self, record: logging.LogRecord) -> None:
        try:
            from rosgraph_msgs.msg import Log
            from rospy.impl.rosout import _rosout

            level = Log.ERROR if record.levelno >= logging.ERROR else Log.WARN
            _rosout(level, record.getMessage(), record.filename, record.lineno, record.funcName)
        except Exception:  # noqa: BLE001 - logging must never take the simulation down
            pass


def _node_alive(master, name: str) -> bool:
    """Whether a node of that name is registered and answers (a dead one may be replaced)."""
    import xmlrpc.client

    try:
        uri = master.lookupNode(name)
    except Exception:  # noqa: BLE001 - rosgraph raises its own error types for "unknown"
        return False
    try:
        code, _, _ = xmlrpc.client.ServerProxy(uri).getPid("/mexone_probe")
        return code == 1
    except OSError:
        return False
