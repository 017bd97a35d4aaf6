"""A student's PythonController in a process of its own: the student's side (mexone's side, and
the protocol, are control/worker.py).

`python -m mexone.control.worker_main FRAMES_FD DESCRIPTORS_FD DUMP_FD`, started by
`sandbox.spawn`. Before any student code it arms faulthandler on the dump pipe (a crash, or
mexone's WHERE_SIGNAL, writes the Python stack there), guards the process (`sandbox.guard`:
os._exit, fork, exec, subprocess, kill raise at the student's line), and watches the dump pipe:
when mexone's process ends, so does this one. Then it serves mexone's calls: describe (import
the class), bind (the shared block, the model), create (the object, configure), activate,
update (each `U` frame), deactivate, set_param, report, model, check_entry, quit.

What it sends back is data (frames of numbers in shared memory, JSON text), never a pickle; it
may lie, and mexone checks everything it reads. Its `State` is the lab's class over read-only
shared memory; `self.dynamics` is a `Dynamics` of its private copy of the compiled model.
"""

from __future__ import annotations

import contextlib
import importlib
import inspect
import json
import logging
import mmap
import os
import select
import socket
import sys
import threading
import traceback
from collections.abc import Iterator, Mapping
from pathlib import Path
from types import FrameType, SimpleNamespace
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from mexone.control import watchdog
from mexone.control.mistakes import StudentLog, not_numbers, return_lines, wrong_count
from mexone.control.resolve import Found, Plugin, _import_failure, load_class, student_line
from mexone.control.student import Exports, PythonController, State, declared_topics, strided_view
from mexone.control.worker import (
    CALL,
    DONE,
    FILLED,
    KEPT,
    LOG,
    MESSAGES,
    PARAMS,
    POOL_IDLE,
    REPLY,
    SENSOR,
    THREAD_FAULT,
    UPDATE,
    UPDATE_FAULT,
    Layout,
    message_from,
)
from mexone.errors import MexoneError
from mexone.sandbox import ended, guard
from mexone.sandbox.wire import Channel, frame

if TYPE_CHECKING:
    from collections.abc import Callable

    from mexone.dynamics import Dynamics


def main(argv: list[str]) -> None:
    sock_fd, descriptors_fd, dump_fd = (int(a) for a in argv[:3])
    ended.dump_to(dump_fd)
    threading.Thread(target=_die_with_mexone, args=(dump_fd,), daemon=True,
                     name="mexone lifeline").start()
    guard.install("a controller")
    try:
        host = _Host(sock_fd, descriptors_fd)
        host.serve()
    except BaseException:  # noqa: BLE001 - mexone's side says what happened; never a traceback here
        guard.real_exit(70)
    guard.real_exit(0)


def _die_with_mexone(fd: int) -> None:
    """End this process when mexone's ends (the dump pipe's reader closes: POLLERR)."""
    poll = select.poll()
    poll.register(fd, select.POLLERR)
    while True:
        with contextlib.suppress(InterruptedError):
            if poll.poll():
                guard.real_exit(0)


class _Quit(Exception):
    pass


