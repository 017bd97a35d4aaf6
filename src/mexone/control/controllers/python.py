"""PythonRunner: a student's PythonController inside the manager's read -> update -> write.

The runner is the framework around the student's `update`: it builds the `State`, times the call,
checks what comes back (numbers, one per joint, finite), clamps it to the joint's limits (said
once), and writes it to the claimed command interface. The student's faults are theirs: an
exception, a NaN or inf, `max_overruns` consecutive updates over `max_update_time` (what a loaded or
stalled machine took from an update is not counted: watchdog.own_time), or an update
that has not returned after `hang_timeout` (a watchdog thread interrupts it) -> the manager stops
the controller, its joints hold their measured position (or are damped: `on_fault: damp`), the
lab runs on, and one line names the controller and the student's file:line.

Holding uses the joint's PID gains from the YAML (pid:, gains:, gazebo_ros_control/pid_gains)
if it has any, else autotune's rule on the live inertia: w dt = 0.1, p = I w^2, d = 2 I w, with I
the joint's diagonal entry of M(q) (MuJoCo's servo; its D term is implicit, so this is stable).
"""

from __future__ import annotations

import inspect
import logging
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from mexone import signals
from mexone.control import watchdog
from mexone.control.controllers.base import Controller, ControllerType
from mexone.control.hardware import TELEPORT_POSITION, TELEPORT_VELOCITY
from mexone.control.mistakes import (
    LogLimit,
    StudentLog,
    non_finite,
    not_numbers,
    return_lines,
    wrong_count,
)
from mexone.control.resolve import Plugin, student_line
from mexone.control.student import (
    Exports,
    PythonController,
    State,
    declared_lengths,
    declared_topics,
    strided_view,
    unit_of,
)
from mexone.control.watchdog import GUARD as _GUARD
from mexone.control.watchdog import ControllerHang, Watched, own_time
from mexone.control.watchdog import sched as _sched
from mexone.errors import InputError, MexoneError
from mexone.physics.simulation import NS
from mexone.ranges import number_text

if TYPE_CHECKING:
    import mujoco

    from mexone.bus.topics import Subscription
    from mexone.control.controllers.base import ControllerContext
    from mexone.control.spec import ControllerSpec
    from mexone.dynamics import Dynamics

__all__ = ["PythonRunner", "ControllerHang", "HOLD_BANDWIDTH", "BudgetMeter"]

log = logging.getLogger("mexone.control")
# the students' own lines: info and up (mexone's own loggers say only warnings); the terminal
# shows them all, the page and /rosout their warnings and errors
STUDENT_LOG = logging.getLogger("mexone.control.student")
STUDENT_LOG.setLevel(logging.INFO)
HOLD_BANDWIDTH = 0.1  # w dt of the hold after a fault (autotune's STEP_BANDWIDTH)
_SATURATION_ERROR = 0.1  # rad: the hold's p reaches the effort limit at this error
_EMPTY = np.zeros(0)
_EMPTY.flags.writeable = False


class BudgetMeter:
    """A Python controller's real-time budget since it started: updates, wall time (mean and
    worst) and deadline misses (updates longer than max_update_time, else its period), each
    counted: a miss the OS caused is a miss too (the fault for overruns is the student's alone)."""

    __slots__ = ("updates", "total", "worst", "misses")

    def __init__(self) -> None:
        self.updates, self.total, self.worst, self.misses = 0, 0.0, 0.0, 0

    def as_dict(self, deadline: float) -> dict[str, Any]:
        """For `sim --json` and the page: ms per update (mean, worst), the deadline (ms), misses."""
        mean = self.total / self.updates if self.updates else 0.0
        return {"updates": self.updates, "update_ms_mean": round(mean * 1e3, 4),
                "update_ms_max": round(self.worst * 1e3, 4), "deadline_ms": round(deadline * 1e3, 4),
                "deadline_misses": self.misses}


