"""ros_control's controller manager on ROS: the services under /<ns>/controller_manager/ with
controller_manager_msgs' definitions, and per controller what ros_controllers offer beside the
command topic: a dynamic_reconfigure server `<ctrl>/pid` for PID gains (what `dynparam set` and
rqt_reconfigure call), and for trajectory controllers the `follow_joint_trajectory` action
(Debian's actionlib) and the `query_state` service.

Configurations are read from the parameter server when a controller is loaded, as ros_control
does (`rosparam load`, then the spawner), else from the YAML mexone started with. Bad requests
answer ok=False and say why on /rosout; the node never falls over."""

from __future__ import annotations

import logging
import math

import numpy as np
import yaml

from mexone.control.config import parse_control_config
from mexone.control.controllers.trajectory import (
    PREEMPTED,
    SUCCESSFUL,
    TrajectoryGoal,
)
from mexone.control.manager import BEST_EFFORT, STRICT
from mexone.control.spec import PidGains
from mexone.errors import InputError, MexoneError
from mexone.ranges import GAIN_D, GAIN_I, GAIN_P, I_CLAMP, TIMEOUT, number_text
from mexone.ros1 import convert

__all__ = ["ControllerManagerNode", "pid_config_type", "params_config_type"]

log = logging.getLogger("mexone.ros")
_INTERFACE_PREFIX = "hardware_interface::"
# dynamic_reconfigure's min and max of control_toolbox's parameters, from mexone.ranges
_GAIN_RANGE = {"p": (GAIN_P.low, GAIN_P.high), "i": (GAIN_I.low, GAIN_I.high),
               "d": (GAIN_D.low, GAIN_D.high), "i_clamp_min": (I_CLAMP.low, 0.0),
               "i_clamp_max": (0.0, I_CLAMP.high)}
_GAIN_CHECKS = {"p": GAIN_P, "i": GAIN_I, "d": GAIN_D, "i_clamp_min": I_CLAMP,
                "i_clamp_max": I_CLAMP}


