"""A private copy of a lab to experiment on (issue 38): the closed loop's finite differences, the
delay and gain trials and the region of attraction run on it, never on the lab a student works in.

`twin(lab)` builds the same robot in the same world and spawn, with the same controllers running
(those deployed from Python included), then copies in the simulation thread every parameter of
the live model (so a gain or a mass changed at run time is the copy's too), the hardware's
commands, the state, and each Python controller's internal state (`ControllerState`). A lab whose
model the copy cannot rebuild (models spawned into it, spec edits) is refused in one line.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, TypeVar, cast

import mujoco
import numpy as np

from mexone.control.controllers.python import PythonRunner
from mexone.control.hardware import set_actuator_state
from mexone.errors import ArgumentTypeError, InputError
from mexone.physics.compile import CompileOptions, SpecEdit

if TYPE_CHECKING:
    from mexone.lab import Lab

T = TypeVar("T")

__all__ = ["twin", "ControllerState", "python_runners", "on_sim", "place"]

# the controller object's own bookkeeping, never its state
_FRAMEWORK = frozenset({"name", "joints", "dofs", "params", "log", "_mexone_binding", "design",
                        "trace", "trace_length", "trace_full", "excitation", "rate", "_sim"})
_MAX_SLOTS = 20_000  # floats in one controller's state: beyond it, a buffer that is no state
_SKIP_MODEL = ("history", "delay")  # the copy's own (a delay line the trials add)


def on_sim(lab: Lab, fn: Callable[[], T]) -> T:
    """Run `fn()` in the lab's simulation thread (now, if no other thread runs the loop)."""
    sim = lab.sim
    return sim.work.call(fn) if sim.loop_elsewhere() else fn()


def python_runners(lab: Lab, names: Sequence[str] | None = None) -> list[PythonRunner]:
    """The running Python controllers (PythonRunner) in the manager's update order, or the ones
    named; one line for a name that is not a running Python controller."""
    manager = getattr(lab, "manager", None)
    if manager is None:
        raise ArgumentTypeError("give a mexone Lab with controllers (Lab.create(controllers=...))")
    running = [c for c in manager.controllers.values() if c.running and isinstance(c, PythonRunner)]
    if names is None:
        if not running:
            raise InputError("no Python controller is running in the lab",
                             hint="deploy a design, or load a controllers YAML with one")
        return running
    by_name = {c.name: c for c in running}
    missing = [n for n in names if n not in by_name]
    if missing:
        raise InputError(f"'{missing[0]}' is not a running Python controller",
                         hint="running: " + (", ".join(by_name) or "none"))
    return [c for c in running if c.name in set(names)]


