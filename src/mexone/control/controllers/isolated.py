"""IsolatedRunner: a student's PythonController whose object lives in a worker process
(control/worker.py), inside the manager's read -> update -> write.

The same framework as PythonRunner -- the schedule, the checks, the clamps, the hold after a
fault, the one line naming the student's file:line -- with the student's calls made in the
worker: each update copies what the controller reads into shared memory, wakes the worker and
waits for its command up to `hang_timeout`. A worker that does not answer, ends or crashes is
ended with everything it started; the controller stops, its joints hold, the lab runs on. A
later start (the page's Start, a switch) starts a fresh worker: the object is created and
configured again.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
from typing import TYPE_CHECKING, Any

import numpy as np

from mexone.control import watchdog
from mexone.control.controllers.python import (
    STUDENT_LOG,
    PythonRunner,
    _clock,
    log,
)
from mexone.control.student import declared_lengths
from mexone.control.watchdog import own_time, sched
from mexone.control.worker import (
    DONE,
    MESSAGES,
    STARTUP_TIMEOUT,
    UPDATE_FAULT,
    ClassInfo,
    Layout,
    StudentFault,
    Worker,
    WorkerFailed,
    claim,
    message_data,
    model_block,
    shown,
)
from mexone.errors import InputError
from mexone.physics.simulation import NS
from mexone.ranges import number_text
from mexone.sandbox.wire import Channel, WireError

if TYPE_CHECKING:
    from mexone.control.resolve import Plugin
    from mexone.control.student import PythonController

__all__ = ["IsolatedRunner"]


class IsolatedRunner(PythonRunner):
    """PythonRunner whose student object runs in a worker process."""

    _sched_meter: watchdog.SchedOf | None = None  # the kernel's schedstat of the worker
    # an update that overran while measured, judged at the next (elapsed, its worker, the
    # worker's schedstat before it, the simulation thread's wait for a CPU meanwhile)
    _pending: tuple[float, Worker, watchdog.Sched | None, float] | None = None

    # ----- loading ------------------------------------------------------------------------------
    def _instantiate(self, plugin: Plugin) -> PythonController:
        # the stand-in class worker.py made for the student's carries its description
        self.info: ClassInfo = plugin.cls._mexone_worker  # type: ignore[attr-defined]
        self.worker: Worker | None = None
        self._mirror: dict[str, Any] = dict(plugin.params)
        self._thread_fault: str | None = None
        self._wanted: list[int] = []
        self._version = -1
        self._sim = self.ctx.sim
        self._hang = plugin.hang_timeout
        self._start_worker()
        impl = plugin.cls()
        impl.name, impl.joints = self.name, list(self.joints)
        impl.dofs = self.dofs.copy()
        impl.effort_limits = self._effort_limit.copy()
        impl.params = self._mirror
        return impl

    def _start_worker(self) -> None:
        """Claim a worker for the class, create the object in it and configure it; an
        InputError (one line, the student's file:line) if that fails."""
        worker = claim(self.info, self.plugin.type, self.plugin.yaml_dir)
        worker.handler, worker.file = self, self.info.file
        self.worker = worker
        try:
            blocks = self._blocks(worker)
            worker.call(self._binding(), STARTUP_TIMEOUT, fds=blocks)  # mexone's own setup
            self._close_blocks()
            worker.call({"call": "create", "name": self.name, "joints": list(self.joints),
                         "dofs": self.dofs.tolist(), "params": dict(self._mirror),
                         "update_rate": self.plugin.update_rate,
                         "effort_limits": [min(float(v), 1e300) for v in self._effort_limit]},
                        watchdog.STUDENT_SETUP_TIMEOUT)
        except StudentFault as exc:
            self._end_worker()
            raise InputError(f"controller '{self.name}': {exc}", hint="fix it, then reload") from None
        except WorkerFailed as exc:
            self._end_worker()
            said = self._said("configure", exc, watchdog.STUDENT_SETUP_TIMEOUT)
            raise InputError(f"controller '{self.name}': {said}", hint="fix it, then reload") \
                from None
        finally:
            self._close_blocks()

    def _binding(self) -> dict[str, Any]:
        """What a bind tells the worker (with the shared block and the model's file): the
        block's layout, its joints' addresses, the model's links."""
        hw, rows = self.hw, self.rows
        return {"call": "bind", "dofs": self.dofs.tolist(),
                "layout": self._layout.to_json(), "qpos_adr": hw.qpos_adr[rows].tolist(),
                "dof_adr": hw.dof_adr[rows].tolist(), "base_joint": self._base_joint(),
                "model": {"size": self._model_size, "links": dict(self._links()),
                          "bodies": [int(b) for b in self._links().values()]}}

    def _links(self) -> dict[str, int]:
        return {str(k): int(v) for k, v in self.ctx.sim.compiled.bodies.items()}

    def _blocks(self, worker: Worker) -> tuple[int, int]:
        """A fresh shared block and model file for `worker` (fds closed by _close_blocks)."""
        sim = self.ctx.sim
        self._layout = self._layout_now()
        shm = worker.map(self._layout)
        self._model_fd, self._model_size = model_block(sim.model)
        self._shm_fd = shm
        self._version = sim.model_version
        self._views_of(worker)
        return shm, self._model_fd

    def _close_blocks(self) -> None:
        for name in ("_shm_fd", "_model_fd"):
            fd = getattr(self, name, None)
            if fd is not None:
                with contextlib.suppress(OSError):
                    os.close(fd)
                setattr(self, name, None)

    def _layout_now(self) -> Layout:
        model = self.ctx.sim.model
        sensors = []
        self._sensor_names: list[str] = []
        source = self.ctx.sensors() if self.ctx.sensors is not None else {}
        for name in source:
            try:
                obj = source[name]
                fields = tuple((f.name, int(np.size(getattr(obj, f.name))))
                               for f in dataclasses.fields(obj))
            except (KeyError, TypeError):
                continue
            sensors.append((name, f"{type(obj).__module__}:{type(obj).__qualname__}", fields))
            self._sensor_names.append(name)
        cls = self.plugin.cls
        inputs = declared_lengths(cls, "inputs")
        return Layout(len(self.rows), model.nq, model.nv, model.nmocap, tuple(sensors),
                      tuple((k, inputs[k]) for k in self.plugin.inputs),
                      tuple(declared_lengths(cls, "exports").items()))

    def _views_of(self, worker: Worker) -> None:
        inp, out = worker.inputs, worker.outputs
        assert inp is not None and out is not None  # a started worker has its block
        views = self._layout.views(inp, out)
        data = self.ctx.sim.data
        self._inp, self._out = inp, out
        self._cmd = views["command"]
        self._dst = (views["qpos"], views["qvel"], views["frc"])
        self._src = (data.qpos, data.qvel, data.qfrc_actuator)
        self._mocap = (views["mocap_pos"], views["mocap_quat"], data.mocap_pos, data.mocap_quat) \
            if self._layout.nmocap else None
        self._sensor_views = views["sensors"]
        self._wanted = []
        self._input_views = list(views["inputs"].items())  # chained: what it reads, and writes
        self._export_views = [(self.exports[k], v) for k, v in views["exports"].items()]

    def _end_worker(self) -> None:
        if self.worker is not None:
            self.worker.kill()
            self.worker = None
        meter = self._sched_meter
        if meter is not None:
            meter.close()
            self._sched_meter = None

    # ----- what front ends read ---------------------------------------------------------------------
    @property
    def params(self) -> dict[str, Any]:
        return dict(self._mirror)

    def set_param(self, key: str, value: object) -> Any:
        param = self.plugin.cls.declared_params().get(key)
        if param is None:
            raise InputError(f"controller '{self.name}' has no parameter '{key}'",
                             hint="its parameters: " + (", ".join(self._mirror) or "none"))
        value = param.check(value, f"controller '{self.name}': {key}")
        if self.worker is not None:
            try:
                self.worker.call({"call": "set_param", "key": key, "value": value},
                                 self.plugin.hang_timeout)
            except (StudentFault, WorkerFailed) as exc:
                self._lost("set_param", exc)
        self._mirror[key] = value
        return value

    def update_line(self) -> str:
        return f"{self.info.file}:{self.info.update_line or '?'}"

    def return_line(self) -> str:
        """file:line of the `return` that produced this update's command, as the worker saw it
        (a number it may have made up: only ever shown)."""
        line = float(self._out[0])
        if 0 < line < 1e7 and line.is_integer():
            return f"{self.info.file}:{int(line)}"
        return self.update_line()

    @property
    def reports(self) -> bool:
        return self.info.report

    def report(self) -> Any:
        """The controller's report(), asked of its worker (None: no report, or no worker)."""
        if not self.info.report or self.worker is None:
            return None
        try:
            return self.worker.call({"call": "report"}, self.plugin.hang_timeout)
        except WorkerFailed as exc:
            self.worker = None
            raise StudentFault(self._said("report", exc)) from None

    def close(self) -> None:
        """Unloaded (or the lab ends): the worker ends, with a line for each thread the student
        left running."""
        worker, self.worker = self.worker, None
        if worker is not None:
            for line in worker.quit():
                log.warning("controller '%s': %s", self.name, line)
        self.say_dropped()

    # ----- the worker's requests while mexone waits ----------------------------------------------
    def on_log(self, level: int, text: str) -> None:
        if self.log_limit.let_through(STUDENT_LOG, self.name):
            STUDENT_LOG.log(level, "%s", text)

    def on_thread_fault(self, text: str) -> None:
        self._thread_fault = self._thread_fault or text

    def on_sensor(self, index: int) -> bool:
        if not 0 <= index < len(self._sensor_names):
            return False
        self._fill_sensor(index)
        if index not in self._wanted:
            self._wanted.append(index)
        return True

    def on_params(self, params: dict[str, Any]) -> None:
        declared = self.plugin.cls.declared_params()
        for key, value in params.items():
            param = declared.get(key)
            if param is not None:
                with contextlib.suppress(InputError):
                    self._mirror[key] = param.check(value)

    def _fill_sensor(self, index: int) -> None:
        sensors = self.ctx.sensors
        assert sensors is not None  # a sensor index exists only with the lab's sensors
        obj = sensors()[self._sensor_names[index]]
        for name, view in self._sensor_views[index]:
            view[:] = np.ravel(getattr(obj, name))

    # ----- the lifecycle (simulation thread) --------------------------------------------------------
    def _fill(self, t: float, dt: float) -> None:
        """What the controller reads, into the shared block."""
        inp = self._inp
        inp[0] = t
        inp[1] = dt
        qd, vd, fd = self._dst
        qs, vs, fs = self._src
        qd[:] = qs
        vd[:] = vs
        fd[:] = fs
        if self._mocap is not None:
            pd, qd_, ps, qs_ = self._mocap
            pd[:] = ps.ravel()
            qd_[:] = qs_.ravel()
        for index in self._wanted:
            self._fill_sensor(index)
        if self._input_views:
            inputs = self.state.inputs
            for name, view in self._input_views:
                view[:] = inputs.get(name, np.nan)

    def _send_messages(self, worker: Worker) -> None:
        """The messages that arrived since the last update (none: no frame), for the worker's
        state.messages."""
        with self._inbox_lock:
            inbox, self._inbox = self._inbox, {}
        if inbox:
            worker.chan.send_json(MESSAGES, {k: message_data(v) for k, v in inbox.items()},
                                  self._hang)

    def _exported(self) -> None:
        """What it exported this update, into the arrays its readers see (copies: the worker
        writes its own memory whenever it likes)."""
        for ours, theirs in self._export_views:
            ours[:] = theirs

    def _activate(self, t: float) -> None:
        if self.worker is None:  # ended by an earlier fault: a fresh one
            try:
                self._start_worker()
            except InputError as exc:
                self._fault(exc.what.removeprefix(f"controller '{self.name}': "))
                return
        self._thread_fault = None
        for _, theirs in self._export_views:  # NaN until this run writes them
            theirs.fill(np.nan)
        try:
            self._check_model()
            self._fill(t, 0.0)
            assert self.worker is not None  # started above
            self.worker.call({"call": "activate"}, watchdog.STUDENT_SETUP_TIMEOUT)
            self._exported()
        except StudentFault as exc:
            self._fault(str(exc))
        except WorkerFailed as exc:
            self.worker = None
            self._fault(self._said("activate", exc, watchdog.STUDENT_SETUP_TIMEOUT))
        if self._thread_fault:
            self._fault(self._thread_fault)

    def _deactivate(self) -> None:
        if self.worker is None:
            return
        try:
            self.worker.call({"call": "deactivate"}, self.plugin.hang_timeout)
        except StudentFault as exc:
            log.warning("controller '%s': %s", self.name, exc)
        except WorkerFailed as exc:
            self.worker = None
            log.warning("controller '%s': %s", self.name,
                        self._said("deactivate", exc, self.plugin.hang_timeout))

    def rebind(self) -> None:
        super().rebind()
        worker = self.worker
        if worker is None:
            return
        try:
            blocks = self._blocks(worker)
            worker.call(self._binding(), STARTUP_TIMEOUT, fds=blocks)
        except (StudentFault, WorkerFailed) as exc:
            self._lost("rebind", exc)
        finally:
            self._close_blocks()

    def _check_model(self) -> None:
        """The model changed in place (gravity, the step): the worker's copy follows."""
        sim = self.ctx.sim
        if self._version == sim.model_version:
            return
        fd, size = model_block(sim.model)
        assert self.worker is not None  # asked only with a worker
        try:
            self.worker.call({"call": "model", "model": {"size": size, "links": self._links(),
                                                         "bodies": list(self._links().values())}},
                             watchdog.STUDENT_SETUP_TIMEOUT, fds=(fd,))
        finally:
            os.close(fd)
        self._version = sim.model_version

    def _lost(self, what: str, exc: Exception) -> None:
        """A call outside the loop failed: a fault (the worker's end, or the student's error)."""
        if isinstance(exc, WorkerFailed):
            self.worker = None
            self._fault(self._said(what, exc))
        else:
            self._fault(str(exc))

    def _said(self, what: str, exc: WorkerFailed, timeout: float | None = None) -> str:
        """The one line for a worker that ended during `what`."""
        where = f"{self.info.file}:{exc.line}" if exc.line else (
            self.update_line() if what == "update" else self.info.file)
        if exc.hung:
            limit = "hang_timeout " if timeout is None else ""
            return f"{what} did not return within {limit}" \
                   f"{number_text(timeout or self.plugin.hang_timeout)} s (ended at {where})"
        return f"{what} ended the controller: {exc.why} ({where})"

    def update(self, t: float, dt: float) -> None:
        """The framework around the student's update, as PythonRunner's, with the call made in
        the worker: fill the shared block, wake it, wait for its command."""
        if not self.due:
            return
        self.due = False
        worker = self.worker
        if worker is None:
            return
        if self._pending is not None and self._judged(worker):
            return
        last, self._last_t = self._last_t, t
        dt = t - last if last is not None else self.period_ns / NS
        self.updates += 1
        try:
            if self._version != self._sim.model_version:
                self._check_model()
            self._fill(t, dt)
            if self._topics:
                self._send_messages(worker)
            suspect = self._suspect
            if suspect:  # an update overran: measure what the machine took from the next ones
                ours, theirs = sched(), self._their_sched(worker)
            start = _clock()
            kind, payload = worker.update(self._hang)
        except StudentFault as exc:
            self._fault(str(exc))
            return
        except (WorkerFailed, WireError) as exc:
            self.worker = None
            if isinstance(exc, WireError):
                worker.kill()
                exc = WorkerFailed(f"its process hung up ({exc})")
            self._fault(self._said("update", exc) + f" at t = {t:.3f} s")
            return
        elapsed = _clock() - start
        if self._thread_fault:
            self._fault(self._thread_fault)
            return
        self._metered(elapsed)
        if kind == UPDATE_FAULT:
            self._fault(self._update_fault(payload))
            return
        if self._export_views:
            self._exported()
        if suspect and elapsed > self._max_time:  # judged when the worker has gone back to wait
            now = sched()
            waited = 0.0 if ours is None or now is None else now[1] - ours[1]
            self._pending = (elapsed, worker, theirs, waited)
        elif (elapsed > self._max_time or suspect) and self._overran(elapsed, None):
            return
        if kind == DONE:
            self._write(self._cmd.copy(), t)

    def _judged(self, worker: Worker) -> bool:
        """Judge the last update, which overran while measured, now that its worker waits for
        the next: its own time (watchdog.own_time: its CPU time if it blocked only to wait for
        the next request, else the round trip less both sides' waits for a CPU). Not at its reply:
        the kernel counts another process's CPU time only at its switches and ticks (4 ms), so
        a worker still running was behind by up to a tick. True if that made it a fault."""
        assert self._pending is not None
        elapsed, measured, theirs, waited = self._pending
        self._pending = None
        if measured is not worker or not self._suspect:  # a new worker, or started again
            return False
        own = own_time(elapsed, theirs, self._their_sched(worker), blocks=1, also_waited=waited)
        return self._overran(elapsed, own)

    def _their_sched(self, worker: Worker) -> watchdog.Sched | None:
        """The worker's `Sched` (watchdog.SchedOf), as the kernel says (not as its shared
        memory says: the student writes there)."""
        pid = worker.pid or worker.process.pid
        meter = self._sched_meter
        if meter is None or meter.pid != pid:
            if meter is not None:
                meter.close()
            meter = self._sched_meter = watchdog.SchedOf(pid)
        return meter()

    def _update_fault(self, payload: bytes) -> str:
        try:
            message = Channel.json(payload)
        except WireError:
            message = None
        if not isinstance(message, dict) or not isinstance(message.get("fault"), str):
            return f"update: its process sent what mexone cannot read ({self.update_line()})"
        return shown(message["fault"])
