"""Why the model and the robot differ (issue 38 item 1): `compare`, decomposed.

`mismatch` runs `compare`'s experiment on the robot as it is, then again with each of the
robot's non-smooth and non-linear effects removed, one at a time, and says how much of the
difference each explains:

dry friction
    every joint's frictionloss off (what `linearize` leaves out by default);
effort limits
    the motors' and joints' torque limits off, and the controller's own clamp;
joint limits
    the joints' range stops off;
contacts changing
    only the contacts the robot has at the start can act (no foot lifting off or landing,
    no link touching what it did not);
amplitude
    the same experiment at a tenth of the deviation with every other effect off, against the
    full one: what the motion's size adds (the dynamics' own curvature).

The share an effect explains is the fraction of the mean-square difference its removal takes
away (1 - (without / with)^2); the shares need not add to 1 (effects interact), and
`residual` is the difference left with all of them off. The friction is then put back in the
model (`FrictionModel.predict`), and the decomposition says how close that gets. The live lab's
model is changed for each run, in its simulation thread, and always put back.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, cast

import mujoco
import numpy as np

from mexone.design.check import Comparison, _check, _on_sim, _vector, compare
from mexone.design.deploy import StateFeedback
from mexone.design.friction import FrictionModel, friction_model
from mexone.errors import InputError
from mexone.ranges import number_text

if TYPE_CHECKING:
    import control
    from matplotlib.figure import Figure
    from numpy.typing import ArrayLike

    from mexone.control.controllers.python import PythonRunner
    from mexone.design.deploy import SystemDesign, _Deployed
    from mexone.lab import Lab

__all__ = ["Mismatch", "mismatch", "plot_mismatch", "describe", "design_plant", "EFFECTS"]

EFFECTS = ("dry friction", "effort limits", "joint limits", "contacts changing", "amplitude")
_SMALL = 0.1  # the amplitude run's fraction of the deviation


@dataclass(frozen=True)
class Mismatch:
    """`relative`: compare's difference on the robot as it is; `without`: effect -> the
    difference with it removed; `explained`: effect -> the share of the mean-square difference
    it explains; `residual`: with every effect removed; `friction_aware`: the difference of the
    linear model with the friction put back (`friction`); `bound` (per state) and `dead_band`
    (per joint): the friction as a bounded disturbance; `describing`: its equivalent damping at
    the run's RMS joint speed; `runs`: the comparisons; `notes`: effects that do not apply."""

    relative: float
    without: dict[str, float]
    explained: dict[str, float]
    residual: float
    friction: FrictionModel | None
    friction_aware: float
    prediction: np.ndarray | None
    bound: np.ndarray | None
    dead_band: np.ndarray | None
    describing: np.ndarray | None
    runs: dict[str, Comparison]
    notes: tuple[str, ...] = field(default=())

    def table(self) -> list[tuple[str, float, float]]:
        """(effect, difference without it, share explained), largest share first."""
        rows = [(e, self.without[e], self.explained[e]) for e in self.without]
        return sorted(rows, key=lambda r: -r[2])

    def as_dict(self) -> dict[str, Any]:
        """The numbers as plain JSON values (`mexone certify --mismatch --json`)."""
        return {"relative": self.relative, "without": self.without, "explained": self.explained,
                "residual": self.residual, "friction_aware": self.friction_aware,
                "dead_band": None if self.dead_band is None else self.dead_band.tolist(),
                "notes": list(self.notes)}