class PythonRunner(Controller):
    """The framework's side of a student's PythonController in the simulation's process: it
    reads the state into `State`, calls update in lockstep, checks and clamps what it returns and
    writes it through the hardware's writers; a fault stops it and holds its joints."""

    kind = "python"
    sliders = False
    reloadable = True

    def __init__(self, spec: ControllerSpec, ctx: ControllerContext) -> None:
        plugin: Plugin = spec.plugin
        self.plugin = plugin
        super().__init__(spec, ctx)
        self.msg_type = None  # it listens to no command topic: its update computes the command
        self.interface_name = plugin.cls.command_interface
        self.unit = unit_of(self.interface_name)
        hw = self.hw
        self.dofs = hw.dof_adr[self.rows].copy()
        self.fault: str | None = None
        self.updates = 0
        self.log_limit = LogLimit()  # its self.log's lines a second
        self.meter = BudgetMeter()  # the real-time budget since it started: every update counted
        self._seen = (0, 0.0)  # the meter's updates and total when update_time was last read
        self._update_time = 0.0
        self.due = False
        self.next_ns = 0
        self.period_ns = 1
        self._last_t: float | None = None
        self._overruns = 0
        self._suspect = False  # the last update overran: the next are measured (own_time)
        self._dyn: Dynamics | None = None
        self._dyn_at = -1
        self._limits_said: set[str] = set()
        self._command = np.zeros(len(self.rows))
        self._effort_limit = hw.effort_limit[self.rows].copy()
        # the same, as Python floats capped finite: an inf command never passes the fast check
        self._limits = [min(float(v), 1e300) for v in self._effort_limit]
        self._n = len(self.rows)
        self._effort = self.interface_name == "effort"
        # the manager's: hw.writer(rows, interface), the hardware's commands and MuJoCo's ctrl
        self.writer: Callable[[np.ndarray], None] = lambda values: None
        self._max_time = 0.001  # s: max_update_time, else the period (set by the manager)
        self.state = State(len(self.rows), ctx.sim.data, self._base_joint(), ctx.sensors)
        self._span: slice | None = None
        self.direct = False  # state views of MuJoCo's arrays: no hardware read needed
        self._gather = False  # neither: state.q, dq, effort are gathered each update
        self._views()
        # chained controllers: what it exports (its own arrays), what it reads (the manager binds)
        self.exports = Exports({k: np.full(n, np.nan)
                                 for k, n in declared_lengths(plugin.cls, "exports").items()})
        self.impl = self._instantiate(plugin)
        # declared topics: each callback (the publisher's thread) only keeps the newest message
        self._topics = declared_topics(plugin.cls)
        self._inbox: dict[str, object] = {}
        self._inbox_lock = threading.Lock()
        self._subscriptions: list[Subscription] = []

    @classmethod
    def type_of(cls, spec: ControllerSpec) -> ControllerType:
        return ControllerType(spec.type, cls, spec.plugin.interface, False)

    # ----- what front ends read -----------------------------------------------------------------
    @property
    def setpoint(self) -> np.ndarray:
        return self._command.copy()

    @property
    def update_time(self) -> float:
        """s of wall time per update: the mean since the last time this was read."""
        meter, (updates, total) = self.meter, self._seen
        if meter.updates > updates:
            self._update_time = (meter.total - total) / (meter.updates - updates)
            self._seen = (meter.updates, meter.total)
        return self._update_time

    @property
    def timed(self) -> bool:
        return True

    def budget(self) -> dict[str, Any]:
        """The real-time budget meter's figures (BudgetMeter.as_dict)."""
        return self.meter.as_dict(self._max_time)

    @property
    def params(self) -> dict[str, Any]:
        return dict(self.impl.params)

    def declared_params(self) -> dict[str, Any]:
        return self.plugin.cls.declared_params()

    @property
    def code_file(self) -> str | None:
        return self.plugin.file

    def set_param(self, key: str, value: object) -> Any:
        """Change a declared parameter live (simulation thread), validated as the YAML's."""
        param = self.plugin.cls.declared_params().get(key)
        if param is None:
            raise InputError(f"controller '{self.name}' has no parameter '{key}'",
                             hint="its parameters: " + (", ".join(self.impl.params) or "none"))
        value = param.check(value, f"controller '{self.name}': {key}")
        self.impl.params[key] = value
        return value

    # ----- loading ------------------------------------------------------------------------------
    def _base_joint(self) -> tuple[int, int] | None:
        """(qpos, qvel) address of this robot's free joint, or None (fixed to the world)."""
        import mujoco

        model, prefix = self.ctx.sim.model, self.hw.prefix
        for j in range(model.njnt):
            if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE and model.joint(j).name.startswith(prefix):
                return int(model.jnt_qposadr[j]), int(model.jnt_dofadr[j])
        return None

    def _instantiate(self, plugin: Plugin) -> PythonController:
        """The student's object, set up and configured; an error in their code is one line with
        their file:line (the load fails; a reload keeps the old controller)."""
        impl = self._call(plugin.cls, "creating")
        impl.name, impl.joints = self.name, list(self.joints)
        impl.dofs = self.dofs.copy()
        impl.effort_limits = self._effort_limit.copy()
        impl.params = dict(plugin.params)
        impl.log = StudentLog(STUDENT_LOG, {"name": self.name, "limit": self.log_limit})
        impl.exports = self.exports
        impl.__dict__["_mexone_binding"] = self
        self._call(impl.configure, "configure")
        return impl

    def _call(self, fn: Callable[..., Any], what: str, *args: object) -> Any:
        try:
            with _GUARD.watching(Watched(f"controller '{self.name}'", self.plugin.file, what)):
                return fn(*args)
        except MexoneError:
            raise
        except ControllerHang as exc:
            signals.recover()
            raise InputError(f"controller '{self.name}': {what} did not return within "
                             f"{number_text(watchdog.STUDENT_SETUP_TIMEOUT)} s (interrupted at "
                             f"{self._line(exc)})", hint="fix it, then reload") from None
        except (Exception, SystemExit) as exc:  # noqa: BLE001 - the student's error, said in one line
            raise InputError(f"controller '{self.name}': {what} failed: {self._where(exc)}",
                             hint="fix it, then reload") from None

    def _line(self, exc: BaseException) -> str:
        """file:line of the student's code an exception went through."""
        return f"{self.plugin.file}:{student_line(self.plugin.file, exc.__traceback__) or '?'}"

    def _where(self, exc: BaseException) -> str:
        file = self.plugin.file
        line = student_line(file, exc.__traceback__)
        text = str(exc).splitlines()[0] if str(exc) else ""
        return f"{file}:{line or '?'}: {type(exc).__name__}" + (f": {text}" if text else "")

    def update_line(self) -> str:
        """file:line of the student's update method (what an overrun points at)."""
        try:
            line = str(inspect.getsourcelines(type(self.impl).update)[1])
        except (OSError, TypeError):
            line = "?"
        return f"{self.plugin.file}:{line}"

    def return_line(self) -> str:
        """file:line of the `return` that produced what update returned: its only return of a
        value, else (several) the def line. (A worker's controller names the very return.)"""
        lines = return_lines(type(self.impl).update)
        return f"{self.plugin.file}:{lines[0]}" if len(lines) == 1 else self.update_line()

    # ----- dynamics at the live state -----------------------------------------------------------
    def dynamics(self) -> Dynamics:
        sim = self.ctx.sim
        if self._dyn is None or self._dyn.model is not sim.model or self._dyn._source is not sim.data:
            from mexone.dynamics import Dynamics

            links = sim.compiled.bodies  # one scratch MjData for the run: refreshed per update
            self._dyn = Dynamics(sim.model, sim.data, links, links.values())
            self._dyn_at = self.updates
        elif self._dyn_at != self.updates:
            self._dyn.refresh()
            self._dyn_at = self.updates
        return self._dyn

    # ----- topics (PythonController.topics) ------------------------------------------------------
    def _subscribe(self) -> None:
        bus, ns = self.ctx.bus, self.ctx.namespace
        if bus is None or self._subscriptions:
            return
        for name, msg_type in self._topics.items():
            def keep(msg: object, name: str = name) -> None:
                with self._inbox_lock:
                    self._inbox[name] = msg
            self._subscriptions.append(bus.subscribe(f"{ns}/{name}", msg_type, keep, node=self.name))

    def _unsubscribe(self) -> None:
        for sub in self._subscriptions:
            sub.unregister()
        self._subscriptions = []
        self._inbox = {}

    def _deliver(self, state: State) -> None:
        """state.messages: each declared topic's newest message since the last update, or None."""
        with self._inbox_lock:
            inbox, self._inbox = self._inbox, {}
        state.messages = {name: inbox.get(name) for name in self._topics}

    # ----- lifecycle (simulation thread) --------------------------------------------------------
    def starting(self, t: float) -> None:
        super().starting(t)
        if self._topics:
            self._subscribe()
        hw, rows = self.hw, self.rows
        hw.release(rows)
        c = hw.command
        self.fault, self._overruns, self._last_t, self._suspect = None, 0, None, False
        self.meter, self._seen = BudgetMeter(), (0, 0.0)
        self.next_ns, self.due = -1, False  # the manager schedules the first update now
        self._limits_said.clear()
        for array in self.exports.values():  # NaN until this run writes them
            array.fill(np.nan)
        if self.interface_name == "position":
            c.position[rows] = hw.state.position[rows]
            if not self._write_pid():
                c.teleport[rows] = TELEPORT_POSITION
            self._command = hw.state.position[rows].copy()
        elif self.interface_name == "velocity":
            found = [self.pid_for(j) for j in self.joints]
            gains = [g for g in found if g is not None]
            if len(gains) < len(found):
                c.teleport[rows] = TELEPORT_VELOCITY
            else:
                c.kd[rows] = [g.p for g in gains]
                hw.gains_changed(rows)
            self._command = np.zeros(len(rows))
        else:
            self._command = np.zeros(len(rows))
        self._read(t)
        self._activate(t)

    def _activate(self, t: float) -> None:
        """The student's activate(state), watched; a failure is a fault."""
        try:
            with _GUARD.watching(Watched(f"controller '{self.name}'", self.plugin.file, "activate")):
                self.impl.activate(self.state)
        except (Exception, SystemExit) as exc:  # noqa: BLE001 - the student's fault
            self._fault(f"activate raised {self._where(exc)}")
        except ControllerHang as exc:
            signals.recover()
            self._fault(f"activate did not return within {number_text(watchdog.STUDENT_SETUP_TIMEOUT)} s "
                        f"(interrupted at {self._line(exc)})")

    def _write_pid(self, damp: bool = False) -> bool:
        """The YAML's PID gains on the claimed joints (p, d only when damping); False if a joint
        has none."""
        found = [self.pid_for(j) for j in self.joints]
        gains = [g for g in found if g is not None]
        if len(gains) < len(found):
            return False
        c, rows = self.hw.command, self.rows
        c.kp[rows] = 0.0 if damp else [g.p for g in gains]
        c.kd[rows] = [g.d for g in gains]
        if not damp:
            c.ki[rows] = [g.i for g in gains]
            c.i_min[rows] = [g.i_clamp_min for g in gains]
            c.i_max[rows] = [g.i_clamp_max for g in gains]
            c.antiwindup[rows] = [g.antiwindup for g in gains]
        self.hw.gains_changed(rows)
        return True

    def stopping(self) -> None:
        self._unsubscribe()
        self._deactivate()
        if self.fault is None:
            super().stopping()
            return
        self.hold(damp=self.plugin.on_fault == "damp")

    def _deactivate(self) -> None:
        """The student's deactivate(), watched with hang_timeout: what it raises or a loop in it
        is said, and the stop goes on."""
        timeout = self.plugin.hang_timeout
        try:
            with _GUARD.watching(Watched(f"controller '{self.name}'", self.plugin.file,
                                         "deactivate", timeout)):
                self.impl.deactivate()
        except (Exception, SystemExit) as exc:  # noqa: BLE001 - said, and the stop goes on
            log.warning("controller '%s': deactivate raised %s", self.name, self._where(exc))
        except ControllerHang as exc:
            signals.recover()
            log.warning("controller '%s': deactivate did not return within %s s (interrupted at "
                        "%s)", self.name, number_text(timeout), self._line(exc))

    def report(self) -> Any:
        """The controller's report() (JSON-able numbers), None if its class has none; what it
        raises is the caller's to say."""
        report = getattr(self.impl, "report", None)
        return report() if callable(report) else None

    @property
    def reports(self) -> bool:
        """Its class defines report()."""
        return callable(getattr(self.impl, "report", None))

    def close(self) -> None:
        """It is unloaded for good (nothing to end in-process): the log lines it had dropped
        are said."""
        self.say_dropped()

    def say_dropped(self) -> None:
        """The line saying how many of its log lines the LogLimit dropped and has not said yet,
        if any were."""
        self.log_limit.say(STUDENT_LOG, self.name)

    def hold(self, damp: bool = False) -> None:
        """The joints hold their measured position (or are only damped) by MuJoCo's servo."""
        hw, rows = self.hw, self.rows
        hw.release(rows)
        c = hw.command
        c.position[rows] = hw.position(rows)
        if self._write_pid(damp):
            return
        sim = self.ctx.sim
        inertia = _inertia_diagonal(sim.model, sim.data, self.dofs)
        w = np.full(len(rows), HOLD_BANDWIDTH / sim.timestep)
        limit = hw.effort_limit[rows]
        with np.errstate(divide="ignore", invalid="ignore"):
            w_effort = np.sqrt(limit / (inertia * _SATURATION_ERROR))
        w = np.where(np.isfinite(w_effort), np.minimum(w, w_effort), w)
        c.kp[rows] = 0.0 if damp else inertia * w**2
        c.kd[rows] = 2.0 * inertia * w
        hw.gains_changed(rows)

    def rebind(self) -> None:
        """The model changed (a robot spawned or deleted): MuJoCo addresses moved."""
        self.dofs = self.hw.dof_adr[self.rows].copy()
        self.impl.dofs = self.dofs.copy()
        self.state._base_joint = self._base_joint()
        self._views()
        self._dyn = None

    def _views(self) -> None:
        """state.q, dq, effort as read-only views, so reading them costs nothing per update:
        of MuJoCo's qpos, qvel and qfrc_actuator when the joints' addresses are evenly spaced
        (a limb's are; `direct`: the manager need not read the hardware for us), else of the
        hardware's state when the rows are; else gathered each update."""
        hw, rows, state = self.hw, self.rows, self.state
        data = self.ctx.sim.data
        state._bind(data)  # MuJoCo's data is replaced only with the model (then we are here)
        self.direct, self._span, self._gather = False, None, False
        if len(rows) == 0:  # a chained controller that only exports: nothing to read
            state.q, state.dq, state.effort = (_EMPTY for _ in range(3))
            self.direct = True
            return
        found = [strided_view(data.qpos, hw.qpos_adr[rows]), strided_view(data.qvel, hw.dof_adr[rows]),
                 strided_view(data.qfrc_actuator, hw.dof_adr[rows])]
        views = [v for v in found if v is not None]
        if len(views) < len(found):
            self._span = _span_of(rows)
            if self._span is None:
                state.q, state.dq, state.effort = (np.zeros(len(rows)) for _ in range(3))
                self._gather = True
                return
            views = [hw.state.position[self._span], hw.state.velocity[self._span],
                     hw.state.effort[self._span]]
        else:
            self.direct = True
        for view in views:
            view.flags.writeable = False
        state.q, state.dq, state.effort = views

    def _read(self, t: float) -> None:
        state = self.state
        if not self.direct and self._span is None:
            joints, rows = self.hw.state, self.rows
            state.q[:] = joints.position[rows]
            state.dq[:] = joints.velocity[rows]
            state.effort[:] = joints.effort[rows]
        state.time, state._sensors, state._base = t, None, None

    def update(self, t: float, dt: float) -> None:
        """The framework around the student's update, every period: what runs here is what a
        Python controller costs beyond its own code (benchmarks/RESULTS.md), so it is kept to
        plain attribute work: the hang guard's enter and leave (as `_HangGuard.enter`/`leave`
        do them) are inlined; the student's own update is timed alone."""
        if not self.due:
            return
        self.due = False
        last, self._last_t = self._last_t, t
        dt = t - last if last is not None else self.period_ns / NS
        state = self.state
        if self._gather:
            self._read(t)
        else:  # q, dq, effort are views: nothing to copy
            state.time, state._sensors, state._base = t, None, None
        if self._topics:
            self._deliver(state)
        self.updates += 1
        suspect = self._suspect
        before = _sched() if suspect else None  # only after an overrun: a read of /proc
        guard = _GUARD
        tid = _thread_id()
        start = _clock()
        guard.last = start  # _HangGuard.enter
        guard.entries[tid] = (start, self)
        if not guard.running:
            guard.start()
        try:
            out = self.impl.update(state, t, dt)
        except (Exception, SystemExit) as exc:  # noqa: BLE001 - the student's fault
            guard.leave(tid)
            self._fault(f"update raised {self._where(exc)} at t = {t:.3f} s")
            return
        except ControllerHang as exc:
            guard.leave(tid)
            signals.recover()  # a Ctrl-C or SIGTERM may have woken the blocked update
            self._fault(f"update did not return within hang_timeout "
                        f"{number_text(self.plugin.hang_timeout)} s (interrupted at "
                        f"{self.plugin.file}:{student_line(self.plugin.file, exc.__traceback__) or '?'})")
            return
        elapsed = _clock() - start
        with guard.lock:  # _HangGuard.leave: the lock is the watchdog thread's safety
            guard.entries.pop(tid, None)
            hung = tid in guard.injected
            if hung:
                guard.withdraw(tid)
        if hung:
            self._fault(f"update did not return within hang_timeout ({self.update_line()})")
            return
        self._metered(elapsed)
        if (elapsed > self._max_time or suspect) and self._overran(
                elapsed, own_time(elapsed, before, _sched()) if suspect else None):
            return
        if out is not None:
            self._write(out, t)

    def _metered(self, elapsed: float) -> None:
        """An update's time, into the budget meter (a miss counted whoever's doing it was: the
        fault `_overran` finds is the controller's only)."""
        meter = self.meter
        meter.updates += 1
        meter.total += elapsed
        if elapsed > meter.worst:
            meter.worst = elapsed
        if elapsed > self._max_time:
            meter.misses += 1

    def _overran(self, elapsed: float, own: float | None) -> bool:
        """An update took `elapsed` s, `own` of them its code's own (watchdog.own_time: not the
        machine's; None when not measured): count it if both overran; True if that made it a
        fault. The first overrun is not counted: it starts measuring the next ones."""
        if elapsed > self._max_time and (own is None or own > self._max_time):
            if not self._suspect:  # the first: measure the next ones
                self._suspect = True
            else:
                self._overruns += 1
            if self._overruns >= self.plugin.max_overruns:
                self._fault(f"update overran its period: {self._overruns} updates in a row took "
                            f"longer than {number_text(self._max_time * 1e3)} ms (the last "
                            f"{number_text(elapsed * 1e3)} ms) ({self.update_line()})")
                return True
        else:
            self._suspect, self._overruns = False, 0
        return False

    def _write(self, out: object, t: float) -> None:
        """Check the student's commands (numbers, one per joint, finite), clamp them, and send
        them to the hardware's commands and MuJoCo, through the hardware's writer for these
        joints (the manager's fast path needs nothing else)."""
        n = self._n
        if type(out) is _NDARRAY and out.dtype is _FLOAT:  # the usual case: taken as it is
            values = out
        else:
            try:
                values = np.asarray(out, dtype=float)
            except Exception:  # noqa: BLE001 - whatever their object raises
                self._fault(not_numbers(out, self.return_line()))
                return
        if values.ndim != 1 or len(values) != n:
            if values.size == n:
                values = values.reshape(n)
            else:
                self._fault(wrong_count(values.size, n, self.return_line()))
                return
        if self._effort:  # the usual case, checked in Python floats (numpy calls cost more for
            # a limb's joints, cold after a physics step): each finite and within +-its limit
            # (NaN fails every comparison)
            for value, limit in zip(values.tolist(), self._limits):  # noqa: B905 - both n long
                if not -limit <= value <= limit:
                    break
            else:
                self._command = values
                self.writer(values)
                return
        if not np.isfinite(values).all():
            self._fault(non_finite(self.joints, values, t, self.return_line()))
            return
        hw, rows, kind = self.hw, self.rows, self.interface_name
        if kind == "effort":
            limit = hw.effort_limit[rows]
            if (np.abs(values) > limit).any():
                values = self._clamped(values, -limit, limit, "URDF effort limit")
        elif kind == "position":
            lo, hi = hw.lower[rows], hw.upper[rows]
            if (values < lo).any() or (values > hi).any():
                values = self._clamped(values, lo, hi, "joint limits")
        else:
            limit = hw.velocity_limit[rows]
            if (np.abs(values) > limit).any():
                values = self._clamped(values, -limit, limit, "URDF velocity limit")
        self._command = values
        self.writer(values)

    def _clamped(self, values: np.ndarray, lower: np.ndarray, upper: np.ndarray, what: str
                 ) -> np.ndarray:
        """Clamp, saying once per joint (Gazebo clamps efforts to the URDF limit too)."""
        clamped = np.clip(values, lower, upper)
        fresh = [i for i in np.flatnonzero(clamped != values) if self.joints[i] not in self._limits_said]
        if fresh:
            self._limits_said.update(self.joints[i] for i in fresh)
            parts = [f"{self.joints[i]} {number_text(values[i])} -> {number_text(clamped[i])}"
                     for i in fresh]
            log.warning("%s: command beyond the %s, clamped (said once per joint): %s",
                        self.name, what, ", ".join(parts))
        return clamped

    def _fault(self, text: str) -> None:
        """Stop at the end of this cycle, joints held; one line on the terminal, page, /rosout."""
        if self.fault is not None:
            return
        held = "damped" if self.plugin.on_fault == "damp" else "holding their position"
        self.fault = text
        log.error("controller '%s' stopped, its joints %s: %s", self.name, held, text)
        self.ctx.faults.append(self.name)