@dataclass
class ControllerState:
    """A Python controller's internal state: its float and float-array attributes (a filter's
    memory, an integral, a LinearController's x, the arrays it exports), flattened to a vector
    `values` with `labels` (`<controller>.<attribute>[i]`), read from and written into a
    controller object. Ints, strings, lists and other objects are not state (a counter, a log)."""

    controller: str
    slots: list[tuple[str, str | None, tuple[int, ...]]]  # attribute, dict key, shape
    values: np.ndarray
    labels: tuple[str, ...]

    @classmethod
    def of(cls, name: str, impl: object) -> ControllerState:
        slots: list[tuple[str, str | None, tuple[int, ...]]] = []
        values: list[np.ndarray] = []
        labels: list[str] = []
        for attr, value in sorted(vars(impl).items()):
            if attr in _FRAMEWORK or attr.startswith("__"):
                continue
            items = value.items() if isinstance(value, dict) else [(None, value)]
            for key, item in items:
                flat = _floats(item)
                if flat is None:
                    continue
                where = attr if key is None else f"{attr}[{key!r}]"
                slots.append((attr, key, np.shape(item)))
                values.append(flat)
                labels += [f"{name}.{where}"] if flat.size == 1 and np.ndim(item) == 0 else \
                    [f"{name}.{where}[{i}]" for i in range(flat.size)]
        vector = np.concatenate(values) if values else np.zeros(0)
        if vector.size > _MAX_SLOTS:
            raise InputError(f"controller '{name}' holds {vector.size} floats in its attributes; "
                             f"the analysis takes up to {_MAX_SLOTS}",
                             hint="keep large buffers in a list or an int array")
        return cls(name, slots, vector, tuple(labels))

    def read(self, impl: object) -> np.ndarray:
        """The vector as the object holds it now (a slot gone or reshaped reads as before)."""
        out, at = self.values.copy(), 0
        for attr, key, shape in self.slots:
            size = int(np.prod(shape)) if shape else 1
            value = getattr(impl, attr, None)
            if key is not None:
                value = value.get(key) if isinstance(value, dict) else None
            flat = _floats(value)
            if flat is not None and flat.size == size:
                out[at:at + size] = flat
            at += size
        return out

    def write(self, impl: object, vector: np.ndarray) -> None:
        """Put `vector` into the object: arrays in place (a reader's view of an export stays
        valid), scalars as floats."""
        at = 0
        for attr, key, shape in self.slots:
            size = int(np.prod(shape)) if shape else 1
            part = vector[at:at + size]
            at += size
            holder = getattr(impl, attr, None) if key is not None else None
            current = holder.get(key) if isinstance(holder, dict) else getattr(impl, attr, None)
            if isinstance(current, np.ndarray) and current.size == size and current.flags.writeable:
                current.reshape(-1)[:] = part
            elif isinstance(holder, dict):
                holder[key] = float(part[0]) if not shape else part.reshape(shape).copy()
            else:
                setattr(impl, attr, float(part[0]) if not shape else part.reshape(shape).copy())


def _floats(value: object) -> np.ndarray | None:
    """A float or float array's values, flat; None for anything else."""
    if isinstance(value, bool | int | np.integer):
        return None
    if isinstance(value, float | np.floating):
        return np.array([float(value)])
    if isinstance(value, np.ndarray) and value.dtype.kind == "f" and value.size > 0:
        return np.asarray(value, dtype=float).reshape(-1).copy()
    return None


@dataclass(frozen=True)
class _Snapshot:
    """What the copy takes from the live lab, in its simulation thread."""

    fields: dict[str, np.ndarray]
    options: dict[str, object]
    qpos: np.ndarray
    qvel: np.ndarray
    act: np.ndarray
    ctrl: np.ndarray
    warmstart: np.ndarray
    time_ns: int
    time: float  # MuJoCo's (a command history's stamps are on it)
    history: np.ndarray
    commands: dict[str, np.ndarray]
    controllers: dict[str, ControllerState]
    running: tuple[str, ...]


_OPTIONS = ("timestep", "gravity", "disableflags", "enableflags", "integrator", "iterations",
            "tolerance", "ls_iterations", "cone", "solver", "impratio", "noslip_iterations")


def snapshot(lab: Lab) -> _Snapshot:
    """The live lab's parameters, state, commands and controllers' state (simulation thread)."""
    def take() -> _Snapshot:
        sim, manager = lab.sim, lab.manager
        model, data = sim.model, sim.data
        fields = {name: np.array(getattr(model, name)) for name in _model_fields(model)}
        options = {name: copy.copy(getattr(model.opt, name)) for name in _OPTIONS
                   if hasattr(model.opt, name)}
        commands: dict[str, np.ndarray] = {}
        states: dict[str, ControllerState] = {}
        running: tuple[str, ...] = ()
        if manager is not None:
            c = manager.hw.command
            commands = {name: np.array(getattr(c, name)) for name in vars(c) if name != "n"}
            running = tuple(ctrl.name for ctrl in manager.controllers.values() if ctrl.running)
            for ctrl in manager.controllers.values():
                if ctrl.running and isinstance(ctrl, PythonRunner):
                    states[ctrl.name] = ControllerState.of(ctrl.name, ctrl.impl)
        return _Snapshot(fields, options, data.qpos.copy(), data.qvel.copy(), data.act.copy(),
                         data.ctrl.copy(), data.qacc_warmstart.copy(), sim.time_ns, data.time,
                         np.array(getattr(data, "history", np.zeros(0))), commands, states, running)
    return on_sim(lab, take)


