"""The closed loop of any controller, linearised at an operating point (issue 38 item 3).

`linearize_loop(lab)` takes the running Python controllers (a deployed design, a student's own
`PythonController`, chained ones: an observer and its reader) at the lab's current state and
returns a `LoopModel`: the plant P by `mjd_transitionFD` (`linearize` at the controllers' period,
their joints' command interface as inputs) and the controller K by central finite differences
of the controllers' own `update`, run on a copy of the lab (`twin`) with the live objects'
internal state captured (`ControllerState`): u = Dc y + Cc xc, xc+ = Ac xc + Bc y, with y the
plant's state and, when a controller reads what its joints measured (`state.effort`), the last
command. Attributes the update never changes (gains, a reference) and buffers nothing reads are
dropped from xc, so K is the controller's own dynamics: a PD has none, a filter or an integral
its states.

Broken at the plant's input the loop is L = -K P (the negative-feedback convention: the closed
loop is stable where det(I + L) has no zeros outside the unit circle); `LoopModel` gives L with
every channel open (`loop()`), one channel open and the others closed (`loop_at(i)`), and the
closed loop with a gain on each channel (`closed_matrix`): what `margins` reads.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, cast

import control
import mujoco
import numpy as np

from mexone.control.controllers.python import PythonRunner
from mexone.control.hardware import set_actuator_state
from mexone.design.linear import linearize
from mexone.design.twin import python_runners, snapshot, twin
from mexone.errors import InputError
from mexone.physics.simulation import NS
from mexone.ranges import number_text

if TYPE_CHECKING:
    from mexone.design.twin import _Snapshot
    from mexone.lab import Lab

__all__ = ["LoopModel", "linearize_loop", "REST_SPEED"]

REST_SPEED = 0.02  # rad/s, m/s: a point faster than this is not at rest (said in notes)
_EPS = 1e-6  # the finite differences' step: rad, m, rad/s, m/s, N m; relative for the rest
_ZERO = 1e-9  # an entry of a derivative below this (relative) is no dependence


@dataclass(frozen=True)
class LoopModel:
    """The closed loop at a point, discrete at the controllers' `period`.

    plant: P, inputs u (`<joint>:<interface>`, deviations from `u0`), states and outputs y (the
    robot's state deviation, as `linearize` names it, then `<joint>:last` for the last command
    when a controller reads the measured effort). controller: K, inputs y, states xc (its
    internal state, `<controller>.<attribute>[i]`), outputs u. `robot` is the StateSpace from
    `linearize` (with `.linearization`); `limits` each input's effort limit (inf for position
    and velocity inputs); `notes` what the analysis should say about the point."""

    plant: control.StateSpace
    controller: control.StateSpace
    robot: control.StateSpace
    controllers: tuple[str, ...]
    joints: tuple[str, ...]
    interface: str
    period: float
    u0: np.ndarray
    limits: np.ndarray
    notes: tuple[str, ...] = field(default=())

    @property
    def inputs(self) -> tuple[str, ...]:
        """The plant's input labels the loop is closed through (`joint:effort`, ...)."""
        return tuple(self.plant.input_labels)

    @property
    def channels(self) -> int:
        """How many input channels the loop has (one margin each, and all at once)."""
        return self.plant.ninputs

    def series(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(Ag, Bg, Cg): G = K P from the plant's input u~ to the controller's output u, so the
        closed loop with u~ = diag(k) u is Ag + Bg diag(k) Cg (K's D times P's D is 0)."""
        ap, bp = np.asarray(self.plant.A), np.asarray(self.plant.B)
        ac, bc = np.asarray(self.controller.A), np.asarray(self.controller.B)
        cc, dc = np.asarray(self.controller.C), np.asarray(self.controller.D)
        n_p, n_c = ap.shape[0], ac.shape[0]
        ag = np.block([[ap, np.zeros((n_p, n_c))], [bc, ac]])
        bg = np.vstack([bp, np.zeros((n_c, bp.shape[1]))])
        cg = np.hstack([dc, cc])
        return ag, bg, cg

    def closed_matrix(self, gains: Sequence[float] | float = 1.0) -> np.ndarray:
        """The closed loop's A with each channel's command scaled by `gains` (one, or one per
        channel) before it reaches the plant."""
        ag, bg, cg = self.series()
        k = np.broadcast_to(np.asarray(gains, dtype=float), (self.channels,))
        return ag + bg @ (k[:, None] * cg)

    def closed(self) -> control.StateSpace:
        """The closed loop: states [plant, controller], input the plant's input (a disturbance
        added to the command), outputs [the commands u, the plant's state y]."""
        ag, bg, cg = self.series()
        a = ag + bg @ cg
        c = np.vstack([cg, np.hstack([np.eye(self.plant.nstates),
                                      np.zeros((self.plant.nstates, self.controller.nstates))])])
        d = np.vstack([np.eye(self.channels), np.zeros((self.plant.nstates, self.channels))])
        return control.ss(a, bg, c, d, self.period,
                          inputs=list(self.inputs),
                          outputs=[f"u:{n}" for n in self.inputs] + list(self.plant.state_labels),
                          name="closed loop")

    def loop(self) -> control.StateSpace:
        """L = -K P with every channel open (MIMO)."""
        ag, bg, cg = self.series()
        return control.ss(ag, bg, -cg, np.zeros((self.channels, self.channels)), self.period,
                          inputs=list(self.inputs), outputs=list(self.inputs), name="L")

    def loop_at(self, i: int) -> control.StateSpace:
        """L_i: the loop broken at channel i alone, every other channel closed (SISO)."""
        ag, bg, cg = self.series()
        closed = np.ones(self.channels)
        closed[i] = 0.0
        a = ag + bg @ (closed[:, None] * cg)
        return control.ss(a, bg[:, [i]], -cg[[i]], np.zeros((1, 1)), self.period,
                          inputs=[self.inputs[i]], outputs=[self.inputs[i]], name=f"L_{i}")


def linearize_loop(lab: Lab, controllers: Sequence[str] | None = None) -> LoopModel:
    """The closed loop of the lab's running Python controllers (or those named) at the lab's
    current state (put the robot at its point first: a design's operating point, or where a
    controller holds it). The live lab is only read: everything runs on a copy."""
    runners = python_runners(lab, controllers)
    names = tuple(r.name for r in runners)
    periods = {r.period_ns for r in runners}
    if len(periods) > 1:
        rates = ", ".join(f"{r.name} {number_text(NS / r.period_ns)} Hz" for r in runners)
        raise InputError(f"the controllers run at different rates ({rates}); the analysis needs "
                         "one period", hint="give them one update_rate, or analyse one alone")
    kinds = {r.interface_name for r in runners if r.joints}
    if len(kinds) != 1:
        what = ", ".join(sorted(kinds)) or "none: no controller drives a joint"
        raise InputError(f"the controllers' command interfaces are {what}; the loop is broken at "
                         "one kind of input", hint="analyse the effort controllers alone")
    interface = kinds.pop()
    period = periods.pop() / NS
    joints = tuple(j for r in runners for j in r.joints)
    taken = snapshot(lab)
    copy_lab = twin(lab, taken=taken)
    step = copy_lab.sim.model.opt.timestep
    if abs(round(period / step) * step - period) > 1e-9:
        raise InputError(f"the controllers' period {number_text(period)} s is not a whole number of "
                         f"physics steps ({number_text(step)} s)", hint="set update_rate to divide "
                         f"{number_text(1 / step)} Hz")
    robot = linearize(copy_lab, inputs=interface, joints=list(joints), period=period)
    manager = copy_lab.manager
    assert manager is not None  # the copy has the live lab's controllers (python_runners found some)
    probe = _Probe(copy_lab, [cast(PythonRunner, manager.controllers[n]) for n in names], taken,
                   robot, joints, interface, period)
    plant, controller = probe.differentiate()
    hw = manager.hw
    limits = hw.effort_limit[hw.rows(list(joints))] if interface == "effort" \
        else np.full(len(joints), np.inf)
    notes = list(probe.notes)
    speed = float(np.abs(taken.qvel).max(initial=0.0))
    if speed > REST_SPEED:
        notes.append(f"the point is not at rest (fastest joint {number_text(speed)} rad/s or m/s): "
                     "the model is of the motion through it")
    return LoopModel(plant, controller, robot, names, joints, interface, period,
                     np.asarray(robot.linearization.u0, float), np.asarray(limits, float),
                     tuple(notes))


class _Probe:
    """Evaluates the controllers' updates on the copy at a perturbed state (plant state dx,
    internal states xc, last command m) and differentiates them."""

    def __init__(self, copy_lab: Lab, runners: list[PythonRunner], taken: _Snapshot,
                 robot: control.StateSpace, joints: tuple[str, ...], interface: str,
                 period: float) -> None:
        self.lab, self.runners, self.robot = copy_lab, runners, robot
        self.period, self.interface = period, interface
        sim = copy_lab.sim
        self.model, self.data = sim.model, sim.data
        lin = robot.linearization
        self.qpos0, self.qvel0 = taken.qpos.copy(), taken.qvel.copy()
        self.act0 = taken.act.copy()
        self.qvel_index = np.asarray(lin.qvel_index, int)
        self.act_rows = np.asarray(lin.act_rows, int)
        self.nv = self.qvel_index.size
        self.nx = robot.nstates
        assert copy_lab.manager is not None  # linearize_loop's copy runs the controllers
        hw = copy_lab.manager.hw
        self.hw, self.rows = hw, hw.rows(list(joints))
        self.command0 = getattr(hw.command, interface)[self.rows].copy()
        self.states = [taken.controllers[r.name] for r in runners]
        self.xc0 = np.concatenate([s.values for s in self.states]) if self.states else np.zeros(0)
        self.labels = [label for s in self.states for label in s.labels]
        self.nu = len(self.rows)
        self.notes: list[str] = []
        self._quiet_sensors()
        self.t = sim.time

    def _quiet_sensors(self) -> None:
        """No sensor noise on the copy: a difference quotient of noise is noise."""
        suite = getattr(self.lab, "sensors", None)
        for sensor in getattr(suite, "sensors", {}).values() if suite is not None else ():
            noise = getattr(sensor, "noise", None)
            if noise is not None and getattr(noise, "active", False):
                noise.active = False
                self.notes.append(f"sensor {sensor.spec.name}'s noise is left out of the model")

    def evaluate(self, dx: np.ndarray, xc: np.ndarray, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(u deviation, next xc) of one update of every controller, in the manager's order."""
        model, data = self.model, self.data
        qpos = self.qpos0.copy()
        v = np.zeros(model.nv)
        v[self.qvel_index] = dx[:self.nv]
        mujoco.mj_integratePos(model, qpos, v, 1.0)
        data.qpos[:] = qpos
        data.qvel[:] = self.qvel0
        data.qvel[self.qvel_index] += dx[self.nv:2 * self.nv]
        set_actuator_state(data, act=self.act0)
        if self.act_rows.size:
            set_actuator_state(data, act=self.act0[self.act_rows] + dx[2 * self.nv:],
                               rows=self.act_rows)
        getattr(self.hw.command, self.interface)[self.rows] = self.command0 + m
        self.hw.write()
        mujoco.mj_forward(model, data)
        self.lab.sim.steps += 1  # a new instant: the sensors read again
        at = 0
        for runner, state in zip(self.runners, self.states, strict=True):
            state.write(runner.impl, xc[at:at + state.values.size])
            at += state.values.size
        u = self.command0 + m
        for runner in self.runners:
            runner.updates += 1
            runner._read(self.t)
            out = runner.impl.update(runner.state, self.t, self.period)
            if out is None or not runner.joints:
                continue
            values = np.asarray(out, dtype=float).reshape(-1)
            if values.size != len(runner.joints) or not np.all(np.isfinite(values)):
                raise InputError(f"controller '{runner.name}': update returned {values.size} values "
                                 f"(or a NaN) at the point; the analysis needs one number per joint")
            where = [list(self.rows).index(r) for r in runner.rows]
            u[where] = values
        nxt = np.concatenate([s.read(r.impl) for r, s in zip(self.runners, self.states, strict=True)]) \
            if self.states else np.zeros(0)
        return u - self.command0, nxt

    def differentiate(self) -> tuple[control.StateSpace, control.StateSpace]:
        nx, nc, nu = self.nx, self.xc0.size, self.nu
        x0, m0 = np.zeros(nx), np.zeros(nu)
        base_u, base_next = self.evaluate(x0, self.xc0, m0)
        if np.abs(base_u).max(initial=0.0) > 1e-3 * max(1.0, float(np.abs(self.command0).max(initial=0))):
            self.notes.append("the controllers' command at the point differs from the one they "
                              f"hold (by {number_text(float(np.abs(base_u).max()))}): the point is "
                              "not their equilibrium")
        du_dx, dn_dx = self._columns(lambda e: self.evaluate(e, self.xc0, m0), nx, _EPS)
        scale = np.maximum(1.0, np.abs(self.xc0))
        du_dc, dn_dc = self._columns(lambda e: self.evaluate(x0, self.xc0 + e, m0), nc, _EPS * scale)
        du_dm, dn_dm = self._columns(lambda e: self.evaluate(x0, self.xc0, e), nu, _EPS)
        keep = _internal_states(dn_dc, np.hstack([dn_dx, dn_dm]), du_dc)
        reads_command = bool(np.abs(du_dm).max(initial=0.0) > _ZERO or
                             np.abs(dn_dm[keep]).max(initial=0.0) > _ZERO)
        labels = list(self.robot.state_labels)
        a, b = np.asarray(self.robot.A), np.asarray(self.robot.B)
        inputs = list(self.robot.input_labels)
        if reads_command:
            n = a.shape[0]
            a = np.block([[a, np.zeros((n, nu))], [np.zeros((nu, n)), np.zeros((nu, nu))]])
            b = np.vstack([b, np.eye(nu)])
            labels += [f"{name.rpartition(':')[0]}:last" for name in inputs]
            dc, bc = np.hstack([du_dx, du_dm]), np.hstack([dn_dx, dn_dm])[keep]
        else:
            dc, bc = du_dx, dn_dx[keep]
        plant = control.ss(a, b, np.eye(a.shape[0]), np.zeros((a.shape[0], nu)), self.period,
                           states=labels, inputs=inputs, outputs=labels, name="plant")
        states = [self.labels[i] for i in keep]
        controller = control.ss(dn_dc[np.ix_(keep, keep)], bc, du_dc[:, keep], dc, self.period,
                                states=states or None, inputs=labels, outputs=inputs,
                                name="controller")
        if not np.all(np.isfinite(dc)):
            raise InputError("the controllers' command is not differentiable at the point (a NaN "
                             "in its derivative)")
        return plant, controller

    def _columns(self, fn: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]], n: int,
                 eps: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        eps = np.broadcast_to(np.asarray(eps, dtype=float), (n,))
        du = np.zeros((self.nu, n))
        dn = np.zeros((self.xc0.size, n))
        for i in range(n):
            e = np.zeros(n)
            e[i] = eps[i]
            up, nup = fn(e)
            down, ndown = fn(-e)
            du[:, i] = (up - down) / (2 * eps[i])
            dn[:, i] = (nup - ndown) / (2 * eps[i])
        return du, dn


def _internal_states(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> list[int]:
    """The internal-state entries that are dynamics: not a parameter (its next value is itself
    whatever the input), not a constant (its next value depends on nothing), and read by the
    command or by another kept entry."""
    n = a.shape[0]
    scale = max(1.0, float(np.abs(a).max(initial=0.0)), float(np.abs(b).max(initial=0.0)))
    tiny = _ZERO * scale
    keep = []
    for i in range(n):
        row = a[i].copy()
        frozen = abs(row[i] - 1.0) < tiny and np.abs(np.delete(row, i)).max(initial=0.0) < tiny
        constant = np.abs(row).max(initial=0.0) < tiny
        moved = np.abs(b[i]).max(initial=0.0) >= tiny
        if (frozen or constant) and not moved:
            continue
        keep.append(i)
    while True:  # drop what nothing reads
        read = [i for i in keep if np.abs(c[:, i]).max(initial=0.0) >= tiny
                or np.abs(a[[j for j in keep if j != i], i]).max(initial=0.0) >= tiny]
        if read == keep:
            return keep
        keep = read
