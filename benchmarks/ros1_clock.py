"""Does the ROS 1 bridge's /clock timer split MuJoCo's batched stepping? `mexone sim --ros
--headless --rtf 0`'s physics steps per mj_step call and CPU per simulated second, paired: a
plain Lab and a Lab with the ROS 1 bridge in one process, alternating, with and without a
rospy node subscribed to /clock (Debian's ROS 1; a roscore of its own on a free port).

    python benchmarks/ros1_clock.py [SIM_SECONDS_PER_ROUND]

Rounds alternate plain / bridge, 5 of each per subscriber state; each mode's best (least CPU)
round is reported, as the machine's load moves single rounds by tens of percent.
"""

from __future__ import annotations

import collections
import os
import socket
import subprocess
import sys
import time

SUBSCRIBER = """
import rospy
from rosgraph_msgs.msg import Clock
rospy.init_node("bench_clock_listener")
rospy.Subscriber("/clock", Clock, lambda m: None, queue_size=1)
rospy.spin()
"""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_port(port: int) -> None:
    deadline = time.time() + 60
    while time.time() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.2)
    raise RuntimeError("roscore did not start")


class Batches:
    """Counts mj_step calls and their steps per model (wraps mujoco.mj_step while on)."""

    def __init__(self):
        import mujoco

        self.mujoco, self.real = mujoco, mujoco.mj_step
        self.calls: collections.Counter = collections.Counter()
        self.steps: collections.Counter = collections.Counter()

    def __enter__(self):
        def counted(model, data, nstep=1):
            self.calls[id(model)] += 1
            self.steps[id(model)] += nstep
            return self.real(model, data, nstep)

        self.mujoco.mj_step = counted
        return self

    def __exit__(self, *exc):
        self.mujoco.mj_step = self.real

    def per_call(self, lab) -> float:
        key = id(lab.sim.model)
        return self.steps[key] / max(self.calls[key], 1)


def main() -> None:
    seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 20.0
    port = free_port()
    os.environ.update(ROS_MASTER_URI=f"http://127.0.0.1:{port}", ROS_HOSTNAME="127.0.0.1",
                      ROS_LOG_DIR=f"/tmp/mexone-roslog-{port}")
    core = subprocess.Popen(["roscore", "-p", str(port)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    listener = None
    try:
        wait_port(port)
        from mexone.lab import Lab
        from mexone.ros1.bridge import Ros1Bridge

        plain, joined = Lab.create(), Lab.create()
        bridge = Ros1Bridge("gazebo")
        bridge.attach(joined, "<robot name='bench'/>")

        def run(lab, hook):  # as `mexone sim --headless --rtf 0`: a tick every 10 ms
            start = time.process_time()
            lab.sim.run(seconds, tick=0.01, on_tick=hook)
            return (time.process_time() - start) / seconds

        def pump(_sim) -> None:
            bridge.pump()

        joined.sim.run(2.0, tick=0.01, on_tick=pump)  # the sim-rate meter fills
        rows = {}
        for subscribed in (False, True):
            if subscribed:
                listener = subprocess.Popen(["/usr/bin/python3", "-c", SUBSCRIBER])
                deadline = time.time() + 60
                while bridge.pub_clock.get_num_connections() < 1 and time.time() < deadline:
                    joined.sim.run(0.1, tick=0.01, on_tick=pump)
            with Batches() as batches:  # batching, in a round of its own (the wrapper costs)
                run(plain, None)
                run(joined, pump)
            sent = bridge.pub_clock.get_num_connections()
            per = {"plain": [], "ros1": []}
            for _ in range(5):
                per["plain"].append(run(plain, None))
                per["ros1"].append(run(joined, pump))
            rows[subscribed] = (batches.per_call(plain), batches.per_call(joined),
                                min(per["plain"]), min(per["ros1"]), sent)
        bridge.shutdown()
    finally:
        for proc in (listener, core):
            if proc is not None and proc.poll() is None:
                proc.terminate()
                proc.wait(timeout=30)
    step = plain.sim.timestep
    print(f"physics step {step * 1000:g} ms, rounds of {seconds:g} s sim, best of 5 paired")
    for subscribed, (b_plain, b_ros, c_plain, c_ros, conns) in rows.items():
        who = f"a /clock subscriber ({conns} connection)" if subscribed else "no /clock subscriber"
        print(f"{who}: steps per mj_step plain {b_plain:.1f}, --ros {b_ros:.1f}; "
              f"CPU s per sim s plain {c_plain:.4f}, --ros {c_ros:.4f}, ratio {c_ros / c_plain:.3f}")


if __name__ == "__main__":
    main()
