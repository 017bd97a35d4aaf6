"""gazebo_ros' services and topics with gazebo_msgs' definitions, under /gazebo (or the
simulator's --name): pause, unpause, resets, model and link states, wrenches and joint efforts
for a duration of sim time, world/model/physics properties, set_model_configuration, spawning
URDF and SDF models and deleting them; /gazebo/model_states and /gazebo/link_states while someone
subscribes.

Names as Gazebo takes them: a model is the robot's name or a spawned model's; a link is
"model::link" or just "link" when that is unique. Bad requests answer success=False with a
status_message, as gazebo_ros does; the handlers never let an exception reach rospy."""

from __future__ import annotations

import contextlib
import logging
import math
import tempfile
import threading
from collections.abc import Callable
from pathlib import Path

import mujoco
import numpy as np

from mexone.errors import InputError, MexoneError
from mexone.physics.compile import Spawn
from mexone.ranges import FORCE, GRAVITY, JOINT_VALUE, RTF, TIMESTEP, number_text
from mexone.ros1 import checks, convert

__all__ = ["GazeboNode", "STATES_RATE"]

log = logging.getLogger("mexone.ros")
STATES_RATE = 100.0  # Hz of sim time for model_states and link_states (only while subscribed)
GROUND = "ground_plane"
_WORLD = ("", "world", "map", "/map")


