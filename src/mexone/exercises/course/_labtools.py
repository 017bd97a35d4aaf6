"""What the graders of course exercises 5-10 share: a lab with the student's controller on some
joints (the shipped PIDs on the rest), a heavier or lighter link for the hidden variant, the
controller's fault, a check. grade(ctx) runs in the grading process and draws the variant there;
these helpers run in the simulator (ctx.measure), whose lab runs the student's class in its
controller worker, a jail of its own: what they measure is the simulation's, not the student's."""

from __future__ import annotations

import os
import re
import shutil
from collections.abc import Callable, Sequence
from pathlib import Path

import mujoco
import numpy as np
import yaml

from mexone.errors import InputError, MexoneError
from mexone.exercises.grading import Check
from mexone.exercises.isolate import SubmissionFailed
from mexone.lab import Lab
from mexone.physics.compile import CompileOptions, Spawn
from mexone.robots import mex_one

__all__ = ["check", "student_yaml", "controller_lab", "scale_mass", "JointLog",
           "controller_fault", "gain_share", "gains_check", "fit_gains", "HAND", "HAND_POINT", "ARM",
           "GAIN_FULL", "GAIN_NONE"]

HAND = "l_forearm"  # the link that carries Mex-One's left hand
HAND_POINT = np.array([0.0, 0.0, -0.17])  # m: the hand, the forearm's far end, in its frame
ARM = ("l_shoulder_pitch", "l_shoulder_roll", "l_elbow")
# libyaml's safe loader and dumper when present: the shipped YAML in ~0.01 s, not ~0.1 s (per run)
_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)
GAIN_FULL, GAIN_NONE = 1.25, 2.0  # a measured gain within x/÷ GAIN_FULL of the asked: full marks


def check(name: str, weight: float, fraction: float, output: str,
          requires: str | None = None) -> Check:
    """A framework Check from (name, weight, share earned 0..1, why); `requires`: the check it
    presumes (Check.requires: nothing earned when that one failed)."""
    return Check(name, float(np.clip(fraction, 0.0, 1.0)), weight, output, requires=requires)


def gain_share(measured: float, asked: float) -> float:
    """The share (0..1) a gain the controller was measured to apply earns: 1 within a factor
    GAIN_FULL of the gain asked, none beyond GAIN_NONE (or of the wrong sign), log-linear
    between: a method check (the statement's law at the grader's gains)."""
    if not np.isfinite(measured) or measured <= 0:
        return 0.0
    off = abs(np.log(measured / asked))
    return float(np.clip((np.log(GAIN_NONE) - off) / (np.log(GAIN_NONE) - np.log(GAIN_FULL)),
                         0.0, 1.0))


def gains_check(name: str, gains: Sequence[tuple[float, float]], kp: float, kd: float,
                fault: str | None, units: tuple[str, str], how: str, digits: int = 3) -> Check:
    """The method check of a law at the grader's `kp` and `kd`: each joint's fitted (stiffness,
    damping) earns gain_share of both, the worst joint counts, none with a `fault`; its output
    says the fitted gains (in `units`), `how` they were fitted, and the gains asked."""
    share = 0.0 if fault else min(gain_share(k, kp) * gain_share(d, kd) for k, d in gains)
    return check(name, 1.0, share,
                 f"kp {', '.join(f'{k:.{digits}g}' for k, _ in gains)} {units[0]}, kd "
                 f"{', '.join(f'{d:.{digits}g}' for _, d in gains)} {units[1]} ({how}); "
                 f"kp {kp:g}, kd {kd:g} asked")


def fit_gains(force: np.ndarray, x: np.ndarray, v: np.ndarray) -> tuple[float, float, float]:
    """(stiffness, damping, rest point) of the spring-damper force = stiffness (rest - x) -
    damping v that fits the samples best (least squares): the law a controller applies, measured
    from what it did (the samples must move: a probe pushes the joint or the hand)."""
    columns = np.c_[-x, -v, np.ones(len(x))]
    (stiffness, damping, offset), *_ = np.linalg.lstsq(columns, force, rcond=None)
    rest = offset / stiffness if stiffness else float("nan")
    return float(stiffness), float(damping), float(rest)


