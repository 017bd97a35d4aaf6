"""What the graders of the walking exercises (11-13) share: Mex-One's walking stack
(walking.yaml) with one part replaced by the student's class or its parameters, a short walk
under the hidden variant (every link's mass, the floor's friction, a push at the torso), and
what the walk measured. grade(ctx) draws the variant in the grading process; `walk` runs in
ctx.run's isolated child, where the lab imports the student's file."""

from __future__ import annotations

import ast
import math
import shutil
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from mexone.errors import InputError
from mexone.exercises.course._labtools import check, controller_fault, controller_lab
from mexone.exercises.isolate import SubmissionFailed
from mexone.exercises.sim import Variation
from mexone.robots import mex_one

__all__ = ["Push", "Variant", "draw", "stack_text", "handout", "stack_yaml", "Encoders", "blind_base", "walk",
           "speed_check", "imports", "refused_import", "built_on", "rows", "UP"]

UP = "stays up"
SAMPLE = 0.02  # s between the grader's samples of the walk
AFTER_FALL = 0.2  # s simulated after a fall (then the walk ends: nothing more to measure)


@dataclass(frozen=True)
class Push:
    """A 0.1 s push at the torso while walking: `impulse` N s (scaled by the variant's mass:
    the same change of speed on any variant) at `at` s, `angle` rad from forward (pi/2: left)."""

    at: float
    impulse: float
    angle: float = 0.0


@dataclass(frozen=True)
class Variant:
    """One episode's hidden variation: the robot's masses and the floor's friction, a push."""

    variation: Variation = Variation()
    push: Push | None = None

    def describe(self) -> str:
        v = self.variation
        text = f"mass x{v.mass:.2f}, friction x{v.friction:.2f}"
        if self.push is not None:
            side = {0.0: "forward", math.pi: "backward"}.get(self.push.angle, f"{self.push.angle:.2f} rad")
            text += f", pushed {self.push.impulse * v.mass:.2f} N s {side} at {self.push.at:.2f} s"
        return text


def draw(r: np.random.Generator | None, push: tuple[float, float] | None,
         at: tuple[float, float] = (2.0, 2.8)) -> Variant:
    """The variant from the grader's generator (None: the given robot, no push, the
    self-check): masses 0.9-1.1x, friction 0.7-1.0x, a push forward or backward of `push`
    (low, high) N s at a time within `at`."""
    if r is None:
        return Variant()
    variation = Variation(mass=float(r.uniform(0.9, 1.1)), friction=float(r.uniform(0.7, 1.0)))
    if push is None:
        return Variant(variation)
    return Variant(variation, Push(float(r.uniform(*at)), float(r.uniform(*push)),
                                   0.0 if r.random() < 0.5 else math.pi))


def stack_text(part: str | None = None, kind: str = "", params: dict[str, dict] | None = None,
               header: str = "") -> str:
    """walking.yaml's text with the controller `part`'s type replaced by `kind` (FILE_STEM/CLASS:
    a class in a file next to the YAML) and `params` ({controller: {param: value}}) set, under
    the comment `header`."""
    data = yaml.safe_load(mex_one.walking_path().read_text())
    ns, controllers = next(iter(data.items()))
    if part is not None:
        controllers[part]["type"] = kind
    for name, values in (params or {}).items():
        controllers[name].update(values)
    comment = "".join(f"# {line}".rstrip() + "\n" for line in header.splitlines())
    return comment + yaml.safe_dump(data, sort_keys=False)


def handout(part: str | None, file: str, cls: str, params: dict[str, dict] | None,
            exercise: str) -> dict[str, str]:
    """What `mexone exercise start` writes beside the starter: controllers.yaml, the walking
    stack with the student's class (`cls` of `file`) in `part`'s place (or the stack alone) and
    the grader's gait, to run the part locally as it is graded."""
    what = (f"the walking stack with your {cls} ({file}) as its {part}" if part else
            "the walking stack")
    header = (f"Exercise {exercise}: {what}, walking as the grader commands.\n"
              "  mexone sim --controllers controllers.yaml         (the page: watch it, push it)\n"
              "  mexone sim --headless --duration 5 --controllers controllers.yaml --json\n"
              "Written by `mexone exercise start` from mexone's walking.yaml (docs/walking-stack.md).")
    kind = f"{Path(file).stem}/{cls}" if part else ""
    return {"controllers.yaml": stack_text(part, kind, params, header)}