class _Host:
    """The worker: its channel, the student's class and object, and the state it reads."""

    DONE_HEAD, KEPT_HEAD = frame(DONE, bytes(8))[:5], frame(KEPT, bytes(8))[:5]

    def __init__(self, sock_fd: int, descriptors_fd: int):
        watchdog.STUDENT_SETUP_TIMEOUT = 1e9  # mexone's side times the student (and ends us)
        self.chan = Channel(socket.socket(fileno=sock_fd), socket.socket(fileno=descriptors_fd),
                            max_frame=1 << 28, student=True)  # mexone's frames (a camera image)
        self.chan.introduce()
        self.lock = threading.Lock()  # a thread of the student's logs or faults too
        self.cls: type[PythonController] | None = None
        self.impl: PythonController | None = None
        self.file = ""
        self.updates = 0
        self.pid = os.getpid()
        self.kinds = {UPDATE: self.update, CALL: self.request, MESSAGES: self.take_messages}
        self.topics: tuple[str, ...] = ()  # the class's declared topics
        self.inbox: dict[str, Any] = {}  # the messages for the next update
        self.sent_params: dict[str, Any] = {}
        self._dyn: Dynamics | None = None
        self._dyn_at = -1
        self.model: Any = None  # mujoco.MjModel (mujoco has no type information)
        self._model_fd: int | None = None
        self._model_size = 0
        self.source: Any = None  # mujoco.MjData
        self.links: dict[str, int] = {}
        self.bodies: list[int] = []
        self.layout: Layout | None = None
        self.state: State | None = None
        self.exports = Exports()
        # what a deployed design (mexone.design's Observer, StateFeedback) reads of its binding
        # in the lab's process, here: the YAML's rate and folder, the model and this update's data
        self.plugin = SimpleNamespace(update_rate=None, yaml_dir=None)
        self.ctx = SimpleNamespace(sim=_SimView(self))
        self.traced = False
        self._frame: FrameType | None = None
        self._reply(REPLY, {"seq": 0, "ok": {"thread": threading.get_ident(), "pid": self.pid}})
        threading.excepthook = self._thread_raised

    # ----- the loop -------------------------------------------------------------------------------
    def serve(self) -> None:
        while True:
            idle = POOL_IDLE if self.impl is None else None  # described, never claimed: end
            frame = self.chan.receive(idle)
            if frame is None:
                return
            kind, payload = frame
            handler = self.kinds.get(kind)
            if handler is None:
                return
            try:
                handler(payload)
            except _Quit:
                return

    def send(self, kind: bytes, obj: object) -> None:
        data = json.dumps(obj, separators=(",", ":"), default=_plain)
        with self.lock:
            self.chan.send(kind, data.encode())

    def _reply(self, kind: bytes, obj: object) -> None:
        self.send(kind, obj)

    def request(self, payload: bytes) -> None:
        request = json.loads(payload)
        call = request.get("call")
        method = getattr(self, f"do_{call}", None)
        if method is None:
            raise _Quit
        try:
            answer = {"ok": method(request)}
        except _Fault as exc:
            answer = {"fault": str(exc)}
        except MexoneError as exc:
            answer = {"input_error": {"what": exc.what if exc.file is None else exc.one_line(),
                                      "hint": None if exc.file is not None else exc.hint,
                                      "line": exc.line if exc.file is None else None}}
        self._reply(REPLY, dict(answer, seq=request.get("seq")))
        if call == "quit":
            raise _Quit
        self._params_changed()

    # ----- describe: import the class ---------------------------------------------------------------
    def do_describe(self, request: dict[str, Any]) -> dict[str, Any]:
        path = [str(p) for p in request["path"]]
        sys.path[:] = path + [p for p in sys.path if p not in path]
        yaml_dir = Path(request["yaml_dir"]) if request["yaml_dir"] else None
        self.plugin.yaml_dir = yaml_dir
        ctype = str(request["type"])
        found = Found(*(str(v) for v in request["found"]))
        try:
            cls, origin = load_class(ctype, found, yaml_dir)
        except MexoneError:
            raise
        except BaseException as exc:  # noqa: BLE001 - a KeyboardInterrupt the module raised
            raise _import_failure(exc, None, ctype) from None
        self.cls = cls
        info = self.describe(cls, origin)
        self.watch_threads()
        return info

    def describe(self, cls: type[PythonController], origin: str) -> dict[str, Any]:
        self.file = Plugin("", cls, origin, None).file
        params = {}
        for name, p in cls.declared_params().items():
            params[name] = {"kind": p.value_type.__name__, "default": p.default, "low": p.low,
                            "high": p.high, "doc": str(p.doc), "unit": str(p.unit),
                            "choices": list(p.choices) if p.choices else None}
        try:
            line = inspect.getsourcelines(cls.update)[1]
        except (OSError, TypeError):
            line = None
        self.returns = return_lines(cls.update)
        # a classmethod read on its class is a bound method (mypy: a plain callable, no __func__)
        checks = getattr(cls.check_entry, "__func__", None) is not \
            PythonController.check_entry.__func__  # type: ignore[attr-defined]
        return {"name": cls.__name__, "file": self.file, "origin": origin,
                "command_interface": cls.command_interface, "params": params,
                "update_line": line, "report": callable(getattr(cls, "report", None)),
                "check_entry": checks, "exports": dict(getattr(cls, "exports", {}) or {}),
                "inputs": dict(getattr(cls, "inputs", {}) or {}), "topics": self.declare_topics(cls)}

    def declare_topics(self, cls: type[PythonController]) -> dict[str, str]:
        """The class's topics as names of mexone.bus.msgs classes (all a worker is sent)."""
        from mexone.bus import msgs

        out = {}
        for name, kind in declared_topics(cls).items():
            if getattr(msgs, kind.__name__, None) is not kind or kind.__name__ not in msgs.__all__:
                raise MexoneError(f"{cls.__name__}.topics['{name}']: {kind.__name__} is not a "
                                  "message class of mexone.bus.msgs",
                                  hint="a controller in its own process takes mexone.bus.msgs "
                                       "messages: docs/controllers.md, Topics")
            out[name] = kind.__name__
        self.topics = tuple(out)
        return out

    def take_messages(self, payload: bytes) -> None:
        """The messages that arrived since the last update (mexone's, rebuilt here)."""
        self.inbox = {str(k): message_from(v) for k, v in json.loads(payload).items()}

    def do_check_entry(self, request: dict[str, Any]) -> None:
        p = request["plugin"]
        cls = cast("type[PythonController]", self.cls)  # set by describe, mexone's first call
        plugin = Plugin(p["type"], cls, self.file, None,
                        {k: (v, p["lines"].get(k)) for k, v in p["raw"].items()}, p["params"],
                        update_rate=p["update_rate"], source=Path(p["source"]) if p["source"] else None,
                        line=p["line"], lines=p["lines"])
        try:  # an InputError is the class's finding (at the YAML's line): said as it is
            cls.check_entry(request["name"], tuple(request["joints"]), plugin,
                            float(request["timestep"]))
        except MexoneError:
            raise
        except BaseException as exc:  # noqa: BLE001 - the student's, said in one line
            raise _Fault(f"check_entry raised {self.where(exc)}") from None

    # ----- create: the object, its state, its model ---------------------------------------------------
    def do_bind(self, request: dict[str, Any]) -> None:
        """mexone's own setup, before any student code: the shared block, the model, the state
        (a rebind after the model changed: the same, the object's dofs updated)."""
        self.attach(request)
        assert self.layout is not None  # attach() has just set it
        if self.state is None:
            self.state = State(self.layout.n, None, None, None)
        if self.impl is not None:
            self.impl.dofs = np.asarray(request["dofs"], dtype=int)
        self.bind_state(request)

    def do_create(self, request: dict[str, Any]) -> dict[str, Any]:
        self.name = str(request["name"])
        impl = self.student("creating", cast("type[PythonController]", self.cls))  # set by describe
        impl.name, impl.joints = self.name, list(request["joints"])
        impl.dofs = np.asarray(request["dofs"], dtype=int)
        impl.effort_limits = np.asarray(request["effort_limits"], dtype=float)
        impl.params = dict(request["params"])
        self.plugin.update_rate = request.get("update_rate")
        logger = logging.getLogger("mexone.control.student")
        logger.setLevel(logging.DEBUG)
        logger.propagate = False
        logger.handlers[:] = [_ToMexone(self)]
        impl.log = StudentLog(logger, {"name": self.name})
        impl.exports = self.exports
        impl.__dict__["_mexone_binding"] = self
        self.impl = impl
        self.update_fn = impl.update
        self.traced = len(self.returns) > 1
        assert self.layout is not None  # mexone's side binds before it creates
        self.shape = (self.layout.n,)
        self.student("configure", impl.configure)
        self.sent_params = dict(impl.params) if isinstance(impl.params, dict) else {}
        return self.sent_params

    def attach(self, request: dict[str, Any]) -> None:
        """Map the shared block (the fd sent with the request), load the model if one came."""
        layout = Layout.from_json(request["layout"])
        fds = self.take_fds(1 + ("model" in request))
        shm = fds[0]
        split = layout.split
        inputs = mmap.mmap(shm, split, prot=mmap.PROT_READ)
        outputs = mmap.mmap(shm, layout.nbytes - split, offset=split)
        os.close(shm)
        self.inp = np.frombuffer(inputs, np.float64, layout.inputs_size)
        self.out = np.frombuffer(outputs, np.float64, max(1, layout.outputs_size))
        self.views = layout.views(self.inp, self.out)
        self.command = self.views["command"]
        self.layout = layout
        if "model" in request:
            self.load_model(fds[1], request["model"])

    def take_fds(self, count: int) -> list[int]:
        return self.chan.take(count)

    def load_model(self, fd: int, about: dict[str, Any]) -> None:
        """Keep the compiled model's file; it is loaded when `self.dynamics` is first read (a
        controller that never reads it never imports MuJoCo)."""
        if self._model_fd is not None:
            os.close(self._model_fd)
        self._model_fd, self._model_size = fd, int(about["size"])
        self.model = None
        self.links = {str(k): int(v) for k, v in about["links"].items()}
        self.bodies = [int(b) for b in about["bodies"]]
        self._dyn = None

    def _load_model(self) -> None:
        import mujoco

        assert self._model_fd is not None  # its one caller, dynamics(), has checked
        data = os.pread(self._model_fd, self._model_size, 0)
        self.model = mujoco.MjModel.from_binary_path("model.mjb", {"model.mjb": data})
        self.source = mujoco.MjData(self.model)

    def do_model(self, request: dict[str, Any]) -> None:
        self.load_model(self.take_fds(1)[0], request["model"])

    def bind_state(self, request: dict[str, Any]) -> None:
        """state.q, dq, effort and all_q, all_dq as read-only views of the shared block."""
        v = self.views
        state = self.state
        assert state is not None and self.layout is not None  # do_bind, its caller, set both
        qadr = np.asarray(request["qpos_adr"], dtype=int)
        dadr = np.asarray(request["dof_adr"], dtype=int)
        base = request.get("base_joint")
        state._base_joint = tuple(base) if base else None
        state._bind(SimpleNamespace(qpos=v["qpos"], qvel=v["qvel"]))
        views = [strided_view(v["qpos"], qadr), strided_view(v["qvel"], dadr),
                 strided_view(v["frc"], dadr)]
        self.gather = None if all(x is not None for x in views) else (qadr, dadr)
        if self.gather is None:  # every view an array (all not None above): numpy's 1-d shape unknown
            state.q, state.dq, state.effort = views  # type: ignore[assignment]
        self.sensor_map = _Sensors(self, self.layout)
        inputs = {}
        for name, view in v["inputs"].items():
            view = view.view()
            view.flags.writeable = False
            inputs[name] = view
        state.inputs = inputs
        dict.update(self.exports, v["exports"])  # the same object: the student may hold it
        state._sensor_source = lambda: self.sensor_map
        self._dyn = None

    # ----- the lifecycle ------------------------------------------------------------------------------
    def fresh_state(self) -> Any:
        state, inp = self.state, self.inp
        assert state is not None  # bound before anything asks for the state
        state.time = float(inp[0])
        state._sensors = None
        state._base = None
        if self.gather is not None:
            qadr, dadr = self.gather
            v = self.views
            for name, array in (("q", v["qpos"][qadr]), ("dq", v["qvel"][dadr]),
                                ("effort", v["frc"][dadr])):
                array.flags.writeable = False
                setattr(state, name, array)
        self.updates += 1
        return state

    def do_activate(self, request: dict[str, Any]) -> None:
        assert self.impl is not None  # mexone's side creates before anything else of the object
        self.student("activate", self.impl.activate, self.fresh_state())

    def do_deactivate(self, request: dict[str, Any]) -> None:
        assert self.impl is not None  # created before (mexone's side)
        self.student("deactivate", self.impl.deactivate)

    def do_set_param(self, request: dict[str, Any]) -> None:
        assert self.impl is not None  # created before (mexone's side)
        self.student("set_param", self.impl.params.__setitem__, str(request["key"]),
                     request["value"])
        self.sent_params = dict(self.impl.params)

    def do_report(self, request: dict[str, Any]) -> Any:
        assert self.impl is not None  # created before (mexone's side)
        # report is optional: asked only of a class that has one (describe's "report")
        report = self.student("report", self.impl.report)  # type: ignore[attr-defined]
        try:
            return json.loads(json.dumps(report, default=_plain))
        except (TypeError, ValueError, RecursionError) as exc:
            raise _Fault(f"report() returned what is not JSON ({type(exc).__name__}: "
                         f"{_safe_str(exc)})") from None

    def do_quit(self, request: dict[str, Any]) -> list[str]:
        """Threads the student started still running, one line each (they end with this
        process), naming where each was started."""
        lines = []
        for thread in threading.enumerate():
            started = getattr(thread, "_mexone_started", None)
            if started is None or not thread.is_alive():
                continue
            lines.append(f"its thread '{thread.name}', started at {started}, was still running: "
                         "it ended with the controller's process")
        return lines

    def watch_threads(self) -> None:
        """Each thread the student's code starts remembers where (for do_quit's line)."""
        host, start = self, threading.Thread.start

        def started(thread: threading.Thread, *args: Any, **kwargs: Any) -> None:
            line = host.line_in(sys._getframe(1))
            # a mark of mexone's on the thread object, which do_quit reads back
            thread._mexone_started = f"{host.file}:{line}" if line else host.file  # type: ignore[attr-defined]
            return start(thread, *args, **kwargs)

        # replacing Thread.start is the point: each start the student makes remembers where
        threading.Thread.start = started  # type: ignore[method-assign,assignment]

    def update(self, number: bytes) -> None:
        """One update: the state is in shared memory; the command goes back there, with the
        line of the `return` that produced it (mexone checks the numbers, and names that line
        for a NaN)."""
        state = self.fresh_state()
        if self.topics:
            inbox, self.inbox = self.inbox, {}
            state.messages = {name: inbox.get(name) for name in self.topics}
        inp, out = self.inp, self.out
        t, dt = state.time, float(inp[1])
        try:
            if self.traced:
                sys.settrace(self._trace)
                try:
                    result = self.update_fn(state, t, dt)
                finally:
                    sys.settrace(None)
            else:
                result = self.update_fn(state, t, dt)
        except BaseException as exc:  # noqa: BLE001 - the student's fault, said in one line
            self._frame = None
            self.fault(number, f"update raised {self.where(exc)} at t = {t:.3f} s")
            return
        if os.getpid() != self.pid:  # a copy of this process (a fork past the guards): not ours
            guard.real_exit(0)
        assert self.impl is not None  # created before any update (mexone's side)
        if self.sent_params != self.impl.params:
            self._params_changed()
        if result is None:
            self._frame = None
            with self.lock:
                self.chan.send_frame(self.KEPT_HEAD + number)
            return
        line = self._return_line()
        out[0] = line
        try:
            values = np.asarray(result, dtype=float)
            if values.shape != self.shape:
                if values.size != self.shape[0]:
                    self.fault(number, wrong_count(values.size, self.shape[0],
                                                   f"{self.file}:{line}"))
                    return
                values = values.reshape(self.shape)
        except BaseException:  # noqa: BLE001 - whatever their object raises
            self.fault(number, not_numbers(result, f"{self.file}:{line}"))
            return
        self.command[:] = values
        with self.lock:
            self.chan.send_frame(self.DONE_HEAD + number)

    def _trace(self, frame: FrameType, event: str, arg: object) -> None:
        self._frame = frame  # the update's frame: its last line, once it returns, is the return's
        sys.settrace(None)

    def _return_line(self) -> int:
        """The line of the `return` that ended this update (0: unknown)."""
        frame, self._frame = self._frame, None
        if frame is not None:
            return frame.f_lineno
        if len(self.returns) == 1:
            return self.returns[0]
        return self.update_line or 0

    @property
    def update_line(self) -> int | None:
        assert self.impl is not None  # read after an update, so created
        try:
            return inspect.getsourcelines(type(self.impl).update)[1]
        except (OSError, TypeError):
            return None

    def fault(self, number: bytes, text: str) -> None:
        """The update numbered `number` failed: its one line."""
        data = json.dumps({"fault": text}).encode()
        with self.lock:
            self.chan.send(UPDATE_FAULT, number + data)

    # ----- the student's code ----------------------------------------------------------------------
    def student(self, what: str, fn: Callable[..., Any], *args: Any) -> Any:
        try:
            return fn(*args)
        except BaseException as exc:  # noqa: BLE001 - the student's, said in one line
            raise _Fault(f"{what} failed: {self.where(exc)}" if what in ("creating", "configure")
                         else f"{what} raised {self.where(exc)}") from None
        finally:
            if os.getpid() != self.pid:  # a copy of this process: not ours
                guard.real_exit(0)

    def where(self, exc: BaseException) -> str:
        line = student_line(self.file, exc.__traceback__)
        text = _safe_str(exc).splitlines()
        first = text[0] if text else ""
        return f"{self.file}:{line or '?'}: {type(exc).__name__}" + (f": {first}" if first else "")

    def line_in(self, frame: FrameType) -> int | None:
        ours = [f for f in traceback.extract_stack(frame) if f.filename == self.file]
        return ours[-1].lineno if ours else None

    def _thread_raised(self, args: threading.ExceptHookArgs) -> None:
        """A thread the student started raised: the controller's fault, in one line."""
        if args.exc_type is SystemExit:
            return
        exc = args.exc_value if args.exc_value is not None else args.exc_type()
        name = args.thread.name if args.thread is not None else "?"
        with contextlib.suppress(BaseException):
            self.send(THREAD_FAULT, {"fault": f"its thread '{name}' raised {self.where(exc)}"})

    def _params_changed(self) -> None:
        params = getattr(self.impl, "params", None)
        if not isinstance(params, dict) or params == self.sent_params:
            return
        self.sent_params = dict(params)
        with contextlib.suppress(TypeError, ValueError):
            self.send(PARAMS, {"params": {k: v for k, v in params.items()
                                          if isinstance(v, bool | int | float | str)}})

    # ----- what the student's object asks of its binding ------------------------------------------------
    def dynamics(self) -> Dynamics:
        """The robot's dynamics at this update's state, on the private model."""
        if self._model_fd is None:
            raise AttributeError("dynamics: no model was sent to this controller's process")
        if self.model is None:
            self._load_model()
        if self._dyn is None:
            from mexone.dynamics import Dynamics

            self._fill_source()
            self._dyn = Dynamics(self.model, self.source, self.links, self.bodies)
            self._dyn_at = self.updates
        elif self._dyn_at != self.updates:
            self._fill_source()
            self._dyn.refresh()
            self._dyn_at = self.updates
        return self._dyn

    def _fill_source(self) -> None:
        v, src = self.views, self.source
        src.qpos[:] = v["qpos"]
        src.qvel[:] = v["qvel"]
        if self.model.nmocap:
            src.mocap_pos[:] = v["mocap_pos"].reshape(-1, 3)
            src.mocap_quat[:] = v["mocap_quat"].reshape(-1, 4)
        src.time = float(self.inp[0])


