"""`identify`: bags and a model in, identified values out -- the whole job, for the CLI, tests and
benchmarks. Reading, replaying, fitting and validating are the other modules; this one decides
what goes in (which joints and links, which bags are held out) and what comes out."""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mexone import signals
from mexone.control.config import ControlConfig, load_control_config
from mexone.description.loader import load_model
from mexone.description.model import RobotModel
from mexone.errors import InputError
from mexone.identify.parameters import KINDS, check_kinds, delay_unknown, unknowns_for
from mexone.identify.problem import MAX_ITERATIONS, Fit, Prediction, Problem, Progress
from mexone.identify.recording import read_recording
from mexone.identify.replay import Experiment, replay
from mexone.robots import mex_one

__all__ = ["Options", "Result", "identify", "DEFAULT_PARAMS", "load_inputs"]

DEFAULT_PARAMS = ("damping", "frictionloss", "armature")


@dataclass
class Options:
    model: Path | None = None  # None: the built-in Mex-One
    controllers: Path | None = None  # None: the built-in robot's, else required
    params: tuple[str, ...] = DEFAULT_PARAMS
    joints: tuple[str, ...] = ()  # () = every measured joint with a motor
    links: tuple[str, ...] = ()
    base: str = "auto"
    max_iterations: int = MAX_ITERATIONS
    threads: int = field(default_factory=lambda: os.cpu_count() or 1)
    intervals: bool = True
    delay: bool = True  # fit each bag's command delay (see parameters.delay_unknown)


@dataclass
class Result:
    robot: RobotModel
    config: ControlConfig
    fit: Fit
    experiments: list[Experiment]
    validation: list[Experiment]
    before: list[Prediction]  # fitted bags, then held-out bags, with the nominal values
    after: list[Prediction]
    notes: list[str]

    def _rms(self, predictions: list[Prediction], held_out: bool) -> float:
        chosen = predictions[len(self.experiments):] if held_out else \
            predictions[:len(self.experiments)]
        errors = np.concatenate([p.error[np.isfinite(p.error)] for p in chosen])
        return float(np.sqrt(np.mean(errors**2))) if errors.size else float("nan")

    @property
    def held_out(self) -> bool:
        return bool(self.validation)

    @property
    def rms_before(self) -> float:
        """RMS joint error (rad) of the nominal model: on the held-out bags if any."""
        return self._rms(self.before, self.held_out)

    @property
    def rms_after(self) -> float:
        return self._rms(self.after, self.held_out)

    def as_json(self) -> dict:
        params: dict[str, dict[str, object]] = {}
        intervals: dict[str, dict[str, object]] = {}
        fit = self.fit
        delays = {u.target: float(fit.values[i]) for i, u in enumerate(fit.unknowns) if u.nuisance}
        for i, u in enumerate(fit.unknowns):
            if u.nuisance:
                continue
            key = u.kind if not u.component or u.kind == "com" else f"{u.kind}.{u.component}"
            target = u.target if u.kind != "com" else u.target
            if u.kind == "com":
                params.setdefault(key, {}).setdefault(target, [0.0, 0.0, 0.0])
                params[key][target]["xyz".index(u.component)] = float(fit.values[i])
            else:
                params.setdefault(key, {})[target] = float(fit.values[i])
            if fit.halfwidth is not None:
                intervals.setdefault(key, {})[target + (f".{u.component}" if u.kind == "com"
                                                        else "")] = float(fit.halfwidth[i])
        return {"params": params, "rms_before": self.rms_before, "rms_after": self.rms_after,
                "interval95": intervals or None, "delay": delays or None,
                "validated_on": [e.name for e in self.validation] or None,
                "bags": [e.name for e in self.experiments],
                "iterations": fit.iterations, "seconds": round(fit.seconds, 3),
                "interrupted": fit.interrupted, "notes": self.notes or None}