def stack_yaml(workdir: Path, part: str | None = None, source: Path | None = None,
               file: str = "", cls: str = "", params: dict[str, dict] | None = None) -> Path:
    """walking.yaml in `workdir` with the controller `part`'s type replaced by the student's
    class `cls` of `source` (copied next to it as `file`, whatever the student named it), and
    `params` ({controller: {param: value}}) set; its path."""
    if part is not None:
        if source is None or not source.is_file():
            raise SubmissionFailed(InputError(f"{source}: no such file", hint=f"hand in {file}").one_line())
        shutil.copyfile(source, workdir / file)
    out = workdir / "controllers.yaml"
    out.write_text(stack_text(part, f"{Path(file).stem}/{cls}", params))
    return out


@dataclass(frozen=True)
class Encoders:
    """What a real robot's joint encoders read: each joint's angle with noise of `angle` rad
    (quantisation) and its velocity with noise of `velocity` rad/s (a differentiated, quantised
    angle), Gaussian and independent per update, drawn from `seed` so a grading repeats."""

    angle: float = 0.0
    velocity: float = 0.0
    seed: int = 0


def blind_base(lab, name: str, encoders: Encoders = Encoders()) -> None:
    """The controller `name` reads no truth of the floating base: its state.all_q / all_dq (and
    so state.base and self.dynamics) hold the base where the robot was put and at rest -- as a
    real robot's estimator knows only where it started; the sensors (IMU, contacts) are as
    measured, the encoders as `encoders` say. Only this controller's view: the others read the
    simulator."""
    import mujoco

    from mexone.dynamics import Dynamics

    ctrl = lab.manager.controllers[name]
    sim = lab.sim
    blind = mujoco.MjData(sim.model)
    start = sim.data.qpos[:7].copy()
    dynamics = Dynamics(sim.model, blind, copy=False)
    noise = np.random.default_rng(encoders.seed)
    joints_q, joints_v = sim.model.nq - 7, sim.model.nv - 6

    def refresh() -> None:
        blind.qpos[:], blind.qvel[:] = sim.data.qpos, sim.data.qvel
        blind.qpos[:7], blind.qvel[:6] = start, 0.0
        if encoders.angle:
            blind.qpos[7:] += noise.normal(0.0, encoders.angle, joints_q)
        if encoders.velocity:
            blind.qvel[6:] += noise.normal(0.0, encoders.velocity, joints_v)
        blind.time = sim.data.time
        dynamics.refresh()

    update = ctrl.update
    if hasattr(ctrl, "_src"):  # a worker process (control/controllers/isolated.py): what it is sent
        def blind_update(t: float, dt: float) -> None:
            refresh()
            ctrl._src = (blind.qpos, blind.qvel, sim.data.qfrc_actuator)
            update(t, dt)
        ctrl.update = blind_update
        return
    read = ctrl._read  # in the lab's process: the State's data and the dynamics

    def blind_read(t: float) -> None:
        read(t)
        ctrl.state._data = blind

    def in_process_update(t: float, dt: float) -> None:
        refresh()
        ctrl.state._data = blind
        update(t, dt)

    refresh()
    ctrl.state._data = blind
    ctrl._read, ctrl.update, ctrl.dynamics = blind_read, in_process_update, lambda: dynamics


