"""Simulation: one robot in one world, stepped in sim time, paced to wall time when asked.

The simulation thread owns MuJoCo. Other threads hand work over (`work.put`) and the loop that
steps the simulation runs it between steps. The control layer plugs in as a `Control` (ros2_control's
read -> update -> write loop), which the simulation runs before a step whenever the control asks
for it (a command is waiting, or a controller needs its period). With nothing to do, MuJoCo steps
many times per call, so a headless run costs what bare MuJoCo costs.

Sim time is kept as integer nanoseconds, so stamps and timers never drift by float rounding.
"""

from __future__ import annotations

import logging
import math
import queue
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import mujoco
import numpy as np
from numpy.typing import ArrayLike

from mexone.description.check import check_model
from mexone.description.loader import load_model
from mexone.description.model import RobotModel
from mexone.errors import InputError
from mexone.physics.attach import attach_model, carry_over, detach_model
from mexone.physics.compile import (
    Compiled,
    CompileOptions,
    Spawn,
    SpecEdit,
    collision_bits,
    compile_model,
)
from mexone.physics.divergence import DivergenceError, Watchdog, link_speeds
from mexone.physics.forces import FOREVER, Forces, JointEffort, Wrench
from mexone.physics.gc_policy import REAL_TIME_GC
from mexone.physics.world import World
from mexone.ranges import GRAVITY, TIMESTEP, number_text

__all__ = ["Simulation", "RtfMeter", "Periodic", "Gate", "Control", "WorkQueue", "NS",
           "MIN_TIMESTEP", "MAX_TIMESTEP", "OutsideInput", "OUTSIDE_WINDOW"]

log = logging.getLogger("mexone.physics")

NS = 1_000_000_000
MIN_TIMESTEP, MAX_TIMESTEP = TIMESTEP.low, TIMESTEP.high  # s: ranges.TIMESTEP is their home
# steps between divergence checks: a diverging run goes NaN within steps, so 50 ms still names the
# link that went first; each check is a Python interlude that costs MuJoCo its warm caches
_WATCH_EVERY = 50
_FIRST_WATCH = 10  # steps after a reset to the first check: a bad start shows at once
# s of sim time after an outside input (a ROS service call, a goal, a command) during which a
# divergence is blamed on it: a teleport or a push shows within a few steps
OUTSIDE_WINDOW = 2.0
_LINT_CAUSES = {"com-outside": "its centre of mass lies outside its geometry",
                "inertia-too-large": "its inertia is implausibly large for its mass and size",
                "inertia-triangle": "its inertia is physically impossible",
                "inertia-not-positive": "its inertia is not positive definite",
                "mass-nonpositive": "it has no mass",
                "dynamics-negative": "a joint has negative damping or friction, which adds energy"}


class Gate(Protocol):
    """Lockstep with code waiting on sim time (see mexone.routines.runtime.Scheduler)."""

    def horizon(self) -> float | None:
        """Wait (briefly) until nobody runs; the earliest wake-up time, or None if someone is
        still running (the caller returns, stays responsive, and asks again)."""

    def advance(self, sim_time: float) -> None:
        """Time moved on: wake whoever is due, and wait until they block again."""


class Control(Protocol):
    """The control layer's loop (mexone.control.ControllerManager)."""

    wake_ns: float  # sim time (ns) it next needs to run; -inf: now (set from any thread)

    def update(self, sim: Simulation) -> None:
        """read -> controllers -> write; sets wake_ns again. Runs in the simulation thread."""


@dataclass(frozen=True)
class OutsideInput:
    """An input from outside the lab that changed the physics (see Simulation.note_input)."""

    what: str  # e.g. "/gazebo/set_model_configuration (l_elbow 0.1)"
    step: int  # Simulation.steps when it was applied
    undo: Callable[[], None] | None = None  # puts back what a lasting change (physics) replaced


@dataclass
class Periodic:
    period_ns: int
    callback: Callable[[Simulation], None]
    next_ns: int

    @property
    def period(self) -> float:
        return self.period_ns / NS


class WorkQueue:
    """Work handed to the simulation thread by other threads (GUI handlers, ROS callbacks): the
    thread that steps the simulation drains it between steps, so nobody else touches MuJoCo."""

    def __init__(self) -> None:
        self._items: queue.SimpleQueue[tuple[Callable[[], Any], threading.Event | None,
                                             list[Any]]] = queue.SimpleQueue()

    def put(self, fn: Callable[[], Any]) -> None:
        self._items.put((fn, None, []))

    def call(self, fn: Callable[[], Any], timeout: float = 10.0) -> Any:
        """Run `fn` in the simulation thread and wait for its result (its exception re-raised)."""
        done = threading.Event()
        box: list[Any] = []
        self._items.put((fn, done, box))
        if not done.wait(timeout):
            raise TimeoutError("the simulation thread did not answer")
        if box and isinstance(box[0], BaseException):
            raise box[0]
        return box[0] if box else None

    def drain(self, on_error: Callable[[Exception], None] | None = None) -> None:
        while True:
            try:
                fn, done, box = self._items.get_nowait()
            except queue.Empty:
                return
            try:
                box.append(fn())
            except Exception as exc:  # noqa: BLE001 - reported to whoever asked
                if done is not None:
                    box.append(exc)
                elif on_error is not None:
                    on_error(exc)
                else:
                    raise
            finally:
                if done is not None:
                    done.set()