class ControllerManagerNode:
    """The lab's robot's controller manager, or (`manager`, `ns`) a spawned robot's."""

    def __init__(self, bridge, manager=None, ns: str | None = None):
        from controller_manager_msgs import srv

        self.bridge, self.rospy = bridge, bridge.rospy
        self.lab = bridge.lab
        self.manager = manager or self.lab.manager
        self.ns = ns or self.lab.namespace
        rospy, base = self.rospy, f"{self.ns}/controller_manager/"
        self.services = [
            rospy.Service(base + "list_controllers", srv.ListControllers, self._list),
            rospy.Service(base + "list_controller_types", srv.ListControllerTypes, self._types),
            rospy.Service(base + "load_controller", srv.LoadController, self._load),
            rospy.Service(base + "unload_controller", srv.UnloadController, self._unload),
            rospy.Service(base + "switch_controller", srv.SwitchController, self._switch),
            rospy.Service(base + "reload_controller_libraries", srv.ReloadControllerLibraries,
                          self._reload),
        ]
        self.extras: dict[str, list] = {}  # controller -> its reconfigure server, action, ...
        self.trajectories: dict[str, TrajectoryInterfaces] = {}  # trajectory controller -> its action
        for name in list(self.manager.controllers):
            self._add_extras(name)

    def shutdown(self) -> None:
        """Take the services down (the robot was deleted)."""
        for name in list(self.extras):
            self._remove_extras(name)
        for service in self.services:
            service.shutdown()

    # ----- services (rospy threads) -------------------------------------------------------------
    def _list(self, _req):
        from controller_manager_msgs.msg import ControllerState, HardwareInterfaceResources
        from controller_manager_msgs.srv import ListControllersResponse

        infos = self.bridge.call(self.manager.list_controllers)
        return ListControllersResponse([ControllerState(
            i.name, i.state, i.type,
            [HardwareInterfaceResources(_INTERFACE_PREFIX + (i.interface or "JointStateInterface"),
                                        list(i.joints))]) for i in infos])

    def _types(self, _req):
        from controller_manager_msgs.srv import ListControllerTypesResponse

        types = self.manager.list_types()
        return ListControllerTypesResponse(types, ["controller_interface::ControllerBase"] * len(types))

    def _load(self, req):
        from controller_manager_msgs.srv import LoadControllerResponse

        name = req.name
        try:
            spec = self._spec_from_parameters(name)

            def load():
                if spec is not None:
                    self.manager.define(spec)
                self.manager.load(name)
            self.bridge.call(load)
        except Exception as exc:  # noqa: BLE001 - every refusal is ok=False, never a crash
            log.error("load_controller %s: %s", name, _text(exc))
            return LoadControllerResponse(False)
        self._add_extras(name)
        return LoadControllerResponse(True)

    def _unload(self, req):
        from controller_manager_msgs.srv import UnloadControllerResponse

        try:
            self.bridge.call(lambda: self.manager.unload(req.name))
        except Exception as exc:  # noqa: BLE001 - every refusal is ok=False, never a crash
            log.error("unload_controller %s: %s", req.name, _text(exc))
            return UnloadControllerResponse(False)
        self._remove_extras(req.name)
        return UnloadControllerResponse(True)

    def _switch(self, req):
        from controller_manager_msgs.srv import SwitchControllerResponse

        strictness = req.strictness
        try:
            if strictness == 0:  # unset: ros_control warns and takes BEST_EFFORT
                log.warning("switch_controller: no strictness given (0); using BEST_EFFORT (1), "
                            "as ros_control does; STRICT is 2")
                strictness = BEST_EFFORT
            elif strictness not in (BEST_EFFORT, STRICT):
                raise InputError(f"strictness {strictness} must be BEST_EFFORT (1) or STRICT (2)")
            TIMEOUT.check(req.timeout, "timeout")
            start, stop = list(req.start_controllers), list(req.stop_controllers)
            self.bridge.call(lambda: self.manager.switch(start=start, stop=stop,
                                                         strictness=strictness))
        except Exception as exc:  # noqa: BLE001 - every refusal is ok=False, never a crash
            log.error("switch_controller: %s", _text(exc))
            return SwitchControllerResponse(False)
        return SwitchControllerResponse(True)

    def _reload(self, req):
        """Controller types are Python classes: nothing to reload; ros_control refuses while
        controllers are loaded unless force_kill, which stops and unloads them all."""
        from controller_manager_msgs.srv import ReloadControllerLibrariesResponse

        loaded = list(self.manager.controllers)
        if loaded and not req.force_kill:
            log.error("reload_controller_libraries: controllers are loaded (%s); pass force_kill "
                      "to stop and unload them", ", ".join(loaded))
            return ReloadControllerLibrariesResponse(False)

        def kill():
            self.manager.switch(stop=[n for n, c in self.manager.controllers.items() if c.running])
            for name in list(self.manager.controllers):
                self.manager.unload(name)
        try:
            self.bridge.call(kill)
        except Exception as exc:  # noqa: BLE001 - every refusal is ok=False, never a crash
            log.error("reload_controller_libraries: %s", _text(exc))
            return ReloadControllerLibrariesResponse(False)
        for name in loaded:
            self._remove_extras(name)
        return ReloadControllerLibrariesResponse(True)

    def _spec_from_parameters(self, name: str):
        """`/<ns>/<name>` from the parameter server as a ControllerSpec, or None if absent."""
        key = f"{self.ns}/{name}"
        if not self.rospy.has_param(key):
            return None
        params = self.rospy.get_param(key)
        ns = self.ns.strip("/")
        config = parse_control_config(yaml.safe_dump({ns: {name: params}}))
        return config.controllers[name]

    # ----- what each controller adds ------------------------------------------------------------
    def _add_extras(self, name: str) -> None:
        ctrl = self.manager.controllers.get(name)
        if ctrl is None or name in self.extras:
            return
        extras = []
        if ctrl.gains is not None and len(ctrl.joints) == 1:
            extras.append(self._reconfigure(name, ctrl.gains[0]))
        params = ctrl.declared_params()
        if params:
            extras.append(self._reconfigure_params(name, params, ctrl.params))
        if ctrl.takes_trajectories:
            self.trajectories[name] = TrajectoryInterfaces(self, name)
            extras += self.trajectories[name].handles
        self.extras[name] = extras

    def _remove_extras(self, name: str) -> None:
        self.trajectories.pop(name, None)
        for handle in self.extras.pop(name, []):
            # a dynamic_reconfigure Server has no shutdown(): its service and topics go one by one
            parts = [getattr(handle, a) for a in ("set_service", "descr_topic", "update_topic")
                     if hasattr(handle, a)] or [handle]
            for part in parts:
                for method in ("shutdown", "unregister"):
                    if hasattr(part, method):
                        getattr(part, method)()
                        break

    def _reconfigure(self, name: str, gains: PidGains):
        """dynamic_reconfigure server at <ns>/<ctrl>/pid with control_toolbox's parameters."""
        from dynamic_reconfigure.server import Server

        def on_change(config, _level):  # rospy thread (and once at start, with the server's values)
            try:  # dynamic_reconfigure clamps to min and max, but a NaN passes its comparisons
                values = {k: check.check(config[k], f"{name}/pid {k}")
                          for k, check in _GAIN_CHECKS.items()}
                new = PidGains(values["p"], values["i"], values["d"], values["i_clamp_min"],
                               values["i_clamp_max"], bool(config["antiwindup"]))
                old = self.bridge.call(lambda: list(self.manager.controllers[name].gains))

                def put() -> None:
                    if old == [new] * len(old):
                        return  # the server's first call, or no change: no outside input
                    self.manager.set_gains(name, new)
                    self.lab.sim.note_input(f"{self.ns}/{name}/pid (p {number_text(new.p)}, i "
                                            f"{number_text(new.i)}, d {number_text(new.d)})",
                                            lambda: self.manager.set_gains(name, old))
                self.bridge.call(put)
            except Exception as exc:  # noqa: BLE001 - a refusal keeps the gains, never a crash
                log.error("%s/pid: %s", name, _text(exc))
                try:
                    current = self.bridge.call(lambda: self.manager.controllers[name].gains[0])
                    config.update(_gain_values(current))
                except Exception:  # noqa: BLE001 - the controller went meanwhile
                    pass
            return config

        return Server(pid_config_type(gains), on_change, namespace=f"{self.ns}/{name}/pid")


    def _reconfigure_params(self, name: str, declared: dict, values: dict):
        """dynamic_reconfigure server at <ns>/<ctrl> with a Python controller's declared
        parameters; each change checked by the same Param as the YAML, a refusal put back."""
        from dynamic_reconfigure.server import Server

        def on_change(config, _level):  # rospy thread (and once at start)
            current = self.bridge.call(lambda: dict(self.manager.controllers[name].params))
            try:
                changed = {k: config[k] for k in declared if k in config and config[k] != current.get(k)}

                def put() -> None:
                    for key, value in changed.items():
                        self.manager.set_param(name, key, value)
                if changed:
                    self.bridge.call(put)
                    shown = ", ".join(f"{k} {v}" for k, v in changed.items())
                    self.lab.sim.note_input(f"{self.ns}/{name} ({shown})")
            except Exception as exc:  # noqa: BLE001 - a refusal keeps the values, never a crash
                log.error("%s: %s", name, _text(exc))
                try:
                    current = self.bridge.call(lambda: dict(self.manager.controllers[name].params))
                    config.update({k: current[k] for k in declared if k in current})
                except Exception:  # noqa: BLE001 - the controller went meanwhile
                    pass
            return config

        return Server(params_config_type(declared, values), on_change, namespace=f"{self.ns}/{name}")


