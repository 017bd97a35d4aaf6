"""The four worked controllers (examples/controllers/): each one's real-time factor per CPU
second, and the LQR sway's push recovery against PD alone (push_recovery.py's method).

    PYTHONPATH=src python benchmarks/worked_controllers.py [--seconds 5] [--no-push]

Real-time factor per CPU second: simulated seconds / process CPU seconds of a headless Lab
running the example's YAML (its Python controller at every 1 ms physics step, the rest of the
robot on the shipped PD), so a loaded machine's other work does not count. Push recovery: the
largest impulse at the torso (N s over 0.1 s) survived, scanning up in 0.5 N s steps, from a
fresh lab per trial. Record the output in benchmarks/RESULTS.md.
"""

import argparse
import time
from pathlib import Path

from mexone.cli.common import read_pose
from mexone.lab import Lab
from mexone.motion.recovery import DIRECTIONS, PushTrial, largest_impulse
from mexone.physics.compile import Spawn

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "controllers"


def lab_of(example: Path) -> Lab:
    pose = example / "pose.yaml"
    joints = tuple(read_pose(pose).items()) if pose.exists() else ()
    return Lab.create(controllers=example / "controllers.yaml", spawn=Spawn(joints=joints))


def rtf_per_cpu(make, seconds: float) -> float:
    lab = make()
    lab.sim.run(0.05)  # first update, imports and allocations out of the measurement
    start = time.process_time()
    lab.sim.run(seconds)
    return seconds / (time.process_time() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0, help="sim seconds per RTF run")
    parser.add_argument("--no-push", action="store_true", help="skip the push-recovery scan")
    args = parser.parse_args()
    print(f"{'controller':<28} {'RTF per CPU s':>14}")
    print(f"{'(shipped PD only)':<28} {rtf_per_cpu(Lab.create, args.seconds):14.1f}")
    examples = sorted(p for p in EXAMPLES.iterdir() if (p / "controllers.yaml").exists())
    for example in examples:
        rtf = rtf_per_cpu(lambda e=example: lab_of(e), args.seconds)
        print(f"{example.name:<28} {rtf:14.1f}", flush=True)
    if args.no_push:
        return
    sway = EXAMPLES / "04_lqr_sway" / "controllers.yaml"
    print(f"\n{'direction':<10} {'PD alone':>9} {'LQR':>9}   (N s at the torso)")
    for name, direction in DIRECTIONS.items():
        trial = PushTrial(direction=direction)
        pd = largest_impulse(trial, 20.0, 0.5)
        lqr = largest_impulse(trial, 20.0, 0.5, make_lab=lambda: Lab.create(controllers=sway))
        print(f"{name:<10} {pd:9.2f} {lqr:9.2f}", flush=True)


if __name__ == "__main__":
    main()
