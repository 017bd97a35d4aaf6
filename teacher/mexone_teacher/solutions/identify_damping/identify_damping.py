"""Exercise 10, reference: fit the left elbow's damping with `mexone identify` (MuJoCo's system
identification: replay the recorded commands through the model, adjust the damping until the
simulated joint positions match the recorded ones)."""

from __future__ import annotations

from pathlib import Path

from mexone.identify.session import Options, identify


def estimate(bag: str) -> float:
    result = identify([Path(bag)], Options(params=("damping",), joints=("l_elbow",), threads=1))
    return float(result.fit.values[0])