class TrajectoryInterfaces:
    """follow_joint_trajectory (actionlib) and query_state for one trajectory controller."""

    def __init__(self, node: ControllerManagerNode, name: str):
        import actionlib
        from control_msgs.msg import FollowJointTrajectoryAction
        from control_msgs.srv import QueryTrajectoryState

        self.node, self.name = node, name
        self.controller = node.manager.controllers[name]
        base = f"{node.ns}/{name}"
        self.server = actionlib.ActionServer(f"{base}/follow_joint_trajectory",
                                             FollowJointTrajectoryAction, self._goal, self._cancel,
                                             auto_start=False)
        self.server.start()
        self.query = node.rospy.Service(f"{base}/query_state", QueryTrajectoryState, self._query)
        self.handles = [_ActionHandle(self.server), self.query]

    def _goal(self, handle) -> None:
        """actionlib's thread, holding its lock: hand over and return at once."""
        goal = handle.get_goal()
        try:
            trajectory = convert.trajectory_from_ros(goal.trajectory)
        except Exception as exc:  # noqa: BLE001 - rejected, never a crash
            self._reject(handle, f"cannot read the trajectory: {exc}")
            return
        joints = list(goal.trajectory.joint_names)

        def start() -> None:  # simulation thread: a goal is always answered
            try:
                self._start(handle, goal, trajectory, joints)
            except Exception as exc:  # noqa: BLE001 - rejected, never a crash
                self._reject(handle, _text(exc))
        self.node.bridge.post(start, f"{self.node.ns}/{self.name}/follow_joint_trajectory")

    def _reject(self, handle, text: str) -> None:
        from control_msgs.msg import FollowJointTrajectoryResult

        log.warning("%s/%s/follow_joint_trajectory: goal rejected: %s", self.node.ns, self.name,
                    text)
        handle.set_rejected(FollowJointTrajectoryResult(
            error_code=FollowJointTrajectoryResult.INVALID_GOAL, error_string=text), text)

    def _start(self, handle, goal, trajectory, joints) -> None:  # simulation thread
        from control_msgs.msg import FollowJointTrajectoryResult

        order = {j: i for i, j in enumerate(self.controller.joints)}

        def tolerance(items, field):
            values = np.zeros(len(order))
            for tol in items:
                if tol.name in order:
                    values[order[tol.name]] = getattr(tol, field)
            return values

        outcome: list = []

        def done(code: int, text: str) -> None:
            outcome.append(code)
            result = FollowJointTrajectoryResult(error_code=code if code != PREEMPTED else 0,
                                                 error_string=text)
            if not accepted:
                log.warning("%s/%s/follow_joint_trajectory: goal rejected: %s", self.node.ns,
                            self.name, text)
                handle.set_rejected(result, text)
            elif code == SUCCESSFUL:
                handle.set_succeeded(result, text)
            elif code == PREEMPTED:
                handle.set_canceled(result, text)
            else:
                handle.set_aborted(result, text)

        accepted = False
        tg = TrajectoryGoal(tolerance(goal.path_tolerance, "position"),
                            tolerance(goal.goal_tolerance, "position"),
                            tolerance(goal.goal_tolerance, "velocity"),
                            goal.goal_time_tolerance.to_sec(), done,
                            lambda t, d, v, a, av: self._feedback(handle, joints, t, d, v, a, av))
        sim = self.node.lab.sim
        # validation ends the goal at once (rejected) before it is accepted
        self.controller.execute(trajectory, tg, sim.time)
        if not outcome:
            accepted = True
            sim.note_input(f"{self.node.ns}/{self.name}/follow_joint_trajectory goal")
            handle.set_accepted("")

    def _feedback(self, handle, joints, t, desired, velocity, actual, actual_velocity) -> None:
        from control_msgs.msg import FollowJointTrajectoryFeedback
        from trajectory_msgs.msg import JointTrajectoryPoint

        fb = FollowJointTrajectoryFeedback(joint_names=list(self.controller.joints))
        fb.header.stamp = convert.ros_time(round(t * 1e9))
        fb.desired = JointTrajectoryPoint(positions=list(desired), velocities=list(velocity))
        fb.actual = JointTrajectoryPoint(positions=list(actual), velocities=list(actual_velocity))
        fb.error = JointTrajectoryPoint(positions=list(desired - actual),
                                        velocities=list(velocity - actual_velocity))
        handle.publish_feedback(fb)

    def _cancel(self, handle) -> None:
        sim = self.node.lab.sim
        self.node.bridge.post(lambda: self.controller.cancel(sim.time),
                              f"{self.node.ns}/{self.name}/follow_joint_trajectory cancel")

    def _query(self, req):
        from control_msgs.srv import QueryTrajectoryStateResponse

        t = req.time.to_sec()
        if not math.isfinite(t):
            return QueryTrajectoryStateResponse()
        try:
            pos, vel, acc = self.node.bridge.call(lambda: self.controller.query_state(t))
        except Exception as exc:  # noqa: BLE001 - an empty answer and a line, never a crash
            log.warning("%s/%s/query_state: %s", self.node.ns, self.name, _text(exc))
            return QueryTrajectoryStateResponse()
        return QueryTrajectoryStateResponse(list(self.controller.joints), list(pos), list(vel), list(acc))


