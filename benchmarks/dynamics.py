"""Dynamics queries and linearisation on Mex-One (issues 25 and 32): wall time per call.

    PYTHONPATH=src python benchmarks/dynamics.py [--repeat 2000] [--json]

Each query row is the cost a controller pays in one update: `refresh()` (the state is taken
again) then the query alone, so the state copy and the forward kinematics (mj_kinematics +
mj_comPos, shared by every query of that update) are in it; the `kinematics` row is that shared
part by itself. Median of 5 batches of `--repeat` calls. Record the output in
benchmarks/RESULTS.md when a change affects it.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from mexone.design import linearize, operating_point
from mexone.dynamics import Dynamics
from mexone.lab import Lab


def per_call(fn, repeat: int) -> float:
    """Median over 5 batches of the wall time per call, in microseconds."""
    batches = []
    for _ in range(5):
        start = time.perf_counter()
        for _ in range(repeat):
            fn()
        batches.append((time.perf_counter() - start) / repeat)
    return 1e6 * float(np.median(batches))


def queries(repeat: int) -> dict[str, float]:
    lab = Lab.create()
    lab.sim.run(0.3)
    model, data = lab.sim.model, lab.sim.data
    links = lab.sim.compiled.bodies
    dyn = Dynamics(model, data, links, links.values())
    dyn.refresh()

    def after_refresh(query):
        def run():
            dyn.refresh()
            query()
        return run

    rows = {
        "refresh + com(): state copy, kinematics, COM": after_refresh(dyn.com),
        "refresh + mass_matrix()": after_refresh(dyn.mass_matrix),
        "refresh + gravity()": after_refresh(dyn.gravity),
        "refresh + bias()": after_refresh(dyn.bias),
        "refresh + jacobian('l_forearm')": after_refresh(lambda: dyn.jacobian("l_forearm")),
        "refresh + jacobian_dot_qdot('l_forearm')": after_refresh(lambda: dyn.jacobian_dot_qdot("l_forearm")),
        "refresh + com_jacobian()": after_refresh(dyn.com_jacobian),
        "refresh + centroidal_momentum()": after_refresh(dyn.centroidal_momentum),
        "refresh + M, g, J, COM (one update's typical set)": after_refresh(
            lambda: (dyn.mass_matrix(), dyn.gravity(), dyn.jacobian("l_forearm"), dyn.com())),
        "jacobian('l_forearm'), kinematics cached": lambda: dyn.jacobian("l_forearm"),
        "Dynamics.snapshot(lab) (no loop thread)": lambda: Dynamics.snapshot(lab),
    }
    out = {name: per_call(fn, repeat) for name, fn in rows.items()}
    arm = ["l_shoulder_pitch", "l_shoulder_roll", "l_elbow"]
    point = operating_point(lab)
    slow = {  # milliseconds: each call copies the model, the reduced one recompiles it
        "operating_point(lab), both feet, ms": lambda: operating_point(lab),
        "linearize(lab, point), full: 54 states, 21 efforts, ms": lambda: linearize(lab, point=point),
        "linearize, full, with the IMU as outputs, ms":
            lambda: linearize(lab, point=point, outputs=["imu/gyro", "imu/acc"]),
        "linearize, one arm, fixed base (after its first call), ms":
            lambda: linearize(lab, joints=arm, held="rigid", fixed_base=True),
    }
    out.update({name: per_call(fn, max(1, repeat // 200)) / 1000 for name, fn in slow.items()})
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=2000)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    results = queries(args.repeat)
    if args.json:
        print(json.dumps(results, indent=2))
        return 0
    print(f"{'what (Mex-One, nv = 27)':58s} {'us per call':>12s} (ms where the row says)")
    for name, value in results.items():
        print(f"{name:58s} {value:12.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