def load_inputs(model: Path | None, controllers: Path | None) -> tuple[RobotModel, ControlConfig]:
    robot = load_model(model or mex_one.urdf_path())
    if controllers is None:
        if model is not None:
            raise InputError("identify needs the controllers the bag was recorded with",
                             hint="give their YAML with --controllers")
        controllers = mex_one.controllers_path()
    return robot, load_control_config(controllers)


def _check_bags(bags: list[Path], validation: list[Path]) -> None:
    if not bags:
        raise InputError("identify needs at least one bag to fit", hint="e.g. mexone identify run.mcap")
    names = [b.name for b in bags]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise InputError(f"two bags to fit are named {twice[0]}", hint="rename one of them: "
                         "reports and each bag's fitted delay go by the name")
    same = {b.resolve() for b in bags} & {v.resolve() for v in validation}
    if same:
        raise InputError(f"{sorted(same)[0]} is both fitted and held out",
                         hint="a validation bag must be one the fit has not seen")


def identify(bags: list[Path], options: Options, validation: list[Path] = (),
             on_progress: Callable[[Progress], None] | None = None,
             on_stage: Callable[[str], None] | None = None) -> Result:
    """Read and replay every bag, fit the chosen parameters on `bags`, and simulate every bag
    (fitted and held out) before and after."""
    bags, validation = [Path(b) for b in bags], [Path(v) for v in validation]
    _check_bags(bags, validation)
    kinds = check_kinds(options.params)
    say = on_stage or (lambda _text: None)
    robot, config = load_inputs(options.model, options.controllers)
    joints = list(options.joints)
    unknown = [j for j in joints if j not in robot.joints or not robot.joints[j].moving]
    if unknown:
        raise InputError(f"--joints: the model has no moving joint {', '.join(unknown)}",
                         hint="joints: " + ", ".join(j.name for j in robot.moving_joints))
    experiments, held = [], []
    for path in bags + validation:
        say(f"replaying {path.name}")
        recording = read_recording(path, robot, config, joints or None)
        signals.check()  # stopped before the fit: nothing to write (signals.Stop, exit 130/143)
        (experiments if path in bags else held).append(replay(recording, robot, config,
                                                               options.base))
        signals.check()
    if not joints:
        measured = {j for e in experiments for j in e.joints}
        joints = [j.name for j in robot.actuated_joints if j.name in measured] \
            if any(KINDS[k].of == "joint" for k in kinds) else []
    unknowns = unknowns_for(kinds, joints, list(options.links), robot,
                            experiments[0].model)
    if options.delay:
        unknowns += [delay_unknown(e.name) for e in experiments]
    notes = [n for e in experiments + held for n in e.notes]
    problem = Problem(experiments, unknowns, threads=options.threads, on_progress=on_progress)
    try:
        say("simulating the nominal model")
        x0 = problem.params.as_vector()
        before = problem.predict(experiments + held, x0)
        say(f"fitting {len(unknowns)} parameters on {len(experiments)} bag(s)")
        fit = problem.solve(options.max_iterations, options.intervals)
        if fit.interrupted and np.array_equal(fit.scaled, x0):  # stopped before a better point
            after = before
        else:
            say("simulating the identified model")
            after = problem.predict(experiments + held, fit.scaled)
    finally:
        problem.close()
    loose = [u.name for u, h in zip(fit.unknowns, fit.halfwidth if fit.halfwidth is not None
                                    else [0.0] * len(fit.unknowns), strict=True)
             if not np.isfinite(h)]
    if loose:
        notes.append(f"the bags do not determine {', '.join(loose[:3])}"
                     f"{f' and {len(loose) - 3} more' if len(loose) > 3 else ''} (interval +- inf): "
                     "the joints they act on did not move enough; record more excitation")
    if fit.interrupted:
        notes.append(f"interrupted after {fit.iterations} iterations: the best fit so far, "
                     "without confidence intervals")
    return Result(robot, config, fit, experiments, held, before, after, notes)