class RtfMeter:
    """Real-time factor over the last `window` seconds of wall time, as Gazebo shows it."""

    def __init__(self, window: float = 1.0) -> None:
        self.window = window
        self.samples: deque[tuple[float, float]] = deque()

    def add(self, wall: float, sim: float) -> None:
        """One stretch of wall time and the sim time it advanced."""
        self.samples.append((wall, sim))
        while len(self.samples) > 2 and wall - self.samples[0][0] > self.window:
            self.samples.popleft()

    def clear(self) -> None:
        """Forget the stretches measured (after a pause or a reset)."""
        self.samples.clear()

    @property
    def value(self) -> float:
        """The real-time factor over the recent stretches (sim time / wall time)."""
        if len(self.samples) < 2:
            return 0.0
        (w0, s0), (w1, s1) = self.samples[0], self.samples[-1]
        return (s1 - s0) / (w1 - w0) if w1 > w0 else 0.0


class Simulation:
    """A robot in a world, compiled into MuJoCo and stepped as Gazebo would: MuJoCo's `model` and
    `data` behind a Gazebo-like API (`step`, `run`, `reset`, `pause`; joint positions,
    velocities and efforts; pushes and efforts; callbacks in sim time). Only the thread that
    steps it touches MuJoCo: other threads hand work over through `work`."""

    def __init__(self, robot: RobotModel | Path | str, world: World | None = None,
                 spawn: Spawn = Spawn(), options: CompileOptions = CompileOptions(),
                 target_rtf: float | None = None, edits: Sequence[SpecEdit] = ()) -> None:
        if not isinstance(robot, RobotModel):
            robot = load_model(robot)
        self.robot = robot
        self.compiled: Compiled = compile_model(robot, world, spawn, options, edits)
        self.model = self.compiled.model
        self.model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_AUTORESET  # the watchdog reports
        self.data = mujoco.MjData(self.model)
        self.joint_names = list(self.compiled.joints)
        self._index = {name: i for i, name in enumerate(self.joint_names)}
        self.models: dict[str, str] = {}  # spawned model -> the MuJoCo name of its root body
        self.forces = Forces()  # timed wrenches and joint efforts (apply_wrench, apply_joint_effort)
        self._model_hooks: list[Callable[[], None]] = []
        self.periodic: list[Periodic] = []
        self.controls: list[Control] = []
        self.work = WorkQueue()
        self._reset_hooks: list[Callable[[], None]] = []
        self._timestep_hooks: list[Callable[[float], None]] = []
        self.paused = False
        self.target_rtf = target_rtf
        self.rtf = RtfMeter()
        self._pace_origin: tuple[float, float] | None = None
        self._since_watch = 0
        self._time_ns = 0
        self.steps = 0  # physics steps taken, never reset: measures time across resets
        # counts the changes of the model in place (gravity, the step, a recompile, collisions):
        # a copy of it (a controller worker's) is stale when this moved
        self.model_version = 0
        # the thread that last ran the loop (run): others reach MuJoCo through `work` (None: no
        # loop ever ran, so the thread that made the simulation steps it by hand)
        self.loop_thread: int | None = None
        self.outside: OutsideInput | None = None  # the last outside input (note_input)
        # a front end that serves a graph (ROS) sets this: a divergence an outside input caused
        # resets the world with a warning instead of ending the run (see _diverged)
        self.recover_outside = False
        self._step_ns = round(self.model.opt.timestep * NS)
        # counts what ends a stretch of single steps step() planned: a timer added or removed,
        # a reset, a new physics step, a recompile (each but the first also new forces)
        self._edits = 0
        link_of_body = {body: name for name, body in self.compiled.bodies.items()}
        self.watchdog = Watchdog(self.model, self.data, link_of_body, self._likely_cause)
        self.reset()

    def loop_elsewhere(self) -> bool:
        """True while another thread, alive, runs the loop: reach MuJoCo through `work.call`
        (else the caller is the only one stepping and may read the data directly)."""
        loop = self.loop_thread
        if loop is None or loop == threading.get_ident():
            return False
        return any(t.ident == loop for t in threading.enumerate())

    # ----- clock ---------------------------------------------------------------------------------
    @property
    def time(self) -> float:
        """Sim time, in seconds."""
        return self._time_ns / NS

    @property
    def time_ns(self) -> int:
        """Sim time in integer nanoseconds: what stamps and timers use."""
        return self._time_ns

    @property
    def timestep(self) -> float:
        """The physics step, in seconds."""
        return float(self.model.opt.timestep)

    def set_timestep(self, seconds: float) -> None:
        """Change the physics step; listeners (the controller manager) are told."""
        seconds = TIMESTEP.check(seconds, hint="Gazebo's default is 0.001")
        self.model.opt.timestep = seconds
        self.model_version += 1
        self._step_ns = round(seconds * NS)
        self._edits += 1
        for hook in self._timestep_hooks:
            hook(seconds)

    def on_timestep_change(self, hook: Callable[[float], None]) -> None:
        """Call `hook(seconds)` whenever the physics step changes."""
        self._timestep_hooks.append(hook)

    def on_reset(self, hook: Callable[[], None]) -> None:
        """Run `hook()` after every reset (controllers hold the new pose, timers restart)."""
        self._reset_hooks.append(hook)

    # ----- what runs between steps ------------------------------------------------------------------
    def add_periodic(self, period: float, callback: Callable[[Simulation], None]) -> Periodic:
        """Call `callback(sim)` every `period` s of sim time, first one period from now.
        Between calls MuJoCo steps in C, so a 50 Hz publisher costs nothing per step."""
        if not (period > 0 and math.isfinite(period)):
            raise InputError(f"period {number_text(period)} must be a finite number > 0")
        period_ns = max(1, round(period * NS))
        timer = Periodic(period_ns, callback, self._time_ns + period_ns)
        self.periodic.append(timer)
        self._edits += 1
        return timer

    def remove_periodic(self, timer: Periodic) -> None:
        """Stop a callback add_periodic started."""
        if timer in self.periodic:
            self.periodic.remove(timer)
            self._edits += 1

    def add_control(self, control: Control) -> None:
        """Run `control.update(sim)` whenever it is due (its wake_ns): a controller manager."""
        self.controls.append(control)

    def remove_control(self, control: Control) -> None:
        """Forget a control and the hooks it registered (a deleted robot's controllers)."""
        if control in self.controls:
            self.controls.remove(control)
        def kept(hook: object) -> bool:
            return getattr(hook, "__self__", None) is not control

        self._reset_hooks[:] = [h for h in self._reset_hooks if kept(h)]
        self._timestep_hooks[:] = [h for h in self._timestep_hooks if kept(h)]
        self._model_hooks[:] = [h for h in self._model_hooks if kept(h)]

    def _fire_due(self) -> None:
        # what is due now (step() inlines this with _steps_until_due: keep the three alike)
        now, half = self._time_ns, self._step_ns // 2
        if self.periodic:
            self._fire_timers(now, half)
        due = now + half
        for control in self.controls:
            if control.wake_ns <= due:
                control.update(self)
        forces = self.forces
        if forces.changed or forces.wrenches or forces.efforts:
            forces.apply(self.data, now, half)

    def _fire_timers(self, now: int, half: int) -> None:
        for timer in list(self.periodic):  # a callback may add or remove timers
            if now >= timer.next_ns - half:
                timer.next_ns += timer.period_ns
                if timer.next_ns < now - half:  # fell behind (a step longer than the period)
                    timer.next_ns = now + timer.period_ns
                timer.callback(self)

    def _steps_until_due(self) -> int:
        soonest = math.inf
        for timer in self.periodic:
            if timer.next_ns < soonest:
                soonest = timer.next_ns
        for control in self.controls:
            if control.wake_ns < soonest:
                soonest = control.wake_ns
        forces, now, step = self.forces, self._time_ns, self._step_ns
        if forces.changed or forces.wrenches or forces.efforts:
            soonest = min(soonest, forces.next_change_ns(now, step))
        if soonest <= now + step:  # due now or at the next step (the usual case below)
            return 1
        if soonest == math.inf:
            return _WATCH_EVERY
        return max(1, math.ceil((soonest - now) / step - 0.5))

    # ----- stepping ----------------------------------------------------------------------------------
    def step(self, n: int = 1) -> None:
        """Advance n physics steps (even when paused: this is Gazebo's step button)."""
        model, data = self.model, self.data
        remaining = int(n)
        inf, mj_step, controls = math.inf, mujoco.mj_step, self.controls
        fired = False  # what was due at `now` has run (the single steps below stopped after it)
        now, half = self._time_ns, self._step_ns // 2
        while remaining > 0:
            # _fire_due and _steps_until_due inlined (keep the three alike): with a controller at
            # the physics rate this runs every step, so what it costs is the framework's
            if fired:
                fired = False
            else:
                now, half = self._time_ns, self._step_ns // 2
                periodic = self.periodic
                if periodic:
                    for timer in periodic:
                        if now >= timer.next_ns - half:
                            self._fire_timers(now, half)
                            break
                due = now + half
                for control in controls:
                    if control.wake_ns <= due:
                        control.update(self)
            forces = self.forces
            if forces.changed or forces.wrenches or forces.efforts:
                forces.apply(self.data, now, half)
            timers_at = inf
            for timer in self.periodic:
                if timer.next_ns < timers_at:
                    timers_at = timer.next_ns
            soonest = timers_at
            for control in controls:
                if control.wake_ns < soonest:
                    soonest = control.wake_ns
            now, step_ns, forces = self._time_ns, self._step_ns, self.forces  # a callback may reset
            quiet = not (forces.changed or forces.wrenches or forces.efforts)
            if not quiet:
                soonest = min(soonest, forces.next_change_ns(now, step_ns))
            if soonest <= now + step_ns:  # due now or at the next step (the usual case below)
                chunk = 1
            else:
                chunk = min(remaining, _WATCH_EVERY - self._since_watch, _WATCH_EVERY
                            if soonest == inf else max(1, math.ceil((soonest - now) / step_ns - 0.5)))
            try:
                mj_step(model, data, chunk)
                self._time_ns += chunk * step_ns
                self.steps += chunk
                remaining -= chunk
                self._since_watch += chunk
                if chunk == 1 and quiet:
                    # single steps while only controls are due (a controller at the physics
                    # rate): the pass above less what cannot be due, until a timer is due, a
                    # control changes anything else (a force; `_edits`: timers, a reset, the
                    # step, the model) or the watchdog's turn comes; the same calls in the same
                    # order (tests/physics/test_step_stretches.py)
                    edits, half = self._edits, step_ns // 2
                    quiet_until = timers_at - half
                    while remaining > 0 and self._since_watch < _WATCH_EVERY:
                        now = self._time_ns
                        if now >= quiet_until:  # a timer is due: the full pass
                            break
                        due = now + half
                        for control in controls:
                            if control.wake_ns <= due:
                                control.update(self)
                        soonest = timers_at
                        for control in controls:
                            if control.wake_ns < soonest:
                                soonest = control.wake_ns
                        if soonest > now + step_ns or forces.changed or self._edits != edits:
                            fired = True  # the full pass plans from here
                            break
                        mj_step(model, data, 1)
                        self._time_ns += step_ns
                        self.steps += 1
                        remaining -= 1
                        self._since_watch += 1
            except mujoco.FatalError as exc:  # e.g. out of constraint memory: a one-line error
                cause = self._outside_cause()
                self._diverged(DivergenceError(
                    f"MuJoCo stopped at t = {self.time:.3f} s: {' '.join(str(exc).split())}",
                    hint=f"likely cause: {cause}" if cause else "a model this big or this stiff "
                    "needs 'mexone check' and a smaller time step"))
                model, data = self.model, self.data
                continue
            if self._since_watch >= _WATCH_EVERY:
                self._since_watch = 0
                try:
                    self.watchdog.check()
                except DivergenceError as exc:
                    self._diverged(exc)
                    model, data = self.model, self.data
        self._fire_due()

    # ----- outside inputs -----------------------------------------------------------------------
    def note_input(self, what: str, undo: Callable[[], None] | None = None) -> None:
        """An input from outside the lab (a ROS service call, an action goal, a command) was just
        applied: a divergence within OUTSIDE_WINDOW s names it as the likely cause and, with
        recover_outside, `undo()` runs and the world is reset instead of the run ending."""
        self.outside = OutsideInput(what, self.steps, undo)

    def recent_input(self) -> OutsideInput | None:
        """The last outside input if it came within OUTSIDE_WINDOW s of sim time."""
        outside = self.outside
        if outside is None or (self.steps - outside.step) * self.timestep > OUTSIDE_WINDOW:
            return None
        return outside

    def _outside_cause(self) -> str | None:
        outside = self.recent_input()
        if outside is None:
            return None
        ago = (self.steps - outside.step) * self.timestep
        return f"the outside input {outside.what}, {ago:.3f} s of sim time before"

    def _diverged(self, error: DivergenceError) -> None:
        """Raise `error`, unless an outside input caused it and recover_outside is set: then
        that input is undone where it lasts (physics settings, gains), the world is reset as
        Gazebo's reset_world does, a warning says why, and the run goes on. No input from the
        graph may end the simulation; a model that diverges on its own still stops it."""
        outside = self.recent_input()
        if outside is None or not self.recover_outside:
            raise error
        self.outside = None
        undone = ""
        if outside.undo is not None:
            try:
                outside.undo()
                undone = " it was undone and"
            except Exception as exc:  # noqa: BLE001 - the reset below still saves the run
                log.warning("could not undo %s: %s", outside.what, exc)
        log.warning("%s;%s the world was reset (as /gazebo/reset_world) so the simulation goes on",
                    error.one_line(), undone)
        self.reset()

    def run(self, duration: float, on_tick: Callable[[Simulation], None] | None = None,
            tick: float = 0.05, gate: Gate | None = None,
            until: Callable[[], bool] | None = None) -> float:
        """Simulate up to `duration` s of sim time, paced to target_rtf if set; return the sim
        time simulated. on_tick(sim) runs every `tick` s of sim time and every 10 ms of wall
        time while paused; `work` is drained at the same moments. `gate` holds the clock for code
        running in lockstep with sim time (routines): when it is busy the run returns early, so
        the caller stays responsive. `until()` true ends the run early. Progress is counted in
        steps, so a reset during the run (a service call, a button) restarts nothing."""
        self.loop_thread = threading.get_ident()
        with REAL_TIME_GC:  # older generations collected between ticks, not in a control step
            return self._run(duration, on_tick, tick, gate, until)

    def _run(self, duration: float, on_tick: Callable[[Simulation], None] | None, tick: float,
             gate: Gate | None, until: Callable[[], bool] | None) -> float:
        budget = math.inf if duration == math.inf else round(duration * NS)
        tick_ns = max(1, round(tick * NS))
        done = 0
        next_tick = tick_ns
        while done < budget - self._step_ns // 2 and not (until and until()):
            self.work.drain()
            if self.paused:  # on_tick still runs: it may be what resumes us (a ROS service)
                REAL_TIME_GC.idle()
                time.sleep(0.01)
                self._pace_origin = None
                if on_tick:
                    on_tick(self)
                continue
            n = max(1, math.ceil((min(budget, next_tick) - done) / self._step_ns - 0.5))
            if gate is not None:
                horizon = gate.horizon()
                if horizon is None or (until and until()):  # busy, or what it waited for ended us
                    break
                wait = round(horizon * NS) - self._time_ns if horizon != math.inf else math.inf
                if wait <= 0:  # someone wakes now: let it run first
                    gate.advance(self.time)
                    continue
                n = min(n, self._steps_until_due())
                if wait != math.inf:  # up to the first step at or after the wake-up, as rospy
                    n = min(n, -(-wait // self._step_ns))
            self.step(n)
            done += n * self._step_ns
            if gate is not None:
                gate.advance(self.time)
            if done >= next_tick - self._step_ns // 2:
                next_tick += tick_ns
                REAL_TIME_GC.idle()  # before the pacing: its sleep absorbs the collection
                self._pace()
                if on_tick:
                    on_tick(self)
        return done / NS

    def _pace(self) -> None:
        wall = time.perf_counter()
        self.rtf.add(wall, self.time)
        if not self.target_rtf:
            return
        if self._pace_origin is None:
            self._pace_origin = (wall, self.time)
            return
        wall0, sim0 = self._pace_origin
        ahead = wall0 + (self.time - sim0) / self.target_rtf - wall
        if ahead > 0:
            time.sleep(ahead)
        elif ahead < -0.25:  # fell behind (slow machine): do not try to catch up in a burst
            self._pace_origin = (wall, self.time)

    def pause(self) -> None:
        """Pause: run() and the page's loop stop advancing sim time."""
        self.paused = True

    def resume(self) -> None:
        """Resume after pause; the pacing starts again from now."""
        self.paused = False
        self._pace_origin = None

    def reset(self) -> None:
        """Back to the spawn pose with every joint at 0 (home) or its initial position (-J), sim
        time 0; pushes and efforts end; timers restart from there and reset hooks run
        (controllers hold that pose)."""
        if self.compiled.spawn_key is None:  # pushes (xfrc_applied) end too
            mujoco.mj_resetData(self.model, self.data)
        else:  # the initial joint positions (-J, --pose)
            mujoco.mj_resetDataKeyframe(self.model, self.data, self.compiled.spawn_key)
        self.forces = Forces()
        mujoco.mj_forward(self.model, self.data)
        self._time_ns = 0
        self.rtf.clear()
        self._pace_origin = None
        self._since_watch = _WATCH_EVERY - _FIRST_WATCH  # a run's first check comes early
        for timer in self.periodic:
            timer.next_ns = timer.period_ns
        self._edits += 1
        for hook in self._reset_hooks:
            hook()

    # ----- models in the world -------------------------------------------------------------------
    def on_model_change(self, hook: Callable[[], None]) -> None:
        """Run `hook()` after a model was added or removed (sim.model and sim.data are new)."""
        self._model_hooks.append(hook)

    def add_model(self, robot: RobotModel | Path | str, name: str | None = None,
                  spawn: Spawn = Spawn(on_ground=False), edits: Sequence[SpecEdit] = ()) -> str:
        """Add another model (a box, a ball, a second robot) to the running world, touching the
        ground and the robot; returns its name. The robot's ids stay. `edits` change its spec
        before it is attached (a second robot's actuators): then its links keep their own
        collision rules (selfCollide), as the robot's do."""
        if not isinstance(robot, RobotModel):
            robot = load_model(robot)
        name = name or robot.name
        if name == self.robot.name or name in self.models:
            raise InputError(f"a model named '{name}' already exists", hint="pick another name")
        self.models[name] = attach_model(self.compiled.spec, robot, name, self.compiled.world,
                                         spawn, edits, touch_all=not edits)
        try:
            self._recompile()
        except ValueError as exc:
            del self.models[name]
            detach_model(self.compiled.spec, name)
            raise InputError(f"MuJoCo cannot add '{name}': {' '.join(str(exc).split())}") from None
        return name

    def remove_model(self, name: str) -> None:
        """Delete a model add_model spawned (its controllers leave with it)."""
        if name == self.robot.name:
            raise InputError(f"'{name}' is the simulated robot; it cannot be deleted",
                             hint="delete models you spawned")
        if name not in self.models:
            raise InputError(f"no model named '{name}'", hint="models: " + ", ".join(self.models))
        detach_model(self.compiled.spec, name)
        del self.models[name]
        self._recompile()

    def _recompile(self) -> None:
        old = self.model
        model, data = self.compiled.spec.recompile(self.model, self.data)
        carry_over(old, model)
        model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_AUTORESET
        self.model = self.compiled.model = model
        self.model_version += 1
        self.data = data
        mujoco.mj_forward(model, data)
        suspects = self.watchdog.suspects
        self.watchdog = Watchdog(model, data, self.watchdog.link_names, self._likely_cause)
        self.watchdog.suspects.extend(suspects)
        self.forces = Forces()
        self._edits += 1
        for hook in self._model_hooks:
            hook()

    def set_self_collision(self, on: bool | None) -> None:
        """Links collide with each other (True), never (False), or as each link's <gazebo
        selfCollide> says (None): Gazebo's physics setting, applied to the running model."""
        for link in self.compiled.bodies:
            contype, conaffinity = collision_bits(self.robot, link, on)
            for i in range(len(self.robot.links[link].collisions)):
                geom = self.model.geom(f"{link}/collision/{i}").id
                self.model.geom_contype[geom] = contype
                self.model.geom_conaffinity[geom] = conaffinity
        self.model_version += 1

    # ----- joints -------------------------------------------------------------------------------
    def _vector(self, values: Mapping[str, float] | Sequence[float] | np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
        """(values, given): a full-length vector and which entries the caller set."""
        n = len(self.joint_names)
        if isinstance(values, Mapping):
            out, given = np.zeros(n), np.zeros(n, dtype=bool)
            for name, value in values.items():
                if name not in self._index:
                    raise InputError(f"no moving joint named '{name}'",
                                     hint="joints: " + ", ".join(self.joint_names))
                out[self._index[name]] = value
                given[self._index[name]] = True
        else:
            out, given = np.asarray(values, dtype=float), np.ones(n, dtype=bool)
            if out.shape != (n,):
                raise InputError(f"expected {n} joint values, got shape {out.shape}")
        if not np.isfinite(out[given]).all():
            bad = [self.joint_names[i] for i in np.flatnonzero(given & ~np.isfinite(out))]
            raise InputError(f"value for {', '.join(bad)} is not finite", hint="send finite numbers")
        return out, given

    def joint_positions(self) -> np.ndarray:
        """Every moving joint's position now (joint_names order)."""
        return self.data.qpos[self.compiled.qpos_adr].copy()

    def joint_velocities(self) -> np.ndarray:
        """Every moving joint's velocity now (joint_names order)."""
        return self.data.qvel[self.compiled.dof_adr].copy()

    def joint_efforts(self) -> np.ndarray:
        """Torque (or force) each joint received from its motors and from applied efforts."""
        dofs = self.compiled.dof_adr
        return self.data.qfrc_applied[dofs] + self.data.qfrc_actuator[dofs]

    def set_joint_positions(self, values: Mapping[str, float] | Sequence[float]) -> None:
        """Teleport joints (velocities zeroed): for setting up experiments, not for control."""
        vec, given = self._vector(values)
        self.data.qpos[self.compiled.qpos_adr[given]] = vec[given]
        self.data.qvel[self.compiled.dof_adr[given]] = 0.0
        mujoco.mj_forward(self.model, self.data)

    def set_state(self, qpos: ArrayLike | None = None, qvel: ArrayLike | None = None) -> None:
        """The generalized positions (nq) and velocities (nv) at once, as computed by a front end
        that places the robot itself (a design check's deviation, a recording's first instant);
        None keeps that part. Forward kinematics follow. Simulation thread only."""
        for name, values, size in (("qpos", qpos, self.model.nq), ("qvel", qvel, self.model.nv)):
            if values is None:
                continue
            array = np.asarray(values, dtype=float).reshape(-1)
            if array.shape != (size,) or not np.isfinite(array).all():
                raise InputError(f"{name} must be {size} finite numbers")
            getattr(self.data, name)[:] = array
        mujoco.mj_forward(self.model, self.data)
        self.watchdog.forget()

    def within_limits(self, values: Mapping[str, float]) -> tuple[dict[str, float], list[str]]:
        """`values` clamped to each joint's URDF limits (revolute and prismatic joints), and a
        note per clamped joint ("l_elbow 100 -> 0.1"): a teleport beyond a limit would have the
        limit's constraint fling the link back, faster than physics allows."""
        out, notes = {}, []
        for name, value in values.items():
            joint = self.robot.joints.get(name)
            limit = joint.limit if joint is not None and joint.type in ("revolute", "prismatic") \
                else None
            clamped = float(value) if limit is None else min(max(float(value), limit.lower),
                                                             limit.upper)
            if clamped != value:
                notes.append(f"{name} {number_text(value)} -> {number_text(clamped)}")
            out[name] = clamped
        return out, notes

    # ----- links --------------------------------------------------------------------------------
    def body_id(self, link: str) -> int:
        """The MuJoCo body of a robot link, or of any body by its MuJoCo name (spawned models)."""
        body = self.compiled.bodies.get(link)
        if body is not None:
            return body
        found = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, link) if link else -1
        if found <= 0:
            raise InputError(f"no link named '{link}'", hint="links: " + ", ".join(self.compiled.bodies))
        return found

    def link_pose(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        """World position and (w, x, y, z) quaternion of a link frame."""
        body = self.body_id(link)
        return self.data.xpos[body].copy(), self.data.xquat[body].copy()

    def link_velocity(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        """Linear velocity of a link frame's origin and angular velocity, both in the world frame."""
        out = np.zeros(6)
        mujoco.mj_objectVelocity(self.model, self.data, mujoco.mjtObj.mjOBJ_BODY, self.body_id(link),
                                 out, 0)
        return out[3:].copy(), out[:3].copy()

    def set_free_body(self, link: str, position: Sequence[float], quaternion: Sequence[float],
                      linear: Sequence[float] = (0, 0, 0), angular: Sequence[float] = (0, 0, 0)) -> None:
        """Teleport a floating body (the robot's base, a spawned model): pose, and linear and angular
        velocity in the world frame (Gazebo's set_model_state)."""
        body = self.body_id(link)
        joint = self.model.body_jntadr[body]
        if joint < 0 or self.model.jnt_type[joint] != mujoco.mjtJoint.mjJNT_FREE:
            raise InputError(f"'{link}' is welded to the world or to another link, so it cannot be "
                             "placed", hint="place the model's floating root link")
        values = np.r_[position, quaternion, linear, angular].astype(float)
        if values.shape != (13,) or not np.isfinite(values).all():
            raise InputError("pose and twist must be 3 + 4 + 3 + 3 finite numbers")
        quat = values[3:7]
        if np.linalg.norm(quat) < 1e-9:
            raise InputError("orientation quaternion is zero", hint="use w = 1 for no rotation")
        q, v = self.model.jnt_qposadr[joint], self.model.jnt_dofadr[joint]
        self.data.qpos[q:q + 3] = values[:3]
        self.data.qpos[q + 3:q + 7] = quat / np.linalg.norm(quat)
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, self.data.qpos[q + 3:q + 7])
        self.data.qvel[v:v + 3] = values[7:10]
        self.data.qvel[v + 3:v + 6] = rot.reshape(3, 3).T @ values[10:13]  # MuJoCo: body frame
        mujoco.mj_forward(self.model, self.data)
        self.watchdog.forget()

    def _duration_ns(self, duration: float | None, start: float | None) -> tuple[int, float]:
        """(start, end) in sim ns: from `start` (or now, if earlier or None) for `duration` s;
        a negative or None duration lasts until cleared, as in Gazebo."""
        if (duration is not None and math.isnan(duration)) or \
                (start is not None and not math.isfinite(start)):
            raise InputError("start time and duration must be numbers",
                             hint="a duration < 0 lasts until cleared")
        begin = self._time_ns if start is None else max(self._time_ns, round(start * NS))
        if duration is None or duration < 0 or duration == math.inf:
            return begin, FOREVER
        return begin, begin + round(duration * NS)

    def apply_wrench(self, link: str, force: Sequence[float] | np.ndarray,
                     torque: Sequence[float] = (0, 0, 0),
                     point: Sequence[float] | None = None, frame: str = "world",
                     duration: float | None = None, start: float | None = None) -> None:
        """Push a link: `force` (N) and `torque` (N m) expressed in `frame` ("world" or a link),
        the force acting at `point` in that frame (default: the pushed link's centre of mass), for
        `duration` s of sim time from `start` (default now; None or < 0: until cleared).
        Several wrenches add up. Simulation thread only."""
        body = self.body_id(link)
        frame_body = -1 if frame in ("", "world", "map", "/map") else self.body_id(frame)
        values = np.r_[force, torque].astype(float)
        if values.shape != (6,) or not np.isfinite(values).all():
            raise InputError("force and torque must be 3 finite numbers each")
        if point is None:  # the link's centre of mass, written in the frame's coordinates
            rot = np.eye(3) if frame_body < 0 else self.data.xmat[frame_body].reshape(3, 3)
            origin = np.zeros(3) if frame_body < 0 else self.data.xpos[frame_body]
            point = rot.T @ (self.data.xipos[body] - origin)
        at = np.asarray(point, dtype=float)
        if at.shape != (3,) or not np.isfinite(at).all():
            raise InputError("application point must be 3 finite numbers")
        if frame_body < 0:  # a world-frame push stays where it was put on the body
            frame_body, rot = body, self.data.xmat[body].reshape(3, 3)
            at = rot.T @ (at - self.data.xpos[body])
            values = np.r_[rot.T @ values[:3], rot.T @ values[3:]]
            world_fixed = True
        else:
            world_fixed = False
        begin, end = self._duration_ns(duration, start)
        wrench = Wrench(body, values[:3], values[3:], at, frame_body, begin, end)
        if world_fixed:  # force and torque keep their world direction as the body turns
            wrench = _WorldWrench.of(wrench, self.data)
        self.forces.wrenches.append(wrench)
        self.forces.changed = True

    def clear_wrenches(self, link: str | None = None) -> int:
        """Remove the wrenches on `link` (every link if None); returns how many."""
        return self.forces.clear_body(None if link is None else self.body_id(link))

    def apply_joint_effort(self, joint: str, effort: float, duration: float | None = None,
                           start: float | None = None) -> None:
        """Add `effort` (N m or N) to a joint for `duration` s of sim time (Gazebo's
        apply_joint_effort); motors and other efforts add to it."""
        dof = self._dof(joint)
        if not math.isfinite(effort):
            raise InputError(f"effort {number_text(effort)} is not finite")
        begin, end = self._duration_ns(duration, start)
        self.forces.efforts.append(JointEffort(dof, float(effort), begin, end))
        self.forces.changed = True

    def clear_joint_efforts(self, joint: str | None = None) -> int:
        """End the efforts applied to `joint` (every joint: None); how many ended."""
        return self.forces.clear_joint(None if joint is None else self._dof(joint))

    def _dof(self, joint: str) -> int:
        if joint not in self._index:
            raise InputError(f"no moving joint named '{joint}'",
                             hint="joints: " + ", ".join(self.joint_names))
        return int(self.compiled.dof_adr[self._index[joint]])

    @property
    def gravity(self) -> np.ndarray:
        """Gravity now, (x, y, z) in m/s^2."""
        return self.model.opt.gravity.copy()

    def set_gravity(self, gravity: Sequence[float]) -> None:
        """Change gravity at once (x, y, z in m/s^2; ranges.GRAVITY)."""
        try:
            values = np.asarray(gravity, dtype=float)
        except (TypeError, ValueError):
            raise InputError("gravity must be 3 numbers (x y z, m/s^2)") from None
        if values.shape != (3,):
            raise InputError(f"gravity must be 3 numbers (x y z, m/s^2), not {values.size}")
        self.model.opt.gravity[:] = GRAVITY.check_all(values.tolist())
        self.model_version += 1

    def link_speeds(self) -> np.ndarray:
        """Linear speed of each link's centre of mass, in the order of compiled.bodies."""
        linear, _ = link_speeds(self.model, self.data)
        return linear[list(self.compiled.bodies.values())]

    @property
    def base_height(self) -> float:
        """The root link's height (z in the world frame), in m."""
        return float(self.data.xpos[self.compiled.root_body][2])

    @property
    def base_tilt(self) -> float:
        """Angle (rad) between the base's z axis and the world's vertical."""
        cos = float(self.data.xmat[self.compiled.root_body, 8])  # the rotation's (2, 2)
        return float(np.arccos(min(1.0, max(-1.0, cos))))  # no np.clip: logged at 100 Hz

    def _likely_cause(self, link: str) -> str | None:
        """The outside input just before it, else the lint finding that explains a divergence:
        on that link first, else anywhere."""
        outside = self._outside_cause()
        if outside is not None:
            return outside
        suspects = [f for f in check_model(self.robot) if f.code in _LINT_CAUSES]
        suspects.sort(key=lambda f: f.element != f'link "{link}"')
        if not suspects:
            return None
        first = suspects[0]
        return f"{first.element} {_LINT_CAUSES[first.code]} (mexone check: {first.code})"


class _WorldWrench(Wrench):
    """A wrench whose force and torque keep their world direction while its point rides the body."""

    @classmethod
    def of(cls, wrench: Wrench, data: mujoco.MjData) -> _WorldWrench:
        rot = data.xmat[wrench.body].reshape(3, 3)
        return cls(wrench.body, rot @ wrench.force, rot @ wrench.torque, wrench.point,
                   wrench.frame_body, wrench.start_ns, wrench.end_ns)

    def world(self, data: mujoco.MjData) -> np.ndarray:
        rot = data.xmat[self.body].reshape(3, 3)
        at = data.xpos[self.body] + rot @ self.point
        return np.r_[self.force, self.torque + np.cross(at - data.xipos[self.body], self.force)]