def mismatch(lab: Lab, controller: _Deployed, plant: control.StateSpace,
             deviation: Mapping[str, float] | ArrayLike | None = None,
             reference: Mapping[str, float] | ArrayLike | None = None, duration: float = 1.0,
             effects: Sequence[str] = EFFECTS, identified: str | None = None) -> Mismatch:
    """Decompose compare(lab, controller, plant, deviation, reference, duration) (see the
    module's docstring). identified: a `mexone identify` output (folder or identify.json) whose
    fitted friction the friction-aware model uses."""
    _check(controller, plant)
    unknown = [e for e in effects if e not in EFFECTS]
    if unknown:
        raise InputError(f"effect {unknown[0]!r} is not one of {', '.join(EFFECTS)}")
    # once to put the controller's updates in step with the runs (a controller just deployed
    # updates at the very instant the first run starts, later ones a step after; and the joints
    # outside the model start each run as the one before left them)
    compare(lab, controller, plant, deviation, reference, duration)
    runs = {"robot": compare(lab, controller, plant, deviation, reference, duration)}
    base = runs["robot"]
    notes: list[str] = []
    without: dict[str, float] = {}
    explained: dict[str, float] = {}
    removers = _removers(lab, controller, plant, base, notes)
    for effect in effects:
        if effect == "amplitude":
            continue
        remove = removers.get(effect)
        if remove is None:
            continue
        with _edited(lab, [remove]):
            runs[effect] = compare(lab, controller, plant, deviation, reference, duration)
        without[effect] = runs[effect].relative
    every = [removers[e] for e in effects if e in removers and e != "amplitude"]
    with _edited(lab, every):
        runs["none"] = compare(lab, controller, plant, deviation, reference, duration)
        if "amplitude" in effects:
            small_dev = _scaled(deviation, plant, _SMALL)
            small_ref = None if reference is None else _scaled_ref(reference, controller, plant)
            runs["small"] = compare(lab, controller, plant, small_dev, small_ref, duration)
    residual = runs["none"].relative
    if "amplitude" in effects:
        without["amplitude"] = runs["small"].relative  # the rest off, and small
    for effect, value in without.items():
        full = base.relative
        if effect == "amplitude":
            share = (residual**2 - value**2) / full**2 if full > 0 else 0.0
        else:
            share = 1 - (value / full) ** 2 if full > 0 else 0.0
        explained[effect] = float(min(1.0, max(0.0, share)))
    friction = prediction = bound = dead = describing = None
    aware = float("nan")
    try:
        friction = friction_model(lab, plant)
        if identified:
            friction = friction.with_identified(identified)
    except InputError as exc:
        notes.append(f"no friction-aware model: {exc.what}")
    if friction is not None:
        x0 = dict(zip(plant.state_labels, base.measured[0], strict=True))
        prediction = friction.predict(controller, plant, x0, duration + float(plant.dt),
                                      reference)[:len(base.t)]
        aware = _relative(base, prediction, plant)
        bound, dead = friction.bound(controller, plant)
        _, _, vrows = friction._columns(plant)
        speed = np.sqrt(np.mean(base.measured[:, vrows] ** 2, axis=0)) * np.sqrt(2)
        describing = friction.describing_function(speed)
    return Mismatch(base.relative, without, explained, residual, friction, aware, prediction,
                    bound, dead, describing, runs, tuple(notes))


def design_plant(lab: Lab, controller: _Deployed) -> control.StateSpace:
    """The plant a deployed StateFeedback's design was made on, linearised again at the lab's
    current state (put the robot at the design's point first): its joints as inputs, the others
    welded when its states leave them out, the base fixed when they leave it out, at its period
    (a design read from a file has no plant with it). One line when no such model has its
    states."""
    from mexone.design.linear import linearize

    if not isinstance(controller, StateFeedback):
        raise InputError(f"controller '{controller.name}' is not a StateFeedback: compare needs the "
                         "plant a design was made on")
    design = controller.design
    states = tuple(design.point.states)
    joints = list(design.joints)
    named = {s.rpartition(":")[0] for s in states}
    welded = bool({j.name for j in lab.sim.robot.actuated_joints} - named)
    fixed = lab.sim.compiled.free and "base" not in named
    plant = linearize(lab, inputs=design.interface, joints=joints,
                      held="rigid" if welded else "controllers", fixed_base=fixed,
                      period=design.dt or 1.0 / controller.rate)
    if tuple(plant.state_labels) != states:
        raise InputError(f"controller '{controller.name}': no model of the robot has the design's "
                         f"{len(states)} states", hint="compare from Python with the design's plant")
    return plant