class _ActionHandle:
    def __init__(self, server):
        self.server = server

    def shutdown(self) -> None:
        timer = getattr(self.server, "status_timer", None)
        if timer is not None:  # first: it publishes the status on a publisher about to go
            timer.shutdown()
        for attr in ("status_pub", "result_pub", "feedback_pub", "goal_sub", "cancel_sub"):
            handle = getattr(self.server, attr, None)
            if handle is not None:
                handle.unregister()


def _gain_values(g: PidGains) -> dict:
    return {"p": g.p, "i": g.i, "d": g.d, "i_clamp_min": g.i_clamp_min,
            "i_clamp_max": g.i_clamp_max, "antiwindup": g.antiwindup}


def pid_config_type(current: PidGains):
    """control_toolbox's Parameters config (p, i, d, i_clamp_min, i_clamp_max, antiwindup) as
    dynamic_reconfigure's generated module would describe it, defaulting to `current`."""
    from types import SimpleNamespace

    values = _gain_values(current)
    parameters = []
    for key, value in values.items():
        kind = "bool" if key == "antiwindup" else "double"
        lo, hi = _GAIN_RANGE.get(key, (False, True))
        parameters.append({"name": key, "type": kind, "default": value, "level": 1,
                           "description": f"PID {key}", "min": lo, "max": hi,
                           "srcline": 0, "srcfile": "mexone", "edit_method": "",
                           "ctype": "bool" if kind == "bool" else "double",
                           "cconsttype": "const bool" if kind == "bool" else "const double"})
    description = {"name": "Default", "type": "", "state": True, "cstate": "true", "id": 0,
                   "parent": 0, "parameters": parameters, "groups": [], "srcline": 0,
                   "srcfile": "mexone", "class": "DEFAULT", "parentclass": "",
                   "parentname": "Default", "field": "default", "upper": "DEFAULT", "lower": "groups"}
    return SimpleNamespace(
        config_description=description, defaults=dict(values),
        min={p["name"]: p["min"] for p in parameters}, max={p["name"]: p["max"] for p in parameters},
        level={p["name"]: 1 for p in parameters}, type={p["name"]: p["type"] for p in parameters},
        all_level=1)


