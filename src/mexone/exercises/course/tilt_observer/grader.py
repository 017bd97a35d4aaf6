"""Exercise 14, an observer of the tilt: the student's controller exports `tilt` (the pelvis's
roll and pitch from the vertical) from the IMU. Hidden variant: a slope (gravity tilted 2-4
degrees: an estimate read from the simulator's world-frame truth is off by the slope), the
IMU's noise and gyro bias. Graded: the estimate's RMS error, and that of its changes over the
pushes (most of the tilt is the slope, still: an estimate held still would pass on the first
alone). The estimate must depend on the gyro: a second run with the gyro's noise 10 % larger
must change it (else it read the truth, perhaps offset by the tilt the accelerometer read at
rest), and the tracking counts only then. The observer reads no truth (`blind`): its floating
base stays where it was put, its IMU reports no orientation."""

from __future__ import annotations

import math
import re
import tempfile
from pathlib import Path
from typing import NamedTuple

import numpy as np

from mexone.exercises.course._labtools import check, controller_fault, controller_lab, student_yaml
from mexone.exercises.course._walktools import blind_base
from mexone.physics.world import World
from mexone.robots import mex_one

NAME = "observer"
FILE, CLASS = "tilt_observer.py", "TiltObserver"
GIVEN = {"slope": (0.0, 0.0), "gyro": 0.01, "bias": (0.0, 0.0), "acc": 0.1, "push": (1.0, 1.0)}
SECONDS, SETTLE = 3.5, 0.5
PUSHES = ((1.2, (1.5, 0.0, 0.0)), (2.3, (0.0, 1.2, 0.0)))  # s, N s at the pelvis over 0.1 s
FULL, NONE = 8e-3, 25e-3  # rad RMS: full marks within FULL, none beyond NONE
# the tilt's changes over the AFTER s after each push, from its mean over the BEFORE s before it:
# their RMS error over their RMS, full marks within CHANGE_FULL, none beyond CHANGE_NONE (an
# estimate that holds still, the slope's tilt read once, scores 1: none)
CHANGE_FULL, CHANGE_NONE, BEFORE, AFTER = 0.4, 0.8, 0.05, 0.6
STEP = 1e-3  # s between samples: the simulator's timestep


class Tracking(NamedTuple):
    """How an estimate of the tilt followed it after SETTLE (rad): its RMS error on the tilt's
    RMS, and the RMS error of its changes after the pushes on the changes' RMS. Most of the
    tilt is the slope, which holds still: an estimate that holds still too (the slope guessed,
    or the accelerometer's reading at rest held) had a small error and full marks (was: 6.17
    mrad RMS, 10/10) while it tracked nothing the pushes did."""

    error: float
    size: float
    change_error: float
    change_size: float

    @property
    def change_share(self) -> float:
        """The changes' RMS error over their RMS (inf: none, or not finite)."""
        ok = math.isfinite(self.change_error) and self.change_size > 0
        return self.change_error / self.change_size if ok else math.inf

    def fraction(self) -> float:
        """The share of the marks (0..1): the lower of the tilt's and its changes'."""
        if not (math.isfinite(self.error) and math.isfinite(self.change_share)):
            return 0.0
        return min((NONE - self.error) / (NONE - FULL),
                   (CHANGE_NONE - self.change_share) / (CHANGE_NONE - CHANGE_FULL))


def tracking(true: np.ndarray, estimate: np.ndarray) -> Tracking:
    """The Tracking of `estimate` against `true`, each (steps, 2) rad sampled every STEP."""
    n = min(len(true), len(estimate))
    true, estimate = true[:n], estimate[:n]
    t = np.arange(n) * STEP
    keep = t >= SETTLE
    if not keep.any() or not np.isfinite(estimate[keep]).all():  # ended early, or NaN
        return Tracking(math.inf, 0.0, math.inf, 0.0)
    error = estimate[keep] - true[keep]
    changes, truths = [], []
    for at, _ in PUSHES:
        before, window = (t >= at - BEFORE) & (t < at), (t >= at) & (t < at + AFTER)
        if before.any() and window.any():
            moved = true[window] - true[before].mean(axis=0)
            changes.append(estimate[window] - estimate[before].mean(axis=0) - moved)
            truths.append(moved)
    if not changes:
        return Tracking(float(np.sqrt(np.mean(error**2))), float(np.sqrt(np.mean(true[keep]**2))),
                        math.inf, 0.0)
    change, moved = np.concatenate(changes), np.concatenate(truths)
    return Tracking(float(np.sqrt(np.mean(error**2))), float(np.sqrt(np.mean(true[keep]**2))),
                    float(np.sqrt(np.mean(change**2))), float(np.sqrt(np.mean(moved**2))))


