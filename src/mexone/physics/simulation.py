"""Simulation: one robot in one world, stepped in sim time, paced to wall time when asked.

The simulation thread owns MuJoCo. Other threads hand work over (`work.put`) and the loop that
steps the simulation runs it between steps. The control layer plugs in as a `Control` (ros2_control's
read -> update -> write loop), which the simulation runs before a step whenever the control asks
for it (a command is waiting, or a controller needs its period). With nothing to do, MuJoCo steps
many times per call, so a headless run costs what bare MuJoCo costs.

Sim time is kept as integer nanoseconds, so stamps and timers never drift by float rounding.
"""

from __future__ import annotations

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

from mexone.description.check import check_model
from mexone.description.loader import load_model
from mexone.description.model import RobotModel
from mexone.errors import InputError
from mexone.physics.compile import (
    Compiled,
    CompileOptions,
    Spawn,
    SpecEdit,
    collision_bits,
    compile_model,
)
from mexone.physics.watchdog import DivergenceError, Watchdog, link_speeds
from mexone.physics.world import World

__all__ = ["Simulation", "RtfMeter", "Periodic", "Gate", "Control", "WorkQueue", "NS",
           "MIN_TIMESTEP", "MAX_TIMESTEP"]

NS = 1_000_000_000
MIN_TIMESTEP, MAX_TIMESTEP = 1e-5, 0.01  # s: what a humanoid lab can sensibly step with
# steps between divergence checks: a diverging run goes NaN within steps, so 50 ms still names the
# link that went first; each check is a Python interlude that costs MuJoCo its warm caches
_WATCH_EVERY = 50
_FIRST_WATCH = 10  # steps after a reset to the first check: a bad start shows at once
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
        self._items: queue.SimpleQueue[tuple[Callable[[], Any], threading.Event | None, list]] = \
            queue.SimpleQueue()

    def put(self, fn: Callable[[], Any]) -> None:
        self._items.put((fn, None, []))

    def call(self, fn: Callable[[], Any], timeout: float = 10.0) -> Any:
        """Run `fn` in the simulation thread and wait for its result (its exception re-raised)."""
        done, box = threading.Event(), []
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

    def __init__(self, window: float = 1.0):
        self.window = window
        self.samples: deque[tuple[float, float]] = deque()

    def add(self, wall: float, sim: float) -> None:
        self.samples.append((wall, sim))
        while len(self.samples) > 2 and wall - self.samples[0][0] > self.window:
            self.samples.popleft()

    def clear(self) -> None:
        self.samples.clear()

    @property
    def value(self) -> float:
        if len(self.samples) < 2:
            return 0.0
        (w0, s0), (w1, s1) = self.samples[0], self.samples[-1]
        return (s1 - s0) / (w1 - w0) if w1 > w0 else 0.0