def _relative(base: Comparison, prediction: np.ndarray, plant: control.StateSpace) -> float:
    npos = plant.linearization.qvel.size
    diff = base.measured[:, :npos] - prediction[:, :npos]
    scale = np.linalg.norm(base.measured[0, :npos]) or np.linalg.norm(base.reference[:npos])
    return float(np.sqrt(np.mean(np.sum(diff**2, axis=1))) / scale) if scale else float("nan")


def _scaled(deviation: Mapping[str, float] | ArrayLike | None, plant: control.StateSpace, factor: float
            ) -> np.ndarray | None:
    if deviation is None:
        return None
    vector = _vector(deviation, list(plant.state_labels), "deviation")
    return vector * factor


def _scaled_ref(reference: Mapping[str, float] | ArrayLike, controller: _Deployed,
                plant: control.StateSpace) -> np.ndarray:
    labels = list(plant.state_labels) if isinstance(controller, StateFeedback) \
        else list(cast("SystemDesign", controller.design).inputs)  # a LinearController's
    return _vector(reference, labels, "reference") * _SMALL


# ----- the effects, each a change to the live model undone after ----------------------------------
Edit = Callable[[], Callable[[], None]]  # applies a change, returns its undo


@contextmanager
def _edited(lab: Lab, edits: Sequence[Edit]) -> Iterator[None]:
    undo = _on_sim(lab, lambda: [edit() for edit in edits])
    try:
        yield
    finally:
        _on_sim(lab, lambda: [u() for u in reversed(undo)])


def _removers(lab: Lab, controller: _Deployed, plant: control.StateSpace, base: Comparison,
              notes: list[str]) -> dict[str, Edit]:
    sim = lab.sim
    model = sim.model

    def fields(*names: str, value: float = 0) -> Edit:
        def edit() -> Callable[[], None]:
            saved = {n: getattr(model, n).copy() for n in names}
            for n in names:
                getattr(model, n)[:] = value

            def undo() -> None:
                for n, v in saved.items():
                    getattr(model, n)[:] = v
            return undo
        return edit

    out: dict[str, Edit] = {}
    if model.dof_frictionloss.any():
        out["dry friction"] = fields("dof_frictionloss")
    else:
        notes.append("dry friction: the joints have none")
    out["effort limits"] = _no_effort_limits(lab, controller)
    if model.jnt_limited.any():
        out["joint limits"] = fields("jnt_limited")
    else:
        notes.append("joint limits: no joint has any")
    touching = _touching_geoms(lab, controller)
    if touching is None:
        notes.append("contacts changing: nothing touches at the start (no contacts to keep)")
    else:
        def keep_contacts() -> Callable[[], None]:
            saved = (model.geom_contype.copy(), model.geom_conaffinity.copy())
            others = np.ones(model.ngeom, dtype=bool)
            others[list(touching)] = False
            others[0] = False  # the ground keeps its bits: what touches it is what was
            model.geom_contype[others] = 0
            model.geom_conaffinity[others] = 0

            def undo() -> None:
                model.geom_contype[:], model.geom_conaffinity[:] = saved
            return undo
        out["contacts changing"] = keep_contacts
    return out


def _no_effort_limits(lab: Lab, controller: _Deployed) -> Edit:
    model = lab.sim.model
    manager = lab.manager
    assert manager is not None  # compare ran the controller in it
    runner = cast("PythonRunner", manager.controllers[controller.name])

    def edit() -> Callable[[], None]:
        saved = (model.actuator_forcelimited.copy(), model.jnt_actfrclimited.copy(),
                 list(runner._limits), runner._effort_limit.copy(),
                 manager.hw.effort_limit.copy())
        model.actuator_forcelimited[:] = 0
        model.jnt_actfrclimited[:] = 0
        runner._limits = [1e300] * len(runner._limits)
        runner._effort_limit[:] = np.inf
        manager.hw.effort_limit[:] = np.inf

        def undo() -> None:
            model.actuator_forcelimited[:], model.jnt_actfrclimited[:] = saved[:2]
            runner._limits = saved[2]
            runner._effort_limit[:] = saved[3]
            manager.hw.effort_limit[:] = saved[4]
        return undo
    return edit


