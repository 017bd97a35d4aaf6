"""CPU per simulated second of `mexone sim --headless --rtf 0` with and without --ros2 (target:
--ros2 <= 1.25x), with a plain rclpy node subscribed to /clock and joint_states meanwhile.

    MEXONE_ROS2_PYTHON=.venv-ros2/bin/python python benchmarks/ros2_cpu.py [SIM_SECONDS]

Each mode's CPU (user + system of the simulator's process) is measured for a long and a shorter
run (1/3 of it); the difference over the sim-time difference leaves every one-time cost out
(imports, compiling, joining the graph, discovery with the listener). Best of 5 per mode, modes
interleaved. Then the paired measurement, steadier on a loaded machine: a plain Lab and a Lab
with the bridge in one process, run back to back PAIRS times; the median of the pairs' ratios.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import textwrap

PYTHON = os.environ.get("MEXONE_ROS2_PYTHON", sys.executable)
PAIRS = 9  # plain and bridged runs back to back in one process; the ratio is their median
LISTENER = textwrap.dedent("""
    import os
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState
    rclpy.init()
    node = rclpy.create_node("bench_listener")
    # raw: the listener takes the bytes without building Python messages, so its own CPU (which
    # competes with the simulator's for this machine's cores) stays small
    node.create_subscription(Clock, "/clock", lambda m: None,
                             QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT),
                             raw=True)
    reliable = os.environ.get("BENCH_JOINT_STATES", "reliable") == "reliable"
    node.create_subscription(JointState, "/mex_rb/joint_states", lambda m: None,
                             10 if reliable else qos_profile_sensor_data, raw=True)
    try:
        rclpy.spin(node)
    except BaseException:  # terminated: the benchmark is over
        pass
""")


def cpu(args: list[str], seconds: float, env: dict) -> float:
    """CPU seconds the simulator's process used."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run([PYTHON, "-m", "mexone", "sim", "--headless", "--rtf", "0", "--duration",
                    str(seconds), *args], env=env, check=True, capture_output=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


PAIRED = textwrap.dedent("""
    import statistics, sys, time
    from mexone.lab import Lab
    from mexone.ros2.bridge import Ros2Bridge
    seconds, rounds = float(sys.argv[1]), int(sys.argv[2])
    plain, joined = Lab.create(), Lab.create()
    bridge = Ros2Bridge("bench")
    bridge.attach(joined, "<robot name='bench'/>")
    def cpu(lab, hook):
        start = time.process_time()
        lab.sim.run(seconds, tick=0.01, on_tick=hook)
        return (time.process_time() - start) / seconds
    cpu(joined, lambda _s: bridge.pump())  # discovery, the listener subscribes
    ratios, per = [], {"plain": [], "ros2": []}
    for _ in range(rounds):  # each pair back to back: the load's drift cancels in the ratio
        per["plain"].append(cpu(plain, None))
        per["ros2"].append(cpu(joined, lambda _s: bridge.pump()))
        ratios.append(per["ros2"][-1] / per["plain"][-1])
    bridge.shutdown()
    print(statistics.median(per["plain"]), statistics.median(per["ros2"]),
          statistics.median(ratios), min(ratios), max(ratios))
""")


def main() -> None:
    sim_seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 120.0
    short = sim_seconds / 3
    env = dict(os.environ, ROS_DOMAIN_ID=str(101 + os.getpid() % 50),
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    listener = subprocess.Popen([PYTHON, "-c", LISTENER], env=env)
    try:
        per: dict[str, list[float]] = {"plain": [], "ros2": []}
        for _ in range(5):
            for mode, args in (("plain", []), ("ros2", ["--ros2"])):
                long_run = cpu(args, sim_seconds, env)
                start_up = cpu(args, short, env)
                per[mode].append((long_run - start_up) / (sim_seconds - short))
        # the same two runs in one process, alternating: no start-up, less of the load's drift
        out = subprocess.run([PYTHON, "-c", PAIRED, str(sim_seconds / 6), str(PAIRS)], env=env,
                             check=True, capture_output=True, text=True).stdout.split()
        paired_plain, paired_ros2, ratio, low, high = (float(v) for v in out[-5:])
    finally:
        listener.terminate()
        listener.wait(timeout=30)
    plain, ros2 = min(per["plain"]), min(per["ros2"])
    print(f"plain --headless --rtf 0, CPU s per sim s      {plain:.4f}")
    print(f"--ros2 (a node on /clock + joint_states), CPU s/sim s {ros2:.4f}")
    print(f"--ros2 cost ratio (target <= 1.25)             {ros2 / plain:.3f}")
    print(f"same, one process, {PAIRS} pairs x {sim_seconds / 6:g} s: plain {paired_plain:.4f}, "
          f"with the bridge {paired_ros2:.4f} (medians), ratio median {ratio:.3f} "
          f"({low:.2f}-{high:.2f}), load {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