class _SimView:
    """`ctx.sim` in a worker, for the design classes that read the simulation itself (an
    Observer reads encoders, the motors' torques, the IMU): the private model, and `data`, an
    MjData of it holding this update's qpos, qvel and qfrc_actuator from the shared block.
    What the block does not carry (ctrl: the PIDs' setpoints; act) is NaN: a design that needs
    it says so by its NaN instead of reading zeros."""

    def __init__(self, host: _Host):
        self._host = host
        self._data: Any = None
        self._at = -1

    @property
    def model(self) -> Any:
        if self._host.model is None:
            self._host.dynamics()  # loads the model (mexone's own call: no student code)
        return self._host.model

    @property
    def data(self) -> Any:
        host = self._host
        if self._data is None:
            import mujoco

            self._data = mujoco.MjData(self.model)
            self._data.ctrl[:] = np.nan
            self._data.act[:] = np.nan
        if self._at != host.updates:
            v = host.views
            self._data.qpos[:], self._data.qvel[:] = v["qpos"], v["qvel"]
            self._data.qfrc_actuator[:] = v["frc"]
            self._data.time = float(host.inp[0])
            self._at = host.updates
        return self._data


class _Fault(Exception):
    """The student's code failed in a call (its one line)."""


class _Sensors(Mapping[str, Any]):
    """state.sensors in the worker: each sensor's state over read-only shared memory, filled by
    mexone from the first update that looks it up (the first look asks for it at once)."""

    def __init__(self, host: _Host, layout: Layout):
        self.host = host
        self.index = {name: i for i, (name, _, _) in enumerate(layout.sensors)}
        self.wanted = [False] * len(layout.sensors)
        self.objects: list[Any] = []
        for (_name, path, _), views in zip(layout.sensors, host.views["sensors"], strict=True):
            module, _, qualname = path.rpartition(":")
            obj = None
            if module.startswith("mexone.sensors"):
                cls = getattr(importlib.import_module(module), qualname)
                obj = cls.__new__(cls)
                for field, view in views:
                    object.__setattr__(obj, field, view)
            self.objects.append(obj)

    def __getitem__(self, name: str) -> Any:
        index = self.index.get(name)
        if index is None:
            raise KeyError(f"no sensor named '{name}' with state interfaces (sensors: "
                           f"{', '.join(self.index) or 'none'})")
        if not self.wanted[index]:
            self.host.send(SENSOR, {"sensor": index})
            frame = self.host.chan.receive(None)
            if frame is None or frame[0] != FILLED:
                raise _Quit
            self.wanted[index] = True
        return self.objects[index]

    def __iter__(self) -> Iterator[str]:
        return iter(self.index)

    def __len__(self) -> int:
        return len(self.index)


class _ToMexone(logging.Handler):
    """The student's `self.log` lines go to mexone, which shows them where the lab's go."""

    def __init__(self, host: _Host):
        super().__init__()
        self.host = host

    def emit(self, record: logging.LogRecord) -> None:
        with contextlib.suppress(BaseException):
            self.host.send(LOG, {"level": int(record.levelno), "text": record.getMessage()})


def _safe_str(exc: BaseException) -> str:
    try:
        return str(exc)
    except BaseException as inner:  # noqa: BLE001 - a __str__ of the student's that raises
        return f"(its str() raised {type(inner).__name__})"


def _plain(value: object) -> Any:
    """numpy numbers and arrays as JSON's; anything else as its text."""
    tolist = getattr(value, "tolist", None)
    return tolist() if callable(tolist) else str(value)


if __name__ == "__main__":
    main(sys.argv[1:])