def _touching_geoms(lab: Lab, controller: _Deployed) -> set[int] | None:
    """The geoms in contact with the robot at the design's point (None: none)."""
    def find() -> set[int] | None:
        sim = lab.sim
        model = sim.model
        data = mujoco.MjData(model)
        mujoco.mj_copyData(data, model, sim.data)
        point = controller.design.point
        assert point is not None  # _check refused a design without its point
        data.qpos[point.qpos_index] = point.qpos
        data.qvel[:] = 0.0
        mujoco.mj_forward(model, data)
        geoms = {int(g) for i in range(data.ncon) for g in data.contact[i].geom}
        return geoms or None
    return _on_sim(lab, find)


# ----- the figure ----------------------------------------------------------------------------------
def plot_mismatch(result: Mismatch, label: str | None = None, fig: Figure | None = None
                  ) -> Figure:
    """Left: the robot, the linear model, the robot without dry friction and the friction-aware
    model for the state that moves most (or `label`); right: each effect's share of the
    difference. Returns the Figure."""
    import matplotlib.pyplot as plt

    base = result.runs["robot"]
    if label is None:
        npos = len(base.labels) // 2
        label = base.labels[int(np.argmax(np.abs(base.measured[:, :npos]).max(axis=0)))]
    i = base.labels.index(label)
    if fig is None:
        fig = plt.figure(figsize=(10, 3.8))
    left, right = fig.subplots(1, 2, gridspec_kw={"width_ratios": [3, 2]})
    left.plot(base.t, base.measured[:, i], label="robot")
    left.plot(base.t, base.predicted[:, i], "--", label="linear model")
    if "dry friction" in result.runs:
        run = result.runs["dry friction"]
        left.plot(run.t, run.measured[:, i], ":", label="robot, no dry friction")
    if result.prediction is not None:
        left.plot(base.t, result.prediction[:, i], "-.", label="model with the friction")
    left.set_xlabel("t (s)")
    left.set_ylabel(label)
    left.set_title(f"robot vs model: {100 * result.relative:.3g} % "
                   f"(with the friction: {100 * result.friction_aware:.3g} %)")
    left.legend(fontsize="small")
    left.grid(True)
    names = list(result.explained)
    right.barh(names, [100 * result.explained[n] for n in names])
    right.set_xlim(0, 100)
    right.set_xlabel("share of the difference explained (%)")
    right.set_title(f"left with every effect off: {100 * result.residual:.2g} %")
    right.invert_yaxis()
    fig.tight_layout()
    return fig


def describe(result: Mismatch) -> list[str]:
    """The decomposition as lines of text (the CLI's view)."""
    lines = [f"robot vs linear model: {number_text(100 * result.relative)} % RMS of the deviation"]
    for effect, value, share in result.table():
        what = "a tenth of the motion, all off" if effect == "amplitude" else f"without {effect}"
        lines.append(f"  {what:<30} {number_text(100 * value):>8} %   explains "
                     f"{number_text(100 * share)} %")
    lines.append(f"  {'with every effect off':<30} {number_text(100 * result.residual):>8} %")
    if result.friction is not None:
        lines.append(f"model with the dry friction ({result.friction.source}): "
                     f"{number_text(100 * result.friction_aware)} %")
        assert result.dead_band is not None and result.describing is not None  # with the friction
        for j, joint in enumerate(result.friction.joints):
            lines.append(f"  {joint}: Coulomb {number_text(result.friction.coulomb[j])} N m, "
                         f"stiction band {number_text(result.friction.band[j])} rad/s, dead band "
                         f"{number_text(result.dead_band[j])} rad, equivalent damping "
                         f"{number_text(result.describing[j])} N m s/rad at this run's speed")
    lines += [f"note: {n}" for n in result.notes]
    return lines