def variant(r: np.random.Generator | None) -> dict:
    if r is None:
        return GIVEN
    axis = int(r.integers(2))
    slope = [0.0, 0.0]
    slope[axis] = float(r.choice([-1.0, 1.0]) * r.uniform(math.radians(2), math.radians(4)))
    return {"slope": tuple(slope), "gyro": float(r.uniform(0.005, 0.02)),
            "bias": tuple(float(b) for b in r.uniform(-0.005, 0.005, size=2)),
            "acc": float(r.uniform(0.05, 0.2)),
            "push": tuple(float(s) for s in r.choice([-1.0, 1.0], size=2))}


def noisy_urdf(folder: Path, var: dict, louder: bool) -> Path:
    """Mex-One's URDF with the variant's IMU noise (Gazebo's <noise>: stddev, bias_mean);
    louder: the gyro's noise 10 % larger (the same draws, scaled), the accelerometer's as it
    was."""
    text = mex_one.urdf_path().read_text()
    bias = np.array([*var["bias"], 0.0])
    scale = 1.1 if louder else 1.0

    def noise(block: str, std: float, means) -> None:
        nonlocal text
        match = re.search(rf"<{block}>.*?</{block}>", text, flags=re.S)
        body = match.group(0)
        for axis, mean in zip("xyz", means, strict=True):
            body = re.sub(rf"<{axis}>.*?</{axis}>", f'<{axis}><noise type="gaussian"><stddev>{std}'
                          f"</stddev><bias_mean>{mean}</bias_mean></noise></{axis}>", body,
                          flags=re.S)
        text = text[:match.start()] + body + text[match.end():]

    noise("angular_velocity", scale * var["gyro"], bias)
    noise("linear_acceleration", var["acc"], (0.0, 0.0, 0.0))
    path = folder / "robot.urdf"
    path.write_text(text)
    return path


def gravity(slope) -> np.ndarray:
    ax, ay = slope
    return 9.81 * np.array([math.sin(ay), -math.sin(ax) * math.cos(ay), -math.cos(ax) * math.cos(ay)])


def blind(lab, name: str) -> None:
    """The observer reads no truth of its tilt: its floating base stays where the robot was put
    (_walktools.blind_base: state.base, state.all_q and self.dynamics), and its IMU reports no
    orientation (x, y, z, w = 0, 0, 0, 1: an IMU without a filter), so what it exports is
    estimated from the gyro and the accelerometer. (Was: the truth against the model's gravity,
    plus a whisker of gyro so a louder gyro moved it, scored 10/10.)"""
    blind_base(lab, name)
    ctrl = lab.manager.controllers[name]
    fill = ctrl._fill_sensor  # the worker's controller (control/controllers/isolated.py)

    def without_orientation(index: int) -> None:
        fill(index)
        for field, view in ctrl._sensor_views[index]:
            if field == "orientation":
                view[:] = (0.0, 0.0, 0.0, 1.0)

    ctrl._fill_sensor = without_orientation