class GazeboNode:
    def __init__(self, bridge):
        from gazebo_msgs import srv
        from gazebo_msgs.msg import LinkStates, ModelStates
        from std_srvs.srv import Empty

        self.bridge, self.rospy = bridge, bridge.rospy
        rospy, ns = self.rospy, bridge.gazebo_ns
        self.managers: dict = {}  # spawned robot -> its ControllerManager (simulation thread)
        self.nodes: dict = {}  # spawned robot -> its ControllerManagerNode (services)
        self._state_types = (LinkStates, ModelStates)
        table: list[tuple[str, type, Callable]] = [
            ("pause_physics", Empty, self._empty(lambda: self.lab.sim.pause())),
            ("unpause_physics", Empty, self._empty(lambda: self.lab.sim.resume())),
            ("reset_simulation", Empty, self._empty(lambda: self.lab.sim.reset())),
            ("reset_world", Empty, self._empty(lambda: self.lab.sim.reset())),
            ("get_model_state", srv.GetModelState, self._get_model_state),
            ("set_model_state", srv.SetModelState, self._set_model_state),
            ("get_link_state", srv.GetLinkState, self._get_link_state),
            ("set_link_state", srv.SetLinkState, self._set_link_state),
            ("apply_body_wrench", srv.ApplyBodyWrench, self._apply_body_wrench),
            ("clear_body_wrenches", srv.BodyRequest, self._clear_body_wrenches),
            ("apply_joint_effort", srv.ApplyJointEffort, self._apply_joint_effort),
            ("clear_joint_forces", srv.JointRequest, self._clear_joint_forces),
            ("get_world_properties", srv.GetWorldProperties, self._world_properties),
            ("get_model_properties", srv.GetModelProperties, self._model_properties),
            ("get_physics_properties", srv.GetPhysicsProperties, self._get_physics),
            ("set_physics_properties", srv.SetPhysicsProperties, self._set_physics),
            ("set_model_configuration", srv.SetModelConfiguration, self._set_configuration),
            ("spawn_urdf_model", srv.SpawnModel, self._spawn(".urdf")),
            ("spawn_sdf_model", srv.SpawnModel, self._spawn(".sdf")),
            ("delete_model", srv.DeleteModel, self._delete_model),
        ]
        self.services = [rospy.Service(f"{ns}/{name}", kind, handler) for name, kind, handler in table]

    @property
    def lab(self):
        """The bridge's lab, once attached (a call that comes earlier waits for it)."""
        if self.bridge.lab is None:
            self.bridge.call(lambda: None)  # waits for attach(), or raises TimeoutError
        return self.bridge.lab

    def attach(self) -> None:
        """The lab is there: the state topics (their publishers feed on the simulation)."""
        ns = self.bridge.gazebo_ns
        link_states, model_states = self._state_types
        self.model_states = _Lazy(self, f"{ns}/model_states", model_states, self._model_states)
        self.link_states = _Lazy(self, f"{ns}/link_states", link_states, self._link_states)

    # ----- helpers ------------------------------------------------------------------------------
    def _empty(self, action: Callable[[], None]):
        from std_srvs.srv import EmptyResponse

        def handler(_req):
            try:
                self.bridge.call(action)
            except Exception as exc:  # noqa: BLE001 - logged, never a crash
                log.error("%s", _text(exc))
            return EmptyResponse()
        return handler

    def _answer(self, response_cls, fn: Callable[[], dict | None], quiet: bool = False,
                **failure) -> object:
        """Run `fn` in the simulation thread: its dict fills the response (success=True); an
        error is success=False with the reason, also on /rosout. Nothing a request carries
        may raise past here (rospy would only say "service cannot process request")."""
        try:
            fields = self.bridge.call(fn) or {}
        except Exception as exc:  # noqa: BLE001 - every refusal is an answer, never a crash
            text = _text(exc)
            if not quiet:  # (the caller says it)
                log.warning("%s/%s: %s", self.bridge.gazebo_ns, _service_name(response_cls), text)
            return response_cls(success=False, status_message=text, **failure)
        return response_cls(success=True, status_message=fields.pop("status_message", "ok"),
                            **fields)

    def _noted(self, service: str, detail: str = "", undo: Callable[[], None] | None = None) -> None:
        """Tell the simulation an outside input changed it (simulation thread): a divergence
        soon after names it and is undone instead of ending the run."""
        self.lab.sim.note_input(f"{self.bridge.gazebo_ns}/{service}"
                                + (f" ({detail})" if detail else ""), undo)

    def _models(self) -> dict[str, str]:
        """Model name -> the MuJoCo name of its root body (the robot's first)."""
        sim = self.lab.sim
        return {sim.robot.name: sim.robot.base_link, **sim.models}

    def _link(self, name: str) -> str:
        """A Gazebo link name ("model::link" or "link") as the simulation names its body."""
        sim = self.lab.sim
        model, sep, link = name.rpartition("::")
        if sep:
            if model == sim.robot.name:
                return link
            if model in sim.models:
                return f"{model}/{link}"
            raise MexoneError(f"no model named '{model}'", hint="models: " + ", ".join(self._models()))
        if name in sim.compiled.bodies:
            return name
        for model in sim.models:
            if mujoco.mj_name2id(sim.model, mujoco.mjtObj.mjOBJ_BODY, f"{model}/{name}") > 0:
                return f"{model}/{name}"
        raise MexoneError(f"no link named '{name}'",
                          hint="links: " + ", ".join(self._link_names()[:8]) + ", ...")

    def _model_root(self, name: str) -> str:
        models = self._models()
        if name not in models:
            raise MexoneError(f"no model named '{name}'", hint="models: " + ", ".join(models))
        return models[name]

    def _link_names(self) -> list[str]:
        sim = self.lab.sim
        names = [f"{sim.robot.name}::{link}" for link in sim.compiled.bodies]
        for model in sim.models:
            prefix = f"{model}/"
            names += [f"{model}::{sim.model.body(b).name[len(prefix):]}" for b in range(sim.model.nbody)
                      if sim.model.body(b).name.startswith(prefix)]
        return names

    def _relative(self, body: str, reference: str) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                             np.ndarray]:
        """Pose (position, w-x-y-z quaternion) and twist of `body` in `reference`'s frame."""
        sim = self.lab.sim
        pos, quat = sim.link_pose(body)
        lin, ang = sim.link_velocity(body)
        if reference in _WORLD:
            return pos, quat, lin, ang
        ref = self._link(reference) if reference not in self._models() else self._model_root(reference)
        rpos, rquat = sim.link_pose(ref)
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, rquat)
        rot = rot.reshape(3, 3)
        inverse = np.array([rquat[0], -rquat[1], -rquat[2], -rquat[3]])
        out = np.zeros(4)
        mujoco.mju_mulQuat(out, inverse, quat)
        rlin, rang = sim.link_velocity(ref)
        return rot.T @ (pos - rpos), out, rot.T @ (lin - rlin), rot.T @ (ang - rang)

    # ----- states -------------------------------------------------------------------------------
    def _get_model_state(self, req):
        from gazebo_msgs.srv import GetModelStateResponse

        def get():
            root = self._model_root(req.model_name)
            pos, quat, lin, ang = self._relative(root, req.relative_entity_name)
            resp = {"pose": _pose(pos, quat), "twist": _twist(lin, ang)}
            header = GetModelStateResponse().header
            header.stamp = convert.ros_time(self.lab.sim.time_ns)
            header.frame_id = req.relative_entity_name or "world"
            return resp | {"header": header}
        return self._answer(GetModelStateResponse, get)

    def _set_model_state(self, req):
        from gazebo_msgs.srv import SetModelStateResponse

        state = req.model_state
        return self._answer(SetModelStateResponse, lambda: self._place(
            self._model_root(state.model_name), state.pose, state.twist, state.reference_frame,
            "set_model_state", state.model_name))

    def _place(self, body: str, pose, twist, reference: str, service: str, name: str) -> None:
        if reference not in _WORLD:
            raise MexoneError(f"reference_frame '{reference}': only the world frame is supported "
                              "for setting states", hint="leave it empty or 'world'")
        position = checks.position(pose.position, "pose.position")
        quat = checks.quaternion(pose.orientation, "pose.orientation", zero_is_identity=False)
        linear, angular = checks.twist(twist, "twist")
        self.lab.sim.set_free_body(body, position, quat, linear, angular)
        self._noted(service, name)

    def _get_link_state(self, req):
        from gazebo_msgs.msg import LinkState
        from gazebo_msgs.srv import GetLinkStateResponse

        def get():
            pos, quat, lin, ang = self._relative(self._link(req.link_name), req.reference_frame)
            return {"link_state": LinkState(req.link_name, _pose(pos, quat), _twist(lin, ang),
                                            req.reference_frame)}
        return self._answer(GetLinkStateResponse, get)

    def _set_link_state(self, req):
        from gazebo_msgs.srv import SetLinkStateResponse

        state = req.link_state

        def put():
            body = self._link(state.link_name)
            if body not in self._models().values():
                raise MexoneError(f"link '{state.link_name}' hangs on a joint; only a model's "
                                  "floating root link can be placed",
                                  hint="set joints with set_model_configuration")
            self._place(body, state.pose, state.twist, state.reference_frame, "set_link_state",
                        state.link_name)
        return self._answer(SetLinkStateResponse, put)

    # ----- forces -------------------------------------------------------------------------------
    def _timing(self, start_time, duration) -> tuple[float | None, float | None]:
        start = start_time.to_sec()
        length = duration.to_sec()
        return (start if start > 0 else None), (None if length < 0 else length)

    def _apply_body_wrench(self, req):
        from gazebo_msgs.srv import ApplyBodyWrenchResponse

        def push():
            sim = self.lab.sim
            body = self._link(req.body_name)
            frame = req.reference_frame
            frame = "world" if frame in _WORLD else self._link(frame)
            force = checks.force(req.wrench.force, "wrench.force")
            torque = checks.force(req.wrench.torque, "wrench.torque")
            offset = checks.offset(req.reference_point, "reference_point")
            point = None
            if offset.any():  # from the pushed link's origin, in the frame's axes
                point = sim.link_pose(body)[0] + offset if frame == "world" else offset
            start, length = self._timing(req.start_time, req.duration)
            sim.apply_wrench(body, force, torque, point, frame, length, start)
            self._noted("apply_body_wrench", f"{req.body_name}: force "
                        + " ".join(number_text(v) for v in force) + ", torque "
                        + " ".join(number_text(v) for v in torque))
        return self._answer(ApplyBodyWrenchResponse, push)

    def _clear_body_wrenches(self, req):
        from gazebo_msgs.srv import BodyRequestResponse

        try:
            self.bridge.call(lambda: self.lab.sim.clear_wrenches(self._link(req.body_name)))
        except Exception as exc:  # noqa: BLE001 - logged, never a crash
            log.error("clear_body_wrenches: %s", _text(exc))
        return BodyRequestResponse()

    def _apply_joint_effort(self, req):
        from gazebo_msgs.srv import ApplyJointEffortResponse

        def push():
            effort = FORCE.check(req.effort, "effort")
            start, length = self._timing(req.start_time, req.duration)
            self.lab.sim.apply_joint_effort(req.joint_name, effort, length, start)
            self._noted("apply_joint_effort", f"{req.joint_name} {number_text(effort)}")
        return self._answer(ApplyJointEffortResponse, push)

    def _clear_joint_forces(self, req):
        from gazebo_msgs.srv import JointRequestResponse

        try:
            self.bridge.call(lambda: self.lab.sim.clear_joint_efforts(req.joint_name))
        except Exception as exc:  # noqa: BLE001 - logged, never a crash
            log.error("clear_joint_forces: %s", _text(exc))
        return JointRequestResponse()

    # ----- properties ---------------------------------------------------------------------------
    def _world_properties(self, _req):
        from gazebo_msgs.srv import GetWorldPropertiesResponse

        sim = self.lab.sim
        return self._answer(GetWorldPropertiesResponse, lambda: {
            "sim_time": sim.time, "model_names": [GROUND, *self._models()],
            "rendering_enabled": False})

    def _model_properties(self, req):
        from gazebo_msgs.srv import GetModelPropertiesResponse

        def get():
            sim = self.lab.sim
            if req.model_name == GROUND:
                return {"canonical_body_name": "link", "body_names": ["link"],
                        "geom_names": ["collision"], "is_static": True}
            root = self._model_root(req.model_name)
            if req.model_name == sim.robot.name:
                robot = sim.robot
                geoms = [f"{link}/collision/{i}" for link in sim.compiled.bodies
                         for i in range(len(robot.links[link].collisions))]
                return {"canonical_body_name": robot.base_link, "body_names": list(sim.compiled.bodies),
                        "geom_names": geoms, "joint_names": list(sim.joint_names),
                        "is_static": not sim.compiled.free}
            prefix = f"{req.model_name}/"
            bodies = [sim.model.body(b).name for b in range(sim.model.nbody)
                      if sim.model.body(b).name.startswith(prefix)]
            geoms = [sim.model.geom(g).name for g in range(sim.model.ngeom)
                     if sim.model.geom(g).name.startswith(prefix)]
            return {"canonical_body_name": root[len(prefix):],
                    "body_names": [b[len(prefix):] for b in bodies],
                    "geom_names": [g[len(prefix):] for g in geoms], "is_static": False}
        return self._answer(GetModelPropertiesResponse, get)

    def _get_physics(self, _req):
        from gazebo_msgs.msg import ODEPhysics
        from gazebo_msgs.srv import GetPhysicsPropertiesResponse

        def get():
            sim = self.lab.sim
            rtf = sim.target_rtf or 0.0
            g = sim.gravity
            return {"time_step": sim.timestep, "pause": sim.paused,
                    "max_update_rate": rtf / sim.timestep if rtf else 0.0,
                    "gravity": _vector(g),
                    "ode_config": ODEPhysics(sor_pgs_iters=int(sim.model.opt.iterations),
                                             sor_pgs_w=1.3, max_contacts=20)}
        return self._answer(GetPhysicsPropertiesResponse, get)

    def _set_physics(self, req):
        """time_step, max_update_rate (0: as fast as possible), gravity and the solver's
        iterations (ode_config.sor_pgs_iters); ODE's other knobs have no MuJoCo meaning."""
        from gazebo_msgs.srv import SetPhysicsPropertiesResponse

        def put():  # every field is checked before anything changes
            sim = self.lab.sim
            step = TIMESTEP.check(req.time_step, "time_step")
            rate = float(req.max_update_rate)
            if not (math.isfinite(rate) and rate >= 0):
                raise InputError(f"max_update_rate {number_text(rate)} must be a finite number "
                                 ">= 0 (0: as fast as possible)")
            rtf = RTF.check(rate * step, "max_update_rate x time_step (the real-time factor)")
            gravity = checks.vector(req.gravity, GRAVITY, "gravity")
            iterations = int(req.ode_config.sor_pgs_iters)
            before = (sim.gravity, sim.timestep, sim.target_rtf, int(sim.model.opt.iterations))

            def undo() -> None:
                sim.set_gravity(before[0])
                sim.set_timestep(before[1])
                sim.target_rtf = before[2]
                sim.model.opt.iterations = before[3]

            sim.set_gravity(gravity)
            sim.set_timestep(step)
            sim.target_rtf = rtf if rate > 0 else None
            if not sim.paused:
                sim.resume()  # pacing restarts from now, at the new rate
            if iterations > 0:
                sim.model.opt.iterations = min(iterations, 1000)
            self._noted("set_physics_properties", f"time_step {number_text(step)}, gravity "
                        + " ".join(number_text(v) for v in gravity), undo)
        return self._answer(SetPhysicsPropertiesResponse, put)

    def _set_configuration(self, req):
        from gazebo_msgs.srv import SetModelConfigurationResponse

        def put():
            sim = self.lab.sim
            self._model_root(req.model_name)
            if req.model_name != sim.robot.name:
                raise MexoneError(f"'{req.model_name}' has no joints to set")
            if len(req.joint_names) != len(req.joint_positions):
                raise MexoneError(f"{len(req.joint_names)} joint names but "
                                  f"{len(req.joint_positions)} positions")
            names = checks.names(req.joint_names, "joint_names")
            unknown = [n for n in names if n not in sim.joint_names]
            if unknown:
                raise InputError(f"no moving joint named {', '.join(unknown)}",
                                 hint="joints: " + ", ".join(sim.joint_names))
            asked = {n: JOINT_VALUE.check(v, f"{n} position")
                     for n, v in zip(names, req.joint_positions, strict=True)}
            # beyond a limit: clamped with a warning (docs/DECISIONS.md), as the controllers'
            # commands are; a teleport past it would be flung back faster than physics allows
            values, clamped = sim.within_limits(asked)
            sim.set_joint_positions(values)
            if self.lab.manager is not None:
                self.lab.manager.hold(values)  # they hold the new pose, not the old setpoint
            self._noted("set_model_configuration",
                        ", ".join(f"{n} {number_text(v)}" for n, v in values.items()))
            if not clamped:
                return None
            text = "clamped to the joint limits: " + ", ".join(clamped)
            log.warning("%s/set_model_configuration: %s", self.bridge.gazebo_ns, text)
            return {"status_message": f"SetModelConfiguration: {text}"}
        return self._answer(SetModelConfigurationResponse, put)

    # ----- models -------------------------------------------------------------------------------
    def _spawn(self, suffix: str):

        def handler(req):
            with tempfile.TemporaryDirectory() as tmp:  # alive until the model has compiled
                path = Path(tmp) / f"model{suffix}"
                answer = self._spawn_from(req, path)
            # the file is ours, not the caller's: name what they sent
            answer.status_message = answer.status_message.replace(str(path), "model_xml")
            if not answer.success:
                log.warning("%s/spawn_%s_model: %s", self.bridge.gazebo_ns, suffix[1:],
                            answer.status_message)
            return answer
        return handler

    def _spawn_from(self, req, path: Path):
        from gazebo_msgs.srv import SpawnModelResponse

        name = req.model_name.strip()
        if not name or "/" in name or "::" in name:
            return SpawnModelResponse(False, f"model_name '{req.model_name}' must be a plain "
                                             "non-empty name")
        if req.reference_frame not in _WORLD:
            return SpawnModelResponse(False, "only the world reference_frame is supported")
        try:
            position = checks.position(req.initial_pose.position, "initial_pose.position")
            quat = checks.quaternion(req.initial_pose.orientation, "initial_pose.orientation")
        except InputError as exc:
            return SpawnModelResponse(False, _text(exc))
        spawn = Spawn(tuple(position), _rpy(quat), on_ground=False)
        try:
            robot = _load_text(req.model_xml, path)
        except Exception as exc:  # noqa: BLE001 - whatever the text holds: an answer, never a crash
            return SpawnModelResponse(False, f"cannot read the model: {_text(exc)}")
        if not robot.transmissions:
            def add():
                self.lab.sim.add_model(robot, name, spawn)
                self._noted("spawn_model", name, lambda: self.lab.sim.remove_model(name))
                return {"status_message": "SpawnModel: Successfully spawned entity"}
            return self._answer(SpawnModelResponse, add, quiet=True)
        return self._spawn_robot(req, robot, name, spawn)

    def _spawn_robot(self, req, robot, name: str, spawn: Spawn):
        """A robot with transmissions gets what gazebo_ros_control gives it: a controller manager
        in its namespace (spawn_model's -robot_namespace, else its URDF's, else its name) with
        the controllers on the parameter server there, loaded stopped for the spawner."""
        from gazebo_msgs.srv import SpawnModelResponse
        from rosgraph.names import is_legal_name

        from mexone.control.hardware import SimHardware, build_actuators
        from mexone.control.manager import ControllerManager
        from mexone.lab import robot_namespace
        from mexone.ros1.controller_manager import ControllerManagerNode
        from mexone.ros1.params import controllers_at

        ns = robot_namespace(robot, None, req.robot_namespace, name)  # its YAML is found there
        if not is_legal_name(ns):
            return SpawnModelResponse(False, f"robot_namespace '{req.robot_namespace}' is not a ROS "
                                             "name (letters, digits, _ and /)")
        taken = {self.lab.namespace} | {m.namespace for m in self.managers.values()}
        if ns in taken:
            return SpawnModelResponse(False, f"robot_namespace {ns} is taken by another robot: "
                                             "spawn it with another -robot_namespace")
        try:
            config = controllers_at(self.rospy, ns)
        except MexoneError as exc:
            return SpawnModelResponse(False, f"controllers at {ns}: {_text(exc)}")

        def add():
            sim = self.lab.sim
            sim.add_model(robot, name, spawn, edits=[build_actuators])
            try:
                self.managers[name] = ControllerManager(sim, self.lab.bus, config,
                                                        SimHardware(sim, robot, f"{name}/"), ns)
            except MexoneError:
                sim.remove_model(name)
                raise
            self._noted("spawn_model", name, lambda: self._undo_spawn(name))
            return {"status_message": f"SpawnModel: Successfully spawned entity (controller "
                                      f"manager at {ns}/controller_manager)"}
        answer = self._answer(SpawnModelResponse, add, quiet=True)
        if answer.success:
            try:
                self.nodes[name] = ControllerManagerNode(self.bridge, self.managers[name], ns)
            except Exception as exc:  # noqa: BLE001 - no services, no robot: taken back
                with contextlib.suppress(Exception):  # the answer below says what went wrong
                    self.bridge.call(lambda: self._undo_spawn(name))
                return SpawnModelResponse(False, f"controller manager at {ns}: {_text(exc)}")
        return answer

    def _undo_spawn(self, name: str) -> None:
        """A spawned robot that made the physics diverge is deleted again (simulation thread)."""
        manager = self.managers.pop(name, None)
        if manager is not None:
            manager.close()
        self.lab.sim.remove_model(name)
        node = self.nodes.pop(name, None)
        if node is not None:
            threading.Thread(target=node.shutdown, daemon=True).start()  # rospy, not the physics

    def _delete_model(self, req):
        from gazebo_msgs.srv import DeleteModelResponse

        def delete():
            manager = self.managers.pop(req.model_name, None)
            if manager is not None:  # its controllers stop before its joints go
                manager.close()
            self.lab.sim.remove_model(req.model_name)
            return {"status_message": f"DeleteModel: successfully deleted model {req.model_name}"}
        answer = self._answer(DeleteModelResponse, delete)
        node = self.nodes.pop(req.model_name, None)
        if node is not None:
            node.shutdown()
        return answer

    # ----- topics -------------------------------------------------------------------------------
    def _model_states(self, cls):
        sim = self.lab.sim
        msg = cls(name=[GROUND], pose=[_pose(np.zeros(3), np.array([1.0, 0, 0, 0]))],
                  twist=[_twist(np.zeros(3), np.zeros(3))])
        for name, root in self._models().items():
            pos, quat = sim.link_pose(root)
            lin, ang = sim.link_velocity(root)
            msg.name.append(name)
            msg.pose.append(_pose(pos, quat))
            msg.twist.append(_twist(lin, ang))
        return msg

    def _link_states(self, cls):
        sim = self.lab.sim
        msg = cls()
        for name in self._link_names():
            body = self._link(name)
            pos, quat = sim.link_pose(body)
            lin, ang = sim.link_velocity(body)
            msg.name.append(name)
            msg.pose.append(_pose(pos, quat))
            msg.twist.append(_twist(lin, ang))
        return msg


