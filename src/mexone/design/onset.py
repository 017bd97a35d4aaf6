"""Each margin's prediction checked on the simulated robot (issue 38 item 3): the delay and the
gain at which the loop actually goes unstable.

A trial starts a copy of the lab (`twin`) at the point with the controlled joints given a small
kick, adds a delay to every controlled joint's command (MuJoCo's actuator delay: the motors are
compiled with a command history, `actuator_delay` set per trial) or scales the controllers'
command deviations (u0 + k (u - u0), as a weaker or stronger amplifier would), runs it, and
calls it unstable when it diverged, fell, faulted or the joints' deviation or their motors'
force deviation is larger in the last quarter of the run than anywhere in the unchanged loop's
response to the same kick: a stable loop has let the kick die out by then, an unstable one has
grown it (to an effort limit, perhaps, where a chatter at the Nyquist frequency stays).
Bisection finds the onset to one physics step of delay or 1 % of gain; `Onset.agrees` compares
it with the prediction: within one control period of delay, 10 % of gain (the issue's
tolerances). The joints' dry friction is off in the trials unless asked for, as in the model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from mexone.design.loop import LoopModel
from mexone.design.margins import LoopMargins
from mexone.design.twin import python_runners, restore, snapshot, twin
from mexone.errors import InputError, MexoneError
from mexone.physics.monitor import has_fallen

if TYPE_CHECKING:
    import mujoco

    from mexone.control.controllers.python import PythonRunner
    from mexone.control.student import State
    from mexone.description.model import RobotModel
    from mexone.lab import Lab
    from mexone.physics.simulation import Simulation

__all__ = ["Onset", "simulate_onset", "GAIN_TOLERANCE", "KICK"]

GAIN_TOLERANCE = 0.10  # the issue's: the simulated gain margin within 10 % of the prediction
KICK = 0.05  # rad/s on each controlled joint at the start of a trial
_MAX_DELAY = 0.25  # s: the longest delay tried (the command history compiled for it)
_GROWTH = 1.0  # a trial's last-quarter peak over the loop's own largest response to the kick
_DECAYED = 0.5  # the loop as it is: its last quarter below this of its peak


@dataclass(frozen=True)
class Onset:
    """One margin checked: `kind` ("delay", s, or "gain", "gain reduction": factors), the
    `predicted` value, the simulated `onset` (the smallest change found unstable), the
    `tolerance` it is held to, `agrees`, and the `trials` ((value, unstable), in order)."""

    kind: str
    predicted: float
    onset: float
    tolerance: float
    trials: tuple[tuple[float, bool], ...] = field(default=())
    note: str = ""

    @property
    def agrees(self) -> bool:
        """Whether the simulated onset of instability is within `tolerance` of the prediction
        (s for a delay, relative for a gain); False where either is not finite."""
        if not (math.isfinite(self.predicted) and math.isfinite(self.onset)):
            return False
        if self.kind == "delay":
            return abs(self.onset - self.predicted) <= self.tolerance + 1e-12
        return abs(self.onset - self.predicted) <= self.tolerance * self.predicted

    @property
    def error(self) -> float:
        """onset - predicted (s for a delay), or its ratio to the prediction - 1 (gains)."""
        if self.kind == "delay":
            return self.onset - self.predicted
        return self.onset / self.predicted - 1.0

    def as_dict(self) -> dict[str, Any]:
        """The prediction and the simulated onset as plain JSON values."""
        def num(x: float) -> float | str:
            return float(x) if math.isfinite(x) else ("inf" if x > 0 else "nan")
        return {"kind": self.kind, "predicted": num(self.predicted), "onset": num(self.onset),
                "tolerance": float(self.tolerance), "agrees": bool(self.agrees), "note": self.note,
                "trials": [[float(v), bool(u)] for v, u in self.trials]}


class _Trials:
    """The copy the trials run on: a command history on the controlled joints' motors, the
    controllers' updates wrapped to scale their commands."""

    def __init__(self, lab: Lab, loop: LoopModel, duration: float, kick: float, friction: bool
                 ) -> None:
        self.loop, self.duration, self.kick = loop, duration, kick
        steps = int(math.ceil(_MAX_DELAY / lab.sim.model.opt.timestep)) + 2
        joints = set(loop.joints)

        def history(spec: mujoco.MjSpec, robot: RobotModel) -> None:
            for joint in joints:
                actuator = spec.actuator(joint)
                actuator.nsample, actuator.delay = steps, 0.0

        self.lab = twin(lab, edits=(history,))
        sim = self.lab.sim
        if not friction:  # as the model has it (linearize leaves the dry friction out)
            sim.model.dof_frictionloss[:] = 0.0
        sim.run((steps + 2) * sim.model.opt.timestep)  # the history fills with the point's commands
        self.taken = snapshot(self.lab)
        model = sim.model
        self.motors = np.array([model.actuator(j).id for j in loop.joints], dtype=int)
        self.step = model.opt.timestep
        assert self.lab.manager is not None  # the copy runs the loop's controllers
        hw = self.lab.manager.hw
        rows = hw.rows(list(loop.joints))
        self.qadr, self.dadr = hw.qpos_adr[rows], hw.dof_adr[rows]
        self.q0 = self.taken.qpos[self.qadr].copy()
        self.force0 = sim.data.actuator_force[self.motors].copy()
        self.height = float(sim.base_height)
        self.gain = 1.0
        self.nominal: np.ndarray | None = None  # the loop's own peaks (deviation, force)
        self.runners = python_runners(self.lab, loop.controllers)
        for runner in self.runners:
            self._wrap(runner)
        rng = np.random.default_rng(38)
        self.direction = rng.choice([-1.0, 1.0], size=len(rows))

    def _wrap(self, runner: PythonRunner) -> None:
        impl, update = runner.impl, type(runner.impl).update
        at = [list(self.loop.joints).index(j) for j in runner.joints]
        u0 = self.loop.u0[at] if at else np.zeros(0)

        def scaled(state: State, t: float, dt: float) -> Any:
            out = update(impl, state, t, dt)
            if out is None or self.gain == 1.0 or not at:
                return out
            return u0 + self.gain * (np.asarray(out, dtype=float).reshape(-1) - u0)
        impl.update = scaled  # type: ignore[method-assign]  # this instance's update, scaled

    def unstable(self, delay: float = 0.0, gain: float = 1.0) -> bool:
        sim = self.lab.sim
        restore(self.lab, self.taken)
        for runner in self.runners:  # restarting re-wrapped nothing: the instance keeps it
            if "update" not in vars(runner.impl):
                self._wrap(runner)
        sim.model.actuator_delay[self.motors] = delay
        self.gain = gain
        sim.data.qvel[self.dadr] += self.kick * self.direction
        samples: list[tuple[float, float]] = []
        fell = [False]

        def watch(s: Simulation) -> None:
            dev = s.data.qpos[self.qadr] - self.q0
            force = s.data.actuator_force[self.motors] - self.force0
            samples.append((float(np.sqrt(dev @ dev)), float(np.sqrt(force @ force))))
            if has_fallen(s, self.height) or not np.isfinite(dev).all():
                fell[0] = True

        try:
            sim.run(self.duration, on_tick=watch, tick=self.step, until=lambda: fell[0])
        except MexoneError:
            return True
        finally:
            self.gain = 1.0
        manager = self.lab.manager
        assert manager is not None  # the copy runs the loop's controllers
        if fell[0] or any(cast("PythonRunner", manager.controllers[r.name]).fault
                          for r in self.runners):
            return True
        trace = np.array(samples)
        late = trace[3 * len(trace) // 4:].max(axis=0)  # decayed, or grown (or held by a limit)
        if self.nominal is None:  # the loop as it is: the kick must have died out
            self.nominal = trace.max(axis=0)
            return bool(np.any(late > _DECAYED * self.nominal))
        return bool(np.any((late > _GROWTH * self.nominal) & (late > 1e-9)))


def simulate_onset(lab: Lab, loop: LoopModel, every: LoopMargins, duration: float = 2.0,
                   kick: float = KICK, gains: bool = True, delay: bool = True,
                   friction: bool = False) -> list[Onset]:
    """Check the all-channels margins of `every` (loop_margins(loop).all) on copies of `lab` (at the
    state the loop was linearised at: call right after linearize_loop). friction: keep the
    joints' dry friction in the copy; by default it is off, as in the model: inside its stiction
    band a small oscillation dies whatever the margin, which moves the onset by an amount that
    depends on the kick (the mismatch decomposition reports that effect)."""
    trials = _Trials(lab, loop, duration, kick, friction)
    if trials.unstable():
        raise InputError("the robot does not hold the point under its controllers after a small "
                         "kick: nothing to check the margins against",
                         hint="check the operating point (is it at rest and stable?)")
    out = []
    if delay:
        out.append(_delay_onset(trials, every.delay_margin, loop.period))
    if gains:
        out.append(_gain_onset(trials, every.gain_increase, "gain"))
        if every.gain_reduction > 0:
            out.append(_gain_onset(trials, every.gain_reduction, "gain reduction"))
    return out


def _delay_onset(trials: _Trials, predicted: float, period: float) -> Onset:
    step = trials.step
    log: list[tuple[float, bool]] = []

    def unstable(k: int) -> bool:
        result = trials.unstable(delay=k * step)
        log.append((k * step, result))
        return result

    if not math.isfinite(predicted):
        top = int(_MAX_DELAY / step)
        found = unstable(top)
        return Onset("delay", predicted, top * step if found else math.inf, period, tuple(log),
                     "no crossover predicted; the longest delay tried" +
                     (" destabilised it" if found else " did not destabilise it"))
    low = 0
    high = max(1, int(round(predicted / step)))
    while not unstable(high):
        low = high
        high = min(int(_MAX_DELAY / step), high * 2)
        if low == high:
            return Onset("delay", predicted, math.inf, period, tuple(log),
                         f"stable up to the longest delay tried ({_MAX_DELAY} s)")
    if high > low + 1 and low == 0:
        guess = max(1, int(math.floor(predicted / step)) - 1)
        if guess < high:
            if unstable(guess):
                high = guess
            else:
                low = guess
    while high - low > 1:
        mid = (low + high) // 2
        if unstable(mid):
            high = mid
        else:
            low = mid
    return Onset("delay", predicted, high * step, period, tuple(log))


def _gain_onset(trials: _Trials, predicted: float, kind: str) -> Onset:
    log: list[tuple[float, bool]] = []

    def unstable(k: float) -> bool:
        result = trials.unstable(gain=k)
        log.append((k, result))
        return result

    if not math.isfinite(predicted) or predicted <= 0:
        return Onset(kind, predicted, math.nan, GAIN_TOLERANCE, (), "no finite margin to check")
    up = kind == "gain"
    safe, bad = 1.0, predicted
    stretch = 1.1 if up else 1 / 1.1
    for _ in range(12):  # from the prediction outwards until unstable
        if unstable(bad):
            break
        safe, bad = bad, bad * stretch
    else:
        return Onset(kind, predicted, math.inf, GAIN_TOLERANCE, tuple(log),
                     "stable at every gain tried")
    if safe == 1.0:  # unstable at the prediction: look inside it
        inner = predicted / stretch
        while (inner > 1.0) == up and unstable(inner):
            bad, inner = inner, inner / stretch
        safe = inner if (inner > 1.0) == up else 1.0
    while abs(math.log(bad / safe)) > math.log(1.01):
        mid = math.sqrt(bad * safe)
        if unstable(mid):
            bad = mid
        else:
            safe = mid
    return Onset(kind, predicted, bad, GAIN_TOLERANCE, tuple(log))
