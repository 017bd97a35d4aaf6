"""ros2_control's controller manager services on ROS 2, under `/controller_manager/` (what
`ros2 control`, the spawner and rqt_controller_manager call), with controller_manager_msgs built
from its official definitions (`python -m mexone.ros2.interfaces`: it has no wheel).

The same manager and semantics as the ROS 1 bridge's services (`mexone.ros1.controller_manager`),
in ros2_control's words: a loaded controller is `inactive` (mexone creates and configures in one
step, so `unconfigured` is never seen), a running one `active`; interfaces are `<joint>/position`,
`<joint>/velocity` and `<joint>/effort`. Every refusal (an unknown controller, a joint two
controllers would claim, an active controller to unload) answers ok=False and says why on
/rosout; the node never falls over. What the manager cannot do is refused the same way:
`cleanup_controller` (no unconfigured state) and `set_hardware_component_state` (the simulated
hardware is always active) are not served; `load_controller` loads what the controllers YAML
configures (not a type set as a parameter).
"""

from __future__ import annotations

import logging

from mexone.control.manager import BEST_EFFORT, STRICT
from mexone.errors import InputError, MexoneError, printable
from mexone.ranges import SWITCH_NAMES, TIMEOUT

__all__ = ["ControllerManagerServices", "SERVICES", "INTERFACES", "command_interface",
           "AUTO", "FORCE_AUTO"]

log = logging.getLogger("mexone.ros2")

AUTO, FORCE_AUTO = 3, 4  # controller_manager_msgs/SwitchController's other strictness levels
INTERFACES = ("position", "velocity", "effort")  # what SimHardware offers for every joint
SERVICES = ("list_controllers", "list_controller_types", "list_hardware_interfaces",
            "list_hardware_components", "load_controller", "configure_controller",
            "switch_controller", "unload_controller", "reload_controller_libraries")
_ROS1_INTERFACES = {"EffortJointInterface": "effort", "PositionJointInterface": "position",
                    "VelocityJointInterface": "velocity"}
_ACTIVE_ID = 3  # lifecycle_msgs/State.PRIMARY_STATE_ACTIVE


def command_interface(interface: str) -> str | None:
    """A controller's hardware interface (ROS 1's name, or a Python controller's own) as
    ros2_control's command interface name; None for a state controller (broadcaster)."""
    return _ROS1_INTERFACES.get(interface, interface if interface in INTERFACES else None)


