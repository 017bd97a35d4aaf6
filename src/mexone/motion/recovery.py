"""Push recovery, measured: does the robot, standing, survive a push of this impulse at its torso
(joint PD alone, or with a balance routine running)? And the largest impulse it survives, by
a scan upward, each trial a short headless simulation from the same standing start."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mexone.lab import Lab
from mexone.motion.push import PUSH_SECONDS, apply_wrench
from mexone.physics.monitor import has_fallen
from mexone.routines.runner import RoutineRunner

__all__ = ["PushTrial", "survives", "largest_impulse", "DIRECTIONS"]

DIRECTIONS = {"forward": (1.0, 0.0, 0.0), "backward": (-1.0, 0.0, 0.0),
              "sideways": (0.0, 1.0, 0.0)}


@dataclass(frozen=True)
class PushTrial:
    """One experiment: stand `settle` s (the routine starts with the sim), push `link` with
    `impulse` N s along `direction` over 0.1 s, then watch `after` s."""

    link: str = "torso"
    direction: tuple[float, float, float] = (1.0, 0.0, 0.0)
    routine: str | Path | None = None  # None: joint PD alone
    params: tuple[tuple[str, object], ...] = ()
    settle: float = 1.0
    after: float = 2.0


def survives(trial: PushTrial, impulse: float, make_lab: Callable[[], Lab] = Lab.create) -> bool:
    """Whether the robot is still standing `after` s after the push."""
    lab = make_lab()
    sim = lab.sim
    start_height = sim.base_height
    force = impulse * np.asarray(trial.direction, dtype=float) / PUSH_SECONDS
    timer = None

    def push(s) -> None:
        s.remove_periodic(timer)
        apply_wrench(s, trial.link, force, duration=PUSH_SECONDS)

    timer = sim.add_periodic(trial.settle, push)
    duration = trial.settle + trial.after
    if trial.routine is None:
        sim.run(duration)
    else:
        RoutineRunner(lab, trial.routine, dict(trial.params)).run(duration, hold=True)
    return not has_fallen(sim, start_height)


def largest_impulse(trial: PushTrial, high: float = 40.0, resolution: float = 0.5,
                    make_lab: Callable[[], Lab] = Lab.create) -> float:
    """The largest impulse (N s) such that every impulse up to it, in steps of `resolution`,
    is survived. A scan, not a bisection: survival is not monotonic in the impulse (a balance
    routine that falls at 4 N s can survive 16), and bisection then reports nonsense."""
    survived = 0.0
    impulse = resolution
    while impulse <= high + 1e-9 and survives(trial, impulse, make_lab):
        survived = impulse
        impulse += resolution
    return survived