_DR_TYPES = {bool: "bool", int: "int", float: "double", str: "str"}
_DR_C = {"bool": ("bool", "const bool"), "int": ("int", "const int"),
         "double": ("double", "const double"), "str": ("std::string", "const char * const")}
_DR_BOUND = 1e300  # dynamic_reconfigure wants numbers for min and max: "unbounded"


def params_config_type(declared: dict, values: dict):
    """A Python controller's declared parameters (mexone.control.Param) as dynamic_reconfigure's
    generated module would describe them, defaulting to their current `values`."""
    from types import SimpleNamespace

    parameters = []
    for key, param in declared.items():
        kind = _DR_TYPES[param.value_type]
        lo = param.low if param.low is not None else -_DR_BOUND
        hi = param.high if param.high is not None else _DR_BOUND
        if kind == "bool":
            lo, hi = False, True
        elif kind == "str":
            lo, hi = "", ""
        elif kind == "int":
            lo, hi = int(max(lo, -2**31)), int(min(hi, 2**31 - 1))
        ctype, cconst = _DR_C[kind]
        parameters.append({"name": key, "type": kind, "default": values.get(key, param.default),
                           "level": 1, "description": param.doc or key, "min": lo, "max": hi,
                           "srcline": 0, "srcfile": "mexone", "edit_method": "",
                           "ctype": ctype, "cconsttype": cconst})
    description = {"name": "Default", "type": "", "state": True, "cstate": "true", "id": 0,
                   "parent": 0, "parameters": parameters, "groups": [], "srcline": 0,
                   "srcfile": "mexone", "class": "DEFAULT", "parentclass": "",
                   "parentname": "Default", "field": "default", "upper": "DEFAULT", "lower": "groups"}
    return SimpleNamespace(
        config_description=description, defaults={p["name"]: p["default"] for p in parameters},
        min={p["name"]: p["min"] for p in parameters}, max={p["name"]: p["max"] for p in parameters},
        level={p["name"]: 1 for p in parameters}, type={p["name"]: p["type"] for p in parameters},
        all_level=1)


def _text(exc: BaseException) -> str:
    return exc.one_line() if isinstance(exc, MexoneError) else str(exc) or type(exc).__name__
