"""Exercise 10, deliberately wrong: damping as the ratio of the measured effort to the speed,
b = sum(tau v) / sum(v^2) -- it ignores that the effort also accelerates the forearm and holds
it up against gravity, so the fit takes those torques for damping."""

from __future__ import annotations

import numpy as np

from mexone.record.reader import read_bag


def estimate(bag: str) -> float:
    states = [s for s in read_bag(bag).states if "l_elbow" in s.names]
    k = states[0].names.index("l_elbow")
    v = np.array([s.velocity[k] for s in states])
    tau = np.array([s.effort[k] for s in states])
    return float(np.sum(tau * v) / np.sum(v * v))