def student_yaml(workdir: Path, source: Path, file: str, cls: str, name: str,
                 joints: Sequence[str], params: dict[str, float]) -> Path:
    """A controllers YAML in `workdir`: the student's class `cls` of file `source` (copied next
    to it as `file`, whatever the student named it) on `joints`, the shipped PID on every other
    joint."""
    if not source.is_file():
        raise SubmissionFailed(InputError(f"{source}: no such file", hint=f"hand in {file}").one_line())
    shutil.copyfile(source, workdir / file)
    source = workdir / file
    os.chmod(workdir, 0o755)  # the controller's worker, a jail of another uid, reads them
    os.chmod(source, 0o644)
    shipped = yaml.load(Path(mex_one.controllers_path()).read_text(), Loader=_LOADER)
    ns, controllers = next(iter(shipped.items()))
    kept = {k: v for k, v in controllers.items() if v.get("joint") not in joints}
    entry = {"type": f"{source.stem}/{cls}", "joints": list(joints), **params}
    out = workdir / "controllers.yaml"
    out.write_text(yaml.dump({ns: {name: entry, **kept}}, Dumper=_DUMPER, sort_keys=False))
    os.chmod(out, 0o644)
    return out


def scale_mass(body: str, factor: float) -> Callable:
    """A spec edit: `body`'s mass and inertia times `factor` (a heavier or lighter link)."""

    def edit(spec: mujoco.MjSpec, robot) -> None:
        b = spec.body(body)
        b.mass *= factor
        b.inertia = np.asarray(b.inertia) * factor
    return edit


def controller_lab(yaml_path: Path, pose: dict[str, float], edits: Sequence[Callable] = (),
                   fixed_base: bool = False, model: Path | None = None, world=None) -> Lab:
    """Mex-One (or `model`, a variant of its URDF) with the controllers of `yaml_path`, its
    joints at `pose`, the variant's edits, in `world` (default: the empty world)."""
    try:
        return Lab.create(model, controllers=yaml_path, spawn=Spawn(joints=tuple(pose.items())),
                          edits=tuple(edits), options=CompileOptions(fixed_base=fixed_base),
                          world=world)
    except MexoneError as exc:  # the student's class did not load: its one line is the reason
        raise SubmissionFailed(_students_line(exc, yaml_path)) from None


def _students_line(exc: MexoneError, yaml_path: Path) -> str:
    """The error's one line as the student reads it: their file by its name (not the grader's
    temporary copy's path), the grader's YAML so named, no hint meant for the GUI's Reload."""
    if exc.hint and "reload" in exc.hint.lower():  # the GUI's: a grade has no Reload
        exc.hint = None
    text = exc.one_line().replace(str(yaml_path), "the grader's controllers.yaml")
    return text.replace(str(yaml_path.parent) + "/", "")


def controller_fault(lab: Lab, name: str) -> str | None:
    """Why the student's controller is not running (a fault, or it never started), else None."""
    ctrl = lab.manager.controllers.get(name)
    if ctrl is None:
        return f"controller {name} was not loaded"
    # the class's interface first: it is the reason whatever the run did (an ideal servo's
    # teleported joints can also make its updates overrun on a loaded machine)
    interface = getattr(getattr(ctrl, "impl", None), "command_interface", "effort")
    if interface != "effort":  # without gains it is an ideal servo: the joints teleported
        return (f"command_interface is '{interface}': the exercise is a torque law "
                "(command_interface = 'effort'); a position or velocity command with no gains "
                "moves the joints ideally, without the robot's dynamics")
    if getattr(ctrl, "fault", None):  # the student's file named without the grader's temp folder
        return re.sub(r"(?:/[^/\s:]+)+/([^/\s:]+\.py)", r"\1", str(ctrl.fault))
    if not ctrl.running:
        return f"controller {name} stopped"
    return None


class JointLog:
    """Every step's positions of `joints`, read in the simulation thread between steps."""

    def __init__(self, lab: Lab, joints: Sequence[str]):
        model = lab.sim.model
        self.adr = [int(model.joint(j).qposadr[0]) for j in joints]
        self.times: list[float] = []
        self.q: list[np.ndarray] = []
        self.timer = lab.sim.add_periodic(lab.sim.timestep, self.sample)

    def sample(self, sim) -> None:
        self.times.append(sim.time)
        self.q.append(self.positions(sim))

    def positions(self, sim) -> np.ndarray:
        """The joints' positions now (rad)."""
        return sim.data.qpos[self.adr].copy()
