"""RunMonitor: what a run did (the numbers the seed judged a fall by), sampled as it runs."""

from __future__ import annotations

import time
from collections import deque
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from mexone.physics.simulation import Simulation

__all__ = ["RunMonitor", "RunSummary", "REST_SPEED", "REST_WINDOW", "has_fallen", "FALL_TILT",
           "FALL_DROP"]

REST_SPEED = 0.01  # m/s: every link's centre of mass slower than this...
REST_WINDOW = 0.2  # s: ...for this long of sim time means at rest
FALL_TILT = 0.5  # rad: a base tilted more than this (29 degrees) has fallen...
FALL_DROP = 0.7  # ...or one lower than 70% of its starting height


def has_fallen(sim: Simulation, start_height: float) -> bool:
    """The one rule for "the robot fell" (run reports, sweeps, walking)."""
    return bool(sim.base_tilt > FALL_TILT or sim.base_height < FALL_DROP * start_height)


@dataclass
class RunSummary:
    sim_time: float
    wall_time: float
    rtf: float
    base_height: float | None  # None: not finite (diverged)
    max_link_speed: float
    at_rest: bool
    diverged: bool
    rest_time: float | None  # sim time since which the robot has been at rest
    error: str | None = None

    def as_json(self) -> dict[str, Any]:
        return asdict(self)


class RunMonitor:
    """Pass `monitor.tick` as Simulation.run's on_tick."""

    def __init__(self, sim: Simulation) -> None:
        self.sim = sim
        self.start_wall = time.perf_counter()
        self.start_sim = sim.time
        self.max_speed = 0.0
        self.recent: deque[tuple[float, float]] = deque()
        self.rest_since: float | None = None
        self.error: str | None = None

    def tick(self, sim: Simulation) -> None:
        speed = float(sim.link_speeds().max())
        self.max_speed = max(self.max_speed, speed)
        self.recent.append((sim.time, speed))
        while self.recent and sim.time - self.recent[0][0] > REST_WINDOW:
            self.recent.popleft()
        if speed >= REST_SPEED:
            self.rest_since = None
        elif self.rest_since is None:
            self.rest_since = sim.time

    def summary(self) -> RunSummary:
        wall = time.perf_counter() - self.start_wall
        simulated = self.sim.time - self.start_sim
        at_rest = self.rest_since is not None and self.sim.time - self.rest_since >= REST_WINDOW
        height = self.sim.base_height
        return RunSummary(
            sim_time=round(self.sim.time, 6), wall_time=round(wall, 4),
            rtf=round(simulated / wall, 3) if wall > 0 else 0.0,
            base_height=round(height, 6) if np.isfinite(height) else None,
            max_link_speed=round(self.max_speed, 6), at_rest=at_rest,
            diverged=self.error is not None,
            rest_time=round(self.rest_since, 4) if at_rest and self.rest_since is not None else None,
            error=self.error)
