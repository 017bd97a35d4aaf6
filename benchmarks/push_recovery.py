"""Push recovery of Mex-One standing: the largest horizontal impulse at the torso (N s, over
0.1 s) it survives, joint PD alone vs with the shipped balance routine (`mexone run balance`).

    PYTHONPATH=src python benchmarks/push_recovery.py [--resolution 0.5] [--high 20]

Each figure is a scan up the impulse in steps (survival is not monotonic, so no
bisection); every trial is a fresh headless lab: stand 1 s, push, watch 2 s; "survived"
is mexone's one fall rule (monitor.has_fallen).
Record the table in benchmarks/RESULTS.md.
"""

import argparse
import time

from mexone.motion.recovery import DIRECTIONS, PushTrial, largest_impulse


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolution", type=float, default=0.5, help="N s (default 0.5)")
    parser.add_argument("--high", type=float, default=20.0, help="largest impulse tried, N s")
    args = parser.parse_args()
    start = time.perf_counter()
    print(f"{'direction':<10} {'PD alone':>9} {'balance':>9} {'ratio':>6}   (N s at the torso)")
    for name, direction in DIRECTIONS.items():
        pd = largest_impulse(PushTrial(direction=direction), args.high, args.resolution)
        balanced = largest_impulse(PushTrial(direction=direction, routine="balance"), args.high,
                                   args.resolution)
        ratio = f"{balanced / pd:6.2f}" if pd > 0 else "   inf"
        print(f"{name:<10} {pd:9.2f} {balanced:9.2f} {ratio}", flush=True)
    print(f"({time.perf_counter() - start:.0f} s wall)")


if __name__ == "__main__":
    main()
