"""Simulation: one robot in one world, stepped in sim time, paced to wall time when asked.

The control layer hooks in with ``add_hook``: each hook runs before every physics step (read
-> update -> write, as ros_control's loop in gazebo_ros_control). With no hooks, MuJoCo steps
many times per call, so a headless run costs what bare MuJoCo costs.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import mujoco
import numpy as np

from mexone.description.check import check_model
from mexone.description.loader import load_model
from mexone.description.model import RobotModel
from mexone.errors import InputError
from mexone.physics.compile import Compiled, CompileOptions, Spawn, compile_model
from mexone.physics.watchdog import Watchdog, link_speeds
from mexone.physics.world import World

__all__ = ["Simulation", "RtfMeter", "Periodic", "Gate"]

_WATCH_EVERY = 10  # steps between divergence checks: divergence grows fast, 10 ms catches it
_LINT_CAUSES = {"com-outside": "its centre of mass lies outside its geometry",
                "inertia-too-large": "its inertia is implausibly large for its mass and size",
                "inertia-triangle": "its inertia is physically impossible",
                "inertia-not-positive": "its inertia is not positive definite",
                "mass-nonpositive": "it has no mass",
                "dynamics-negative": "a joint has negative damping or friction, which adds energy"}


class Gate(Protocol):
    """Lockstep with code waiting on sim time (see mexone.routines.runtime.Scheduler)."""

    def horizon(self) -> float: ...  # block until nobody runs; the earliest wake-up time

    def advance(self, sim_time: float) -> None: ...  # time moved on: wake whoever is due


@dataclass
class Periodic:
    period: float
    callback: Callable[[Simulation], None]
    next_time: float


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
                 target_rtf: float | None = None):
        if not isinstance(robot, RobotModel):
            robot = load_model(robot)
        self.robot = robot
        self.compiled: Compiled = compile_model(robot, world, spawn, options)
        self.model = self.compiled.model
        self.model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_AUTORESET  # the watchdog reports
        self.data = mujoco.MjData(self.model)
        self.joint_names = list(self.compiled.joints)
        self._index = {name: i for i, name in enumerate(self.joint_names)}
        self._actuated = np.array([self._index[j] for j in self.compiled.actuated], dtype=int)
        passive = sorted(set(range(len(self.joint_names))) - set(self._actuated.tolist()))
        self._passive = np.array(passive, dtype=int)
        self._efforts = np.zeros(len(self.joint_names))
        self.hooks: list[Callable[[Simulation], None]] = []
        self.periodic: list[Periodic] = []
        self.controllers_active = False
        self.paused = False
        self.target_rtf = target_rtf
        self.rtf = RtfMeter()
        self._pace_origin: tuple[float, float] | None = None
        self._since_watch = 0
        link_of_body = {body: name for name, body in self.compiled.bodies.items()}
        self.watchdog = Watchdog(self.model, self.data, link_of_body, self._likely_cause)
        self.reset()

    # ----- clock and stepping ----------------------------------------------------------------
    @property
    def time(self) -> float:
        return float(self.data.time)

    @property
    def timestep(self) -> float:
        return float(self.model.opt.timestep)

    def add_hook(self, hook: Callable[[Simulation], None]) -> None:
        """Run `hook(sim)` before every physics step (a 1 kHz control loop, say)."""
        self.hooks.append(hook)

    def remove_hook(self, hook: Callable[[Simulation], None]) -> None:
        if hook in self.hooks:
            self.hooks.remove(hook)

    def add_periodic(self, period: float, callback: Callable[[Simulation], None]) -> Periodic:
        """Call `callback(sim)` every `period` s of sim time, first one period from now.
        Between calls MuJoCo steps in C, so a 50 Hz publisher costs nothing per step."""
        if not period > 0:
            raise InputError(f"period {period} must be > 0")
        timer = Periodic(period, callback, self.time + period)
        self.periodic.append(timer)
        return timer

    def remove_periodic(self, timer: Periodic) -> None:
        if timer in self.periodic:
            self.periodic.remove(timer)

    def _fire_due(self) -> None:
        now, half = self.time, 0.5 * self.timestep
        for timer in list(self.periodic):
            if now >= timer.next_time - half:
                timer.next_time += timer.period
                if timer.next_time < now - half:  # fell behind (e.g. after a reset): no burst
                    timer.next_time = now + timer.period
                timer.callback(self)

    def _steps_until_due(self) -> int:
        if not self.periodic:
            return _WATCH_EVERY
        soonest = min(t.next_time for t in self.periodic)
        return max(1, int(np.ceil((soonest - self.time) / self.timestep - 0.5)))

    def step(self, n: int = 1) -> None:
        """Advance n physics steps (even when paused: this is Gazebo's step button)."""
        model, data = self.model, self.data
        remaining = int(n)
        while remaining > 0:
            self._fire_due()
            chunk = min(remaining, _WATCH_EVERY - self._since_watch, self._steps_until_due())
            if self.hooks:
                for _ in range(chunk):
                    for hook in self.hooks:
                        hook(self)
                    mujoco.mj_step(model, data)
            else:
                mujoco.mj_step(model, data, chunk)
            remaining -= chunk
            self._since_watch += chunk
            if self._since_watch >= _WATCH_EVERY:
                self._since_watch = 0
                self.watchdog.check(self.controllers_active)
        self._fire_due()

    def run(self, duration: float, on_tick: Callable[[Simulation], None] | None = None,
            tick: float = 0.05, gate: Gate | None = None,
            until: Callable[[], bool] | None = None) -> None:
        """Simulate `duration` s of sim time, paced to target_rtf if set. on_tick(sim) runs every
        `tick` s of sim time (status lines, GUI frames, monitors) and every 10 ms while paused;
        `gate` holds the clock for code running in lockstep with sim time (routines); `until()`
        true ends the run early."""
        half = 0.5 * self.timestep
        end = self.data.time + duration
        next_tick = self.data.time + tick
        while self.data.time < end - half and not (until and until()):
            if self.paused:  # on_tick still runs: it may be what resumes us (a ROS service)
                time.sleep(0.01)
                self._pace_origin = None
                if on_tick:
                    on_tick(self)
                continue
            limit = min(end, next_tick)
            if gate is not None:
                limit = min(limit, gate.horizon())
                if until and until():  # what the gate waited for may have ended the run
                    break
                if limit <= self.data.time + half:  # someone wakes now: let it run first
                    gate.advance(self.time)
                    continue
            n = max(1, round((limit - self.data.time) / self.timestep))
            if gate is not None:
                n = min(n, self._steps_until_due())  # deliver messages to waiting routines
            self.step(n)
            if gate is not None:
                gate.advance(self.time)
            if self.data.time >= next_tick - half:
                next_tick += tick
                self._pace()
                if on_tick:
                    on_tick(self)

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
        """Back to the spawn pose with every joint at 0 (home), sim time 0."""
        mujoco.mj_resetData(self.model, self.data)
        self._efforts[:] = 0.0
        mujoco.mj_forward(self.model, self.data)
        self.rtf.clear()
        self._pace_origin = None
        self._since_watch = 0
        for timer in self.periodic:
            timer.next_time = timer.period

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
        """Torque (or force) each joint received from its motor and applied efforts."""
        out = self.data.qfrc_applied[self.compiled.dof_adr].copy()
        out[self._actuated] += self.data.actuator_force * self.compiled.gear
        return out

    def set_joint_positions(self, values: Mapping[str, float] | Sequence[float]) -> None:
        """Teleport joints (velocities zeroed): for setting up experiments, not for control."""
        vec, given = self._vector(values)
        self.data.qpos[self.compiled.qpos_adr[given]] = vec[given]
        self.data.qvel[self.compiled.dof_adr[given]] = 0.0
        mujoco.mj_forward(self.model, self.data)

    def apply_efforts(self, values: Mapping[str, float] | Sequence[float]) -> None:
        """Joint-space efforts, held until changed. Actuated joints go through their motor, which
        clamps to the URDF effort limit; joints without transmission are pushed directly."""
        vec, given = self._vector(values)
        self._efforts[given] = vec[given]
        if self._actuated.size:
            self.data.ctrl[:] = self._efforts[self._actuated] / self.compiled.gear
        if self._passive.size:
            self.data.qfrc_applied[self.compiled.dof_adr[self._passive]] = self._efforts[self._passive]

    # ----- links --------------------------------------------------------------------------------
    def link_pose(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        """World position and (w, x, y, z) quaternion of a link frame."""
        body = self.compiled.bodies.get(link)
        if body is None:
            raise InputError(f"no link named '{link}'", hint="links: " + ", ".join(self.compiled.bodies))
        return self.data.xpos[body].copy(), self.data.xquat[body].copy()

    def link_speeds(self) -> np.ndarray:
        """Linear speed of each link's centre of mass, in the order of compiled.bodies."""
        linear, _ = link_speeds(self.model, self.data)
        return linear[list(self.compiled.bodies.values())]

    @property
    def base_height(self) -> float:
        return float(self.data.xpos[self.compiled.root_body][2])

    def _likely_cause(self, link: str) -> str | None:
        """The lint finding that explains a divergence: on that link first, else anywhere."""
        suspects = [f for f in check_model(self.robot) if f.code in _LINT_CAUSES]
        suspects.sort(key=lambda f: f.element != f'link "{link}"')
        if not suspects:
            return None
        first = suspects[0]
        return f"{first.element} {_LINT_CAUSES[first.code]} (mexone check: {first.code})"
