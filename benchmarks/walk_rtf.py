"""Real-time factor of walking, headless: `mexone run walk`'s course (footstep plan, ZMP preview,
whole-body IK each 10 ms, the IMU in the loop) on the physics with its controllers, with every
sensor but the Kinect's images subscribed (IMU, foot force-torque, contacts, COM/ZMP).

    OMP_NUM_THREADS=1 taskset -c 0 env PYTHONPATH=src python benchmarks/walk_rtf.py [--profile]

RTF = sim seconds / wall seconds (and per CPU second: what one core gives when the machine is
shared). --profile prints where the time goes. Record the figures in benchmarks/RESULTS.md.
"""

import argparse
import cProfile
import pstats
import sys
import time

from mexone.bus.msgs import ROS_TYPES
from mexone.lab import Lab
from mexone.motion import walk as _  # noqa: F401 - loads the planner module
from mexone.physics.monitor import has_fallen
from mexone.routines.runner import RoutineRunner

walk = sys.modules["mexone.motion.walk"]  # the module (mexone.motion.walk is also a function)
SKIPPED = ("image", "depth", "points", "camera_info")  # the Kinect's: a renderer, not walking


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--profile", action="store_true", help="print the 15 costliest calls")
    parser.add_argument("--no-sensors", action="store_true", help="only what walking reads")
    parser.add_argument("--ik-iterations", type=int, default=None,
                        help=f"IK steps per control period (default {walk.IK_ITERATIONS})")
    parser.add_argument("--ik-every", type=int, default=None,
                        help=f"control periods per IK solve (default {walk.IK_EVERY})")
    args = parser.parse_args()
    if args.ik_iterations is not None:
        walk.IK_ITERATIONS = args.ik_iterations
    if args.ik_every is not None:
        walk.IK_EVERY = args.ik_every
    lab = Lab.create()
    sim = lab.sim
    start_height = sim.base_height
    subscribed = []
    if not args.no_sensors:
        for name, topic in sorted(lab.bus.topics.items()):
            if topic.publishers and topic.type in ROS_TYPES and not any(s in name for s in SKIPPED):
                lab.bus.subscribe(name, topic.type, lambda _msg: None)
                subscribed.append(name)
    runner = RoutineRunner(lab, "walk")
    profile = cProfile.Profile() if args.profile else None
    wall, cpu = time.perf_counter(), time.process_time()
    if profile:
        profile.enable()
    runner.run(None)
    if profile:
        profile.disable()
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    print(f"sensors subscribed: {', '.join(subscribed) or 'none beyond the walk'}")
    print(f"walked {sim.time:.1f} s of sim time in {wall:.1f} s wall, {cpu:.1f} s CPU: "
          f"RTF {sim.time / wall:.2f} (wall), {sim.time / cpu:.2f} (per CPU second); "
          f"fell: {has_fallen(sim, start_height)}; error: {runner.error}")
    if profile:
        pstats.Stats(profile).sort_stats("tottime").print_stats(15)


if __name__ == "__main__":
    main()