def _span_of(rows: np.ndarray) -> slice | None:
    """rows as a slice when they are consecutive (a limb's joints usually are), else None."""
    if len(rows) == 0 or not np.array_equal(rows, np.arange(rows[0], rows[0] + len(rows))):
        return None
    return slice(int(rows[0]), int(rows[0]) + len(rows))


def _inertia_diagonal(model: mujoco.MjModel, data: mujoco.MjData, dofs: np.ndarray) -> np.ndarray:
    """M(q)[i, i] for each dof i: the inertia the joint moves now (armature included)."""
    import mujoco

    unit, column = np.zeros(model.nv), np.zeros(model.nv)
    out = np.empty(len(dofs))
    for k, dof in enumerate(dofs):
        unit[:] = 0.0
        unit[dof] = 1.0
        mujoco.mj_mulM(model, data, column, unit)
        out[k] = column[dof]
    return out


_clock = time.perf_counter
_thread_id = threading.get_ident  # the hang guard's key (watchdog._thread_id)
_NDARRAY, _FLOAT = np.ndarray, np.dtype(float)  # a float array: float64 in this byte order


def period_ns(runner: PythonRunner, control_period: float, timestep: float) -> int:
    """The runner's period: 1/update_rate (at least one physics step), else the control period."""
    rate = runner.plugin.update_rate
    period = 1.0 / rate if rate else control_period
    if period < timestep * (1 - 1e-9):
        asked = f"update_rate {number_text(rate)} Hz" if rate else \
            f"the control rate {number_text(1 / control_period)} Hz"
        runner.warn_once("rate", f"{asked} is faster than the physics "
                                 f"step ({number_text(1 / timestep)} Hz): it updates every step")
        period = timestep
    return max(1, round(period * NS))