def _model_fields(model: mujoco.MjModel) -> list[str]:
    names = []
    for name in dir(model):
        if name.startswith("_") or any(s in name for s in _SKIP_MODEL) or name.startswith("name"):
            continue
        value = getattr(model, name, None)
        if isinstance(value, np.ndarray) and value.dtype.kind in "fib" and value.size:
            names.append(name)
    return names


def twin(lab: Lab, edits: Sequence[SpecEdit] = (), taken: _Snapshot | None = None) -> Lab:
    """A private Lab like `lab` (see the module's docstring), with `edits` on its spec; its
    Python controllers are fresh objects of the same classes holding the live ones' state."""
    sim = getattr(lab, "sim", None)
    if sim is None or not hasattr(sim, "compiled"):
        raise ArgumentTypeError(f"give a mexone Lab, not {type(lab).__name__}")
    if sim.models:
        raise InputError("the lab has models spawned into it (" + ", ".join(sim.models) + "); the "
                         "analysis copies the robot alone", hint="analyse a lab with the robot only")
    taken = taken or snapshot(lab)
    compiled = sim.compiled
    manager = lab.manager
    config = None if manager is None else replace(manager.config,
                                                  controllers=dict(manager.config.controllers))
    fixed = not compiled.free and not sim.robot.fixed_to_world
    copy_lab = type(lab).create(sim.robot, config if config is not None else False, compiled.world,
                          compiled.spawn, CompileOptions(fixed_base=fixed), start=list(taken.running),
                          edits=tuple(edits))
    model, live = copy_lab.sim.model, sim.model
    for name in ("nq", "nv", "na", "nu", "nbody", "ngeom", "nsensordata"):
        if getattr(model, name) != getattr(live, name):
            raise InputError(f"the lab's model differs from the robot's as compiled ({name} "
                             f"{getattr(live, name)} vs {getattr(model, name)}): it was edited, so "
                             "the analysis cannot copy it", hint="analyse a lab made by Lab.create")
    if copy_lab.manager is not None and taken.commands:
        c = copy_lab.manager.hw.command
        for name, value in taken.commands.items():
            getattr(c, name)[:] = value
        copy_lab.manager.hw.write()
    for name, value in taken.fields.items():
        target = getattr(model, name)
        if target.shape == value.shape:
            target[...] = value
    for name, option in taken.options.items():
        setattr(model.opt, name, copy.copy(option))
    restore(copy_lab, taken)
    return copy_lab


def restore(copy_lab: Lab, taken: _Snapshot) -> None:
    """The copy back at the snapshot's state, its Python controllers holding the snapshot's
    internal state (between trials)."""
    sim = copy_lab.sim
    data = sim.data
    data.qpos[:], data.qvel[:], data.qacc_warmstart[:] = taken.qpos, taken.qvel, taken.warmstart
    set_actuator_state(data, ctrl=taken.ctrl, act=taken.act)
    data.qfrc_applied[:] = 0.0
    data.xfrc_applied[:] = 0.0
    if taken.history.size and data.history.shape == taken.history.shape:
        data.history[:] = taken.history
        data.time = taken.time
    mujoco.mj_forward(sim.model, data)
    manager = copy_lab.manager
    if manager is None:
        return
    stopped = [n for n in taken.running if not manager.controllers[n].running]
    if stopped:  # a trial's fault stopped them
        manager.switch(start=stopped)
    for name, state in taken.controllers.items():
        runner = cast(PythonRunner, manager.controllers[name])  # snapshot took Python ones
        runner.fault = None
        state.write(runner.impl, state.values)


def place(lab: Lab, qpos: np.ndarray) -> None:
    """The robot at `qpos`, at rest, every running controller restarted to hold it there (their
    integrals restart with them)."""
    def put() -> None:
        sim = lab.sim
        data = sim.data
        if np.shape(qpos) != data.qpos.shape:
            raise InputError(f"a pose of {np.size(qpos)} positions for a model of {data.qpos.size}")
        sim.set_state(qpos, np.zeros(sim.model.nv))
        manager = lab.manager
        if manager is not None:
            manager.hold([j for c in manager.controllers.values() if c.running for j in c.joints])
    on_sim(lab, put)