class _Lazy:
    """A topic built by the simulation thread at STATES_RATE while ROS nodes subscribe."""

    def __init__(self, node: GazeboNode, topic: str, cls: type, build: Callable):
        self.node, self.cls, self.build, self.timer = node, cls, build, None
        listener = type("Listener", (), {
            "peer_subscribe": lambda _s, *a: node.lab.sim.work.put(self.start),
            "peer_unsubscribe": lambda _s, _t, n: n or node.lab.sim.work.put(self.stop)})()
        self.publisher = node.rospy.Publisher(topic, cls, queue_size=10, subscriber_listener=listener)

    def start(self) -> None:
        if self.timer is None:
            self.timer = self.node.lab.sim.add_periodic(1.0 / STATES_RATE, self.publish)

    def stop(self) -> None:
        if self.timer is not None and self.publisher.get_num_connections() == 0:
            self.node.lab.sim.remove_periodic(self.timer)
            self.timer = None

    def publish(self, _sim) -> None:
        self.publisher.publish(self.build(self.cls))


def _pose(pos: np.ndarray, quat: np.ndarray):
    from geometry_msgs.msg import Point, Pose, Quaternion

    return Pose(Point(*map(float, pos)), Quaternion(float(quat[1]), float(quat[2]), float(quat[3]),
                                                    float(quat[0])))


def _twist(lin: np.ndarray, ang: np.ndarray):
    from geometry_msgs.msg import Twist

    return Twist(_vector(lin), _vector(ang))


def _vector(v):
    from geometry_msgs.msg import Vector3

    return Vector3(*map(float, v))


def _rpy(quat: np.ndarray) -> tuple[float, float, float]:
    w, x, y, z = quat
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


def _load_text(xml: str, path: Path):
    """A model from the XML text a spawn request carries (meshes by package:// or absolute)."""
    from mexone.description.loader import load_model

    if not xml.strip():
        raise MexoneError("model_xml is empty")
    path.write_text(xml)
    return load_model(path)


def _service_name(response_cls: type) -> str:
    """SetModelConfigurationResponse -> set_model_configuration."""
    name = response_cls.__name__.removesuffix("Response")
    return "".join(f"_{c.lower()}" if c.isupper() else c for c in name).lstrip("_")


def _text(exc: BaseException) -> str:
    return exc.one_line() if isinstance(exc, MexoneError) else str(exc) or type(exc).__name__
