"""The IK acceptance at full size (issue 16): 200 random reachable hand targets, sampled by
forward kinematics of random arm configurations over the arms' whole ranges
(`mexone.motion.ik.reachable_targets`), each solved by whole-body IK from the standing pose;
reached means within 5 mm and 2 degrees with both feet moved less than 1 mm. The test suite
checks 80 (tests/motion/test_ik.py, slow) of the same kind, for the suite's time.

    PYTHONPATH=src python benchmarks/ik_targets.py [--count 200] [--seed 7] [--json]

Two solvers on the same targets: `one start` descends from the standing pose only (at most 600
steps), `restarts` is `WholeBodyIK.solve` (the same, then up to RESTARTS fresh starts of the
arm's joints when the first stops short). Prints, for each, the share reached, the worst
position and orientation errors, the worst foot motion and the wall time per target. Record the
output in benchmarks/RESULTS.md when a change affects it.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from mexone.lab import Lab
from mexone.motion.ik import RESTARTS, WholeBodyIK, reachable_targets

POSITION, ANGLE, FEET = 0.005, np.radians(2.0), 0.001  # m, rad, m: the thresholds
ITERATIONS = 600  # IK steps at most per target, as the tests


def measure(ik: WholeBodyIK, home: np.ndarray, goals, restarts: int) -> dict:
    errors, angles, moves, reached = [], [], [], 0
    start = time.perf_counter()
    for frame, xyz, rotation in goals:
        ik.reset(home)
        feet = {f: ik.pose(f)[0] for f in ("l_foot", "r_foot")}
        ik.set_target(frame, xyz, rotation)
        error = ik.solve(frame, iterations=ITERATIONS, restarts=restarts)
        moved = max(float(np.linalg.norm(ik.pose(f)[0] - p)) for f, p in feet.items())
        errors.append(error.position)
        angles.append(error.angle)
        moves.append(moved)
        reached += error.position <= POSITION and error.angle <= ANGLE and moved < FEET
    seconds = time.perf_counter() - start
    return {"targets": len(goals), "reached": reached, "reached_share": reached / len(goals),
            "worst_position_mm": 1000 * max(errors), "median_position_mm": 1000 * float(np.median(errors)),
            "worst_angle_deg": float(np.degrees(max(angles))),
            "worst_feet_mm": 1000 * max(moves), "ms_per_target": 1000 * seconds / len(goals)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--count", type=int, default=200)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    lab = Lab.create(controllers=False)
    lab.sim.run(0.2)  # standing on the ground, as the tests start
    home = lab.sim.data.qpos.copy()
    ik = WholeBodyIK.for_sim(lab.sim)
    goals = reachable_targets(ik, home, args.count, seed=args.seed)
    results = {name: measure(ik, home, goals, restarts)
               for name, restarts in (("one start", 0), (f"restarts {RESTARTS}", RESTARTS))}
    if args.json:
        print(json.dumps(results, indent=2))
        return 0
    print(f"{args.count} FK hand targets each, seed {args.seed}; reached: <= 5 mm, <= 2 deg, "
          "feet < 1 mm")
    print(f"{'solver':12} {'reached':>12} {'worst mm':>9} {'median mm':>10} {'worst deg':>10} "
          f"{'feet mm':>8} {'ms/target':>10}")
    for name, r in results.items():
        print(f"{name:12} {r['reached']:>5}/{r['targets']:<3} ({r['reached_share']:4.0%}) "
              f"{r['worst_position_mm']:9.2f} {r['median_position_mm']:10.3f} "
              f"{r['worst_angle_deg']:10.2f} {r['worst_feet_mm']:8.3f} {r['ms_per_target']:10.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