def walk(yaml_path: Path, variant: Variant, seconds: float, part: str | None = None,
         blind: bool = False, encoders: Encoders = Encoders()) -> dict:
    """In the isolated child: the stack of `yaml_path` walks `seconds` s (the footstep planner's
    vx from the YAML) on `variant`; every SAMPLE s the base's x, y, the robot's COM and what
    `part` exports (its `com` or `base`). Ends AFTER_FALL s after a fall. `blind`: `part`
    reads no truth of the floating base, its encoders as `encoders` say (blind_base). Returns
    plain lists."""
    from mexone.motion.push import PUSH_SECONDS, apply_wrench
    from mexone.physics.monitor import has_fallen

    before = set(sys.modules)
    lab = controller_lab(yaml_path, {}, [variant.variation.edit])
    sim = lab.sim
    if blind:
        blind_base(lab, part, encoders)
    push = variant.push
    if push is not None:
        force = push.impulse * variant.variation.mass / PUSH_SECONDS * \
            np.array([math.cos(push.angle), math.sin(push.angle), 0.0])
        timer = None

        def shove(s) -> None:
            s.remove_periodic(timer)
            apply_wrench(s, "torso", force, duration=PUSH_SECONDS)
        timer = sim.add_periodic(push.at, shove)
    start = sim.base_height
    ctrl = lab.manager.controllers.get(part) if part else None
    exports = getattr(ctrl, "exports", {}) if ctrl is not None else {}
    rows: list[list[float]] = []
    fell: float | None = None
    steps = max(1, round(SAMPLE / sim.timestep))
    while sim.time < seconds - 1e-9:
        sim.step(steps)
        data = sim.data
        row = [sim.time, *data.qpos[:3], *data.qvel[:3], *data.subtree_com[1]]
        for key in ("com", "base"):
            value = exports.get(key) if hasattr(exports, "get") else None
            row.extend(np.asarray(value[:6] if key == "com" else value[:10], dtype=float)
                       if value is not None else [])
        rows.append(row)
        if fell is None and has_fallen(sim, start):
            fell = sim.time
        if fell is not None and sim.time >= fell + AFTER_FALL:
            break
    out = {"rows": rows, "fell": fell, "fault": controller_fault(lab, part) if part else None,
           "faults": [f"{n}: {c.fault}" for n, c in lab.manager.controllers.items()
                      if getattr(c, "fault", None)]}
    if ctrl is not None:  # what class ran in the part's place (the method checks')
        out["mro"] = [f"{c.__module__}.{c.__qualname__}" for c in type(ctrl.impl).__mro__] \
            if getattr(ctrl, "impl", None) is not None else []
    out["modules"] = sorted(m for m in sys.modules if m.startswith("mexone.walking.")
                            and m not in before)  # what the student's part imported
    return out


def speed_check(name: str, weight: float, t: np.ndarray, x: np.ndarray, window: float,
                none: float, full: float, what: str) -> tuple:
    """(check, speed): the mean forward speed over the walk's last `window` s, full marks from
    `full` m/s, none at `none`."""
    ok = t >= t[-1] - window
    speed = float((x[ok][-1] - x[ok][0]) / max(t[ok][-1] - t[ok][0], 1e-9))
    return check(name, weight, (speed - none) / (full - none),
                 f"{speed:.3f} m/s forward over the last {window:g} s (full marks from {full:g}, "
                 f"none at {none:g}; {what})", requires=UP), speed


DYNAMIC = {"importlib", "__import__", "exec", "eval"}  # what would hide an import from imports()


def refused_import(submission: Path, shipped: str, what: str) -> str | None:
    """Why the student's file is not run (None: it is): it imports the shipped part `shipped`
    (`what`, e.g. "the shipped planner": the grade would be mexone's, not the student's), or
    imports by name at run time, which would hide that from this check."""
    found = imports(submission)
    if shipped in found:
        return f"{submission.name} imports {shipped}, {what}: write your own"
    dynamic = found & DYNAMIC
    if dynamic:
        return (f"{submission.name} imports by name at run time ({sorted(dynamic)[0]}): import "
                "what you use with `import`")
    return None


def built_on(out: dict, shipped: str) -> str | None:
    """The shipped module `shipped` the student's class was built on or imported in the run
    (walk's `mro` and `modules`), None if neither: a class in a worker process shows only what
    its source imports (refused_import)."""
    found = [c for c in out.get("mro", []) if c.startswith(shipped)] or \
        [m for m in out.get("modules", []) if m.startswith(shipped)]
    return found[0] if found else None


def imports(source: Path) -> set[str]:
    """The modules a Python file imports by statement (read, not run: in the grading process),
    each with its parents ("a.b.c" gives a, a.b, a.b.c), and the names __import__, exec, eval
    where it uses them; empty when it does not parse (the run then says why)."""
    try:
        tree = ast.parse(source.read_text(errors="replace"))
    except (SyntaxError, ValueError, OSError):
        return set()
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Name) and node.id in ("__import__", "exec", "eval"):
            names.add(node.id)
            continue
        if isinstance(node, ast.Import):
            found = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            found = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
        else:
            continue
        for name in found:  # (and the calls that import by name: __import__, exec, eval)
            parts = name.split(".")
            names.update(".".join(parts[:i]) for i in range(1, len(parts) + 1))
    return names


def rows(run: dict, width: int) -> np.ndarray:
    """The walk's samples as an array (time, base x y z, base velocity, COM, then the part's
    export), `width` columns (a sample without the part's export: NaN there)."""
    out = np.full((len(run["rows"]), width), np.nan)
    for i, row in enumerate(run["rows"]):
        out[i, :min(len(row), width)] = row[:width]
    return out