class ControllerManagerServices:
    """The services on the bridge's node; each handler runs in rclpy's thread and hands the
    manager's work to the simulation thread (`bridge.call`)."""

    def __init__(self, bridge, base: str = "/controller_manager") -> None:
        from controller_manager_msgs import srv

        self.bridge, self.base = bridge, base.rstrip("/")
        self.manager = bridge.lab.manager
        types = {"list_controllers": srv.ListControllers,
                 "list_controller_types": srv.ListControllerTypes,
                 "list_hardware_interfaces": srv.ListHardwareInterfaces,
                 "list_hardware_components": srv.ListHardwareComponents,
                 "load_controller": srv.LoadController,
                 "configure_controller": srv.ConfigureController,
                 "switch_controller": srv.SwitchController,
                 "unload_controller": srv.UnloadController,
                 "reload_controller_libraries": srv.ReloadControllerLibraries}
        self.handles = [bridge.node.create_service(types[name], f"{self.base}/{name}",
                                                   self._guarded(name))
                        for name in SERVICES]

    def _guarded(self, name: str):
        """The handler of service `name`: a refusal (any exception) is ok=False and a warning."""
        handler = getattr(self, f"_{name}")

        def serve(request, response):
            try:
                message = handler(request, response)
                if hasattr(response, "ok"):
                    response.ok = True
                if hasattr(response, "message"):
                    response.message = message or ""
            except Exception as exc:  # noqa: BLE001 - every refusal is ok=False, never a crash
                text = _text(exc)
                log.warning("%s/%s: %s", self.base, name, text)
                if hasattr(response, "ok"):
                    response.ok = False
                if hasattr(response, "message"):
                    response.message = text
            return response
        return serve

    # ----- what the manager holds (simulation thread) --------------------------------------------
    def _snapshot(self) -> list[dict]:
        manager, out = self.manager, []
        rate = min(65535, round(1.0 / manager.control_period))
        for info in manager.list_controllers():
            ctrl = manager.controllers[info.name]
            command = command_interface(info.interface)
            joints = list(info.joints) or (list(manager.hw.joints) if command is None else [])
            commands = [f"{j}/{command}" for j in joints] if command else []
            states = [f"{j}/{i}" for j in joints for i in
                      (INTERFACES if command is None else ("position", "velocity"))]
            out.append({"name": info.name, "state": "active" if ctrl.running else "inactive",
                        "type": info.type, "update_rate": min(65535, round(info.update_rate))
                        if info.update_rate else rate,
                        "claimed": commands if ctrl.running else [], "commands": commands,
                        "states": states})
        return out

    # ----- services (rclpy's thread) -------------------------------------------------------------
    def _list_controllers(self, _request, response) -> None:
        from controller_manager_msgs.msg import ControllerState

        response.controller = [ControllerState(
            name=c["name"], state=c["state"], type=c["type"], is_async=False,
            update_rate=c["update_rate"], claimed_interfaces=c["claimed"],
            required_command_interfaces=c["commands"], required_state_interfaces=c["states"])
            for c in self.bridge.call(self._snapshot)]

    def _list_controller_types(self, _request, response) -> None:
        types = self.manager.list_types()
        response.types = types
        response.base_classes = ["controller_interface::ControllerInterface"] * len(types)

    def _interfaces(self):
        from controller_manager_msgs.msg import HardwareInterface

        def read():
            return list(self.manager.hw.joints), {i for c in self._snapshot() for i in c["claimed"]}
        joints, claimed = self.bridge.call(read)
        commands = [HardwareInterface(name=f"{j}/{i}", data_type="double", is_available=True,
                                      is_claimed=f"{j}/{i}" in claimed)
                    for j in joints for i in INTERFACES]
        states = [HardwareInterface(name=f"{j}/{i}", data_type="double", is_available=True,
                                    is_claimed=False) for j in joints for i in INTERFACES]
        return commands, states

    def _list_hardware_interfaces(self, _request, response) -> None:
        response.command_interfaces, response.state_interfaces = self._interfaces()

    def _list_hardware_components(self, _request, response) -> None:
        from controller_manager_msgs.msg import HardwareComponentState

        commands, states = self._interfaces()
        component = HardwareComponentState(
            name=self.bridge.lab.sim.robot.name, type="system", is_async=False,
            rw_rate=min(65535, round(1.0 / self.bridge.lab.sim.timestep)),
            plugin_name="mexone/SimHardware", command_interfaces=commands,
            state_interfaces=states)
        component.state.id, component.state.label = _ACTIVE_ID, "active"
        response.component = [component]

    def _load_controller(self, request, _response) -> str:
        name = request.name
        self.bridge.call(lambda: self.manager.load(name))
        return f"{printable(name, 80)} loaded (inactive)"

    def _configure_controller(self, request, _response) -> str:
        """ros2_control cleans an inactive controller up and configures it again: here it is
        created afresh from its configuration (an active one is refused, as there)."""
        name = request.name

        def configure() -> None:
            ctrl = self.manager.controllers.get(name)
            if ctrl is None:
                raise InputError(f"no controller named '{name}' is loaded",
                                 hint="load_controller first; loaded: "
                                      + (", ".join(self.manager.controllers) or "none"))
            if ctrl.running:
                raise InputError(f"controller '{name}' is active: it cannot be configured",
                                 hint="deactivate it first (switch_controller)")
            self.manager.unload(name)
            try:
                self.manager.load(name)
            except Exception:
                self.manager.controllers[name] = ctrl  # as it was
                raise
        self.bridge.call(configure)
        return f"{printable(name, 80)} configured (inactive)"

    def _unload_controller(self, request, _response) -> str:
        name = request.name
        self.bridge.call(lambda: self.manager.unload(name))
        return f"{printable(name, 80)} unloaded"

    def _switch_controller(self, request, _response) -> str:
        strictness = request.strictness
        if strictness == 0:  # unset: ros2_control warns and takes BEST_EFFORT
            log.warning("%s/switch_controller: no strictness given (0); using BEST_EFFORT (1), "
                        "as ros2_control does; STRICT is 2", self.base)
            strictness = BEST_EFFORT
        elif strictness not in (BEST_EFFORT, STRICT, AUTO, FORCE_AUTO):
            raise InputError(f"strictness {strictness} must be BEST_EFFORT (1), STRICT (2), "
                             "AUTO (3) or FORCE_AUTO (4)")
        timeout = request.timeout.sec + request.timeout.nanosec * 1e-9
        TIMEOUT.check(timeout, "timeout")
        start = list(request.activate_controllers)
        stop = list(request.deactivate_controllers)
        if not SWITCH_NAMES.contains(len(start) + len(stop)):
            raise InputError(f"switch_controller names {len(start) + len(stop)} controllers: at "
                             f"most {SWITCH_NAMES.high:g} in one request",
                             hint="name the controllers to switch")
        manager = self.manager
        unknown: list[str] = []

        def switch() -> list[str]:
            nonlocal start, stop
            known = set(manager.controllers) | set(manager.config.controllers)
            unknown[:] = [n for n in dict.fromkeys(start + stop) if n not in known]
            if unknown and strictness != STRICT:  # skipped, and said so (ros2_control warns)
                start = [n for n in start if n in known]
                stop = [n for n in stop if n in known]
                if not start and not stop:
                    raise InputError(f"no controller named {_names(unknown)} is loaded or "
                                     "configured: nothing to switch",
                                     hint="loaded: " + ", ".join(manager.controllers))
            extra: list[str] = []
            if strictness == FORCE_AUTO:  # deactivate whatever claims the joints asked for
                wanted = {j for n in start if n in manager.controllers
                          for j in manager.controllers[n].joints}
                extra = [c.name for c in manager.controllers.values()
                         if c.running and c.name not in stop and c.name not in start
                         and wanted & set(c.joints)]
            # AUTO resolves controller chains: mexone has none, so it is STRICT
            manager.switch(start=start, stop=stop + extra,
                           strictness=BEST_EFFORT if strictness == BEST_EFFORT else STRICT)
            manager.sim.note_input(f"{self.base}/switch_controller")
            return extra
        extra = self.bridge.call(switch)
        said = [f"activated {_names(start)}" if start else "",
                f"deactivated {_names(stop + extra)}" if stop or extra else "",
                f"skipped {len(unknown)} unknown: {_names(unknown)}" if unknown else ""]
        if unknown:
            log.warning("%s/switch_controller: skipped %d unknown controller(s): %s (best "
                        "effort)", self.base, len(unknown), _names(unknown))
        return "; ".join(s for s in said if s) or "nothing to switch"

    def _reload_controller_libraries(self, request, _response) -> str:
        """Controller types are Python classes: nothing to reload; ros2_control refuses while
        controllers are loaded unless force_kill, which deactivates and unloads them all."""
        manager = self.manager

        def kill() -> None:
            loaded = list(manager.controllers)
            if loaded and not request.force_kill:
                raise InputError(f"controllers are loaded ({', '.join(loaded)})",
                                 hint="pass force_kill to deactivate and unload them")
            manager.switch(stop=[n for n, c in manager.controllers.items() if c.running])
            for name in loaded:
                manager.unload(name)
        self.bridge.call(kill)
        return "no libraries to reload (controller types are Python classes)"


def _text(exc: BaseException) -> str:
    """A refusal's one line, printable (a request's names are echoed in it: a NUL, a newline or
    100 000 characters stay out of the response and /rosout)."""
    return printable(exc.one_line() if isinstance(exc, MexoneError)
                     else str(exc) or type(exc).__name__, 500)


def _names(names: list[str], shown: int = 5) -> str:
    """Controller names from a request, for a message: the first `shown`, printable."""
    listed = ", ".join(printable(n, 80) for n in names[:shown])
    return listed + (f" (and {len(names) - shown} more)" if len(names) > shown else "")