def measure(submission: Path, var: dict, louder: bool = False
            ) -> tuple[np.ndarray, np.ndarray, str | None]:
    """In the isolated child: the pelvis's true tilt from gravity and the student's estimate,
    each (steps, 2) rad, one row a step from the start; the controller's fault."""
    with tempfile.TemporaryDirectory() as tmp, tempfile.TemporaryDirectory() as hidden:
        folder = Path(tmp)
        path = student_yaml(folder, submission, FILE, CLASS, NAME, (), {})
        g = gravity(var["slope"])
        # the model in a folder of its own: the controller's worker reads the YAML's folder,
        # and the URDF holds the hidden noise and bias (and which run is the louder one)
        lab = controller_lab(path, {}, model=noisy_urdf(Path(hidden), var, louder),
                             world=World(gravity=tuple(g)))
        blind(lab, NAME)
        down = g / np.linalg.norm(g)
        pelvis = lab.sim.compiled.bodies["pelvis"]
        true, estimate = [], []

        def sample(sim) -> None:
            up = sim.data.xmat[pelvis].reshape(3, 3).T @ (-down)
            true.append((math.atan2(up[1], up[2]), math.atan2(-up[0], math.hypot(up[1], up[2]))))
            estimate.append(np.array(lab.manager.exports()[f"{NAME}/tilt"]))

        lab.sim.add_periodic(lab.sim.timestep, sample)
        for at, impulse in PUSHES:
            lab.sim.run(at - lab.sim.time)
            force = np.asarray(impulse) * np.array([var["push"][0], var["push"][1], 1.0]) / 0.1
            lab.sim.apply_wrench("pelvis", tuple(force), (0.0, 0.0, 0.0), duration=0.1)
        lab.sim.run(SECONDS - lab.sim.time)
        fault = controller_fault(lab, NAME)
    return np.array(true, dtype=float), np.array(estimate, dtype=float), fault


HIDDEN = ("the hidden variant: a slope of 2-4 degrees, the gyro's noise 0.005-0.02 rad/s and "
          "bias within +-0.005 rad/s, the accelerometer's noise 0.05-0.2 m/s^2")


def described(var: dict) -> str:
    """The variant's numbers: shown for the self-check's given robot only. A graded report is
    the class's oracle (the variant is keyed by the teacher's secret, the same for every
    submission): it stated the slope and the gyro's bias (was: "slope 0.0/2.0 deg, ... bias
    +0.0040, +0.0032"), and the gyro integrated from that slope less that bias, no accelerometer
    and so no observer, scored 8.6/10 on a resubmission."""
    return (f"slope {math.degrees(var['slope'][0]):.1f}/{math.degrees(var['slope'][1]):.1f} deg, "
            f"gyro {var['gyro']:g} rad/s (bias {var['bias'][0]:+.4f}, {var['bias'][1]:+.4f}), "
            f"accelerometer {var['acc']:g} m/s^2")


def grade(ctx) -> list:
    var = variant(None if ctx.local else ctx.rng)
    true, estimate, fault = ctx.run(measure, ctx.submission, var)
    how = tracking(true, estimate)
    runs = check("runs", 1.0, 0.0 if fault else 1.0, fault or f"exported a tilt for {SECONDS} s")
    what = described(var) if ctx.local else HIDDEN
    frac = 0.0 if fault else how.fraction()
    tracks = check("tracks the tilt", 6.0, frac,
                   f"RMS error {how.error * 1e3:.2f} mrad on a tilt of {how.size * 1e3:.1f} mrad "
                   f"RMS, and {how.change_error * 1e3:.2f} mrad on its changes after the pushes "
                   f"({how.change_share:.0%} of their {how.change_size * 1e3:.1f} mrad RMS) (full "
                   f"marks <= {FULL * 1e3:g} mrad and <= {CHANGE_FULL:.0%}, none >= "
                   f"{NONE * 1e3:g} mrad or >= {CHANGE_NONE:.0%}; {what})", requires="uses the IMU")
    _, again, fault2 = ctx.run(measure, ctx.submission, var, True)
    n = min(len(estimate), len(again))
    moved = float(np.abs(estimate[:n] - again[:n]).max()) if n else 0.0
    reads = moved > 1e-6 and not fault2
    why = "" if reads else (": it does not fuse the gyro (the accelerometer alone, or the "
                            "simulator's truth: state.base, state.all_q and the IMU's orientation "
                            "are not measurements)")
    uses = check("uses the IMU", 3.0, 1.0 if reads else 0.0,
                 f"with the gyro's noise 10 % larger the estimate changed by up to "
                 f"{moved * 1e3:.3f} mrad{why}", requires="runs")
    return [runs, tracks, uses]