class Simulation:
    def __init__(self, robot: RobotModel | Path | str, world: World | None = None,
                 spawn: Spawn = Spawn(), options: CompileOptions = CompileOptions(),
                 target_rtf: float | None = None, edits: Sequence[SpecEdit] = ()):
        if not isinstance(robot, RobotModel):
            robot = load_model(robot)
        self.robot = robot
        self.compiled: Compiled = compile_model(robot, world, spawn, options, edits)
        self.model = self.compiled.model
        self.model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_AUTORESET  # the watchdog reports
        self.data = mujoco.MjData(self.model)
        self.joint_names = list(self.compiled.joints)
        self._index = {name: i for i, name in enumerate(self.joint_names)}
        self._effort_limit = np.array([j.limit.effort if j.limit and j.limit.effort > 0 else np.inf
                                       for j in robot.moving_joints])
        self._efforts = np.zeros(len(self.joint_names))
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
        self._resets = 0
        self._step_ns = round(self.model.opt.timestep * NS)
        link_of_body = {body: name for name, body in self.compiled.bodies.items()}
        self.watchdog = Watchdog(self.model, self.data, link_of_body, self._likely_cause)
        self.reset()

    # ----- clock ---------------------------------------------------------------------------------
    @property
    def time(self) -> float:
        return self._time_ns / NS

    @property
    def time_ns(self) -> int:
        """Sim time in integer nanoseconds: what stamps and timers use."""
        return self._time_ns

    @property
    def timestep(self) -> float:
        return float(self.model.opt.timestep)

    def set_timestep(self, seconds: float) -> None:
        """Change the physics step; listeners (the controller manager) are told."""
        if not MIN_TIMESTEP <= seconds <= MAX_TIMESTEP:  # also refuses NaN
            raise InputError(f"time step {seconds:g} s is out of range",
                             hint=f"use {MIN_TIMESTEP:g} to {MAX_TIMESTEP:g} s")
        self.model.opt.timestep = seconds
        self._step_ns = round(seconds * NS)
        for hook in self._timestep_hooks:
            hook(seconds)

    def on_timestep_change(self, hook: Callable[[float], None]) -> None:
        self._timestep_hooks.append(hook)

    def on_reset(self, hook: Callable[[], None]) -> None:
        """Run `hook()` after every reset (controllers hold the new pose, timers restart)."""
        self._reset_hooks.append(hook)

    # ----- what runs between steps ------------------------------------------------------------------
    def add_periodic(self, period: float, callback: Callable[[Simulation], None]) -> Periodic:
        """Call `callback(sim)` every `period` s of sim time, first one period from now.
        Between calls MuJoCo steps in C, so a 50 Hz publisher costs nothing per step."""
        if not (period > 0 and math.isfinite(period)):
            raise InputError(f"period {period} must be a finite number > 0")
        period_ns = max(1, round(period * NS))
        timer = Periodic(period_ns, callback, self._time_ns + period_ns)
        self.periodic.append(timer)
        return timer

    def remove_periodic(self, timer: Periodic) -> None:
        if timer in self.periodic:
            self.periodic.remove(timer)

    def add_control(self, control: Control) -> None:
        self.controls.append(control)

    def _fire_due(self) -> None:
        now, half = self._time_ns, self._step_ns // 2
        for timer in list(self.periodic):
            if now >= timer.next_ns - half:
                timer.next_ns += timer.period_ns
                if timer.next_ns < now - half:  # fell behind (a step longer than the period)
                    timer.next_ns = now + timer.period_ns
                timer.callback(self)
        for control in self.controls:
            if control.wake_ns <= now + half:
                control.update(self)

    def _steps_until_due(self) -> int:
        soonest = min([t.next_ns for t in self.periodic] + [c.wake_ns for c in self.controls],
                      default=math.inf)
        if soonest == math.inf:
            return _WATCH_EVERY
        if soonest <= self._time_ns:
            return 1
        return max(1, math.ceil((soonest - self._time_ns) / self._step_ns - 0.5))

    # ----- stepping ----------------------------------------------------------------------------------
    def step(self, n: int = 1) -> None:
        """Advance n physics steps (even when paused: this is Gazebo's step button)."""
        model, data = self.model, self.data
        remaining = int(n)
        while remaining > 0:
            self._fire_due()
            chunk = min(remaining, _WATCH_EVERY - self._since_watch, self._steps_until_due())
            try:
                mujoco.mj_step(model, data, chunk)
            except mujoco.FatalError as exc:  # e.g. out of constraint memory: a one-line error
                raise DivergenceError(f"MuJoCo stopped at t = {self.time:.3f} s: "
                                      f"{' '.join(str(exc).split())}",
                                      hint="a model this big or this stiff needs 'mexone check' "
                                           "and a smaller time step") from None
            self._time_ns += chunk * self._step_ns
            remaining -= chunk
            self._since_watch += chunk
            if self._since_watch >= _WATCH_EVERY:
                self._since_watch = 0
                self.watchdog.check()
        self._fire_due()

    def run(self, duration: float, on_tick: Callable[[Simulation], None] | None = None,
            tick: float = 0.05, gate: Gate | None = None,
            until: Callable[[], bool] | None = None) -> float:
        """Simulate up to `duration` s of sim time, paced to target_rtf if set; return the sim
        time simulated. on_tick(sim) runs every `tick` s of sim time and every 10 ms of wall
        time while paused; `work` is drained at the same moments. `gate` holds the clock for code
        running in lockstep with sim time (routines): when it is busy the run returns early, so
        the caller stays responsive. `until()` true ends the run early. Progress is counted in
        steps, so a reset during the run (a service call, a button) restarts nothing."""
        budget = math.inf if duration == math.inf else round(duration * NS)
        tick_ns = max(1, round(tick * NS))
        done = 0
        next_tick = tick_ns
        while done < budget - self._step_ns // 2 and not (until and until()):
            self.work.drain()
            if self.paused:  # on_tick still runs: it may be what resumes us (a ROS service)
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
        self.paused = True

    def resume(self) -> None:
        self.paused = False
        self._pace_origin = None

    def reset(self) -> None:
        """Back to the spawn pose with every joint at 0 (home) or its initial position (-J), sim
        time 0; timers restart from there and reset hooks run (controllers hold that pose)."""
        if self.compiled.spawn_key is None:  # pushes (xfrc_applied) end too
            mujoco.mj_resetData(self.model, self.data)
        else:  # the initial joint positions (-J, --pose)
            mujoco.mj_resetDataKeyframe(self.model, self.data, self.compiled.spawn_key)
        self._resets += 1
        self._efforts[:] = 0.0
        mujoco.mj_forward(self.model, self.data)
        self._time_ns = 0
        self.rtf.clear()
        self._pace_origin = None
        self._since_watch = _WATCH_EVERY - _FIRST_WATCH  # a run's first check comes early
        for timer in self.periodic:
            timer.next_ns = timer.period_ns
        for hook in self._reset_hooks:
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
        return self.data.qpos[self.compiled.qpos_adr].copy()

    def joint_velocities(self) -> np.ndarray:
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

    def apply_efforts(self, values: Mapping[str, float] | Sequence[float]) -> None:
        """Joint-space efforts pushed straight onto the joints (Gazebo's Joint::SetForce, clamped to
        the URDF effort limit as Gazebo clamps it), held until changed. Motors add to them."""
        vec, given = self._vector(values)
        self._efforts[given] = np.clip(vec[given], -self._effort_limit[given],
                                       self._effort_limit[given])
        self.data.qfrc_applied[self.compiled.dof_adr] = self._efforts

    # ----- links --------------------------------------------------------------------------------
    def link_pose(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        """World position and (w, x, y, z) quaternion of a link frame."""
        body = self.compiled.bodies.get(link)
        if body is None:
            raise InputError(f"no link named '{link}'", hint="links: " + ", ".join(self.compiled.bodies))
        return self.data.xpos[body].copy(), self.data.xquat[body].copy()

    def apply_wrench(self, link: str, force: Sequence[float], torque: Sequence[float] = (0, 0, 0),
                     point: Sequence[float] | None = None, duration: float = 0.1) -> None:
        """Push `link` with a world-frame `force` (N) acting at the world `point` (default: its
        centre of mass) plus `torque` (N m), for `duration` s of sim time; pushes add up and a
        reset ends them. Simulation thread only (Gazebo's apply_body_wrench, the GUI's push)."""
        body = self.compiled.bodies.get(link)
        if body is None:
            raise InputError(f"no link named '{link}'", hint="links: " + ", ".join(self.compiled.bodies))
        at = self.data.xipos[body] if point is None else np.asarray(point, dtype=float)
        wrench = np.r_[np.asarray(force, dtype=float), np.asarray(torque, dtype=float)]
        if wrench.shape != (6,) or at.shape != (3,) or not np.isfinite(np.r_[wrench, at]).all():
            raise InputError(f"push on '{link}': force, torque and point must be 3 finite numbers each")
        if not (duration > 0 and math.isfinite(duration)):
            raise InputError(f"push on '{link}': duration {duration} must be a finite number > 0 s")
        wrench[3:] += np.cross(at - self.data.xipos[body], wrench[:3])  # moved to the COM
        self.data.xfrc_applied[body] += wrench
        start = self._resets

        def release(sim: Simulation) -> None:
            if sim._resets == start:  # a reset zeroed xfrc_applied already
                sim.data.xfrc_applied[body] -= wrench
            sim.remove_periodic(timer)

        timer = self.add_periodic(duration, release)

    def link_speeds(self) -> np.ndarray:
        """Linear speed of each link's centre of mass, in the order of compiled.bodies."""
        linear, _ = link_speeds(self.model, self.data)
        return linear[list(self.compiled.bodies.values())]

    @property
    def base_height(self) -> float:
        return float(self.data.xpos[self.compiled.root_body][2])

    @property
    def base_tilt(self) -> float:
        """Angle (rad) between the base's z axis and the world's vertical."""
        rot = self.data.xmat[self.compiled.root_body].reshape(3, 3)
        return float(np.arccos(np.clip(rot[2, 2], -1.0, 1.0)))

    def _likely_cause(self, link: str) -> str | None:
        """The lint finding that explains a divergence: on that link first, else anywhere."""
        suspects = [f for f in check_model(self.robot) if f.code in _LINT_CAUSES]
        suspects.sort(key=lambda f: f.element != f'link "{link}"')
        if not suspects:
            return None
        first = suspects[0]
        return f"{first.element} {_LINT_CAUSES[first.code]} (mexone check: {first.code})"
