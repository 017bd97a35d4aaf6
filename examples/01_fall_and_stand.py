"""Mex-One without and with its controllers: it falls (the seed's 4.2.3), then it stands (4.3.1).

    python examples/01_fall_and_stand.py [out_dir]

With out_dir, it also plots the pelvis height of both runs to out_dir/fall_and_stand.png.
"""

import sys
from pathlib import Path

from mexone.lab import Lab
from mexone.physics.monitor import RunMonitor

heights = {}
for controllers in (False, None):  # False: none; None: the robot's own controllers.yaml
    lab = Lab.create(controllers=controllers)
    monitor = RunMonitor(lab.sim)
    label = "with controllers" if controllers is None else "without controllers"
    track = heights[label] = []

    def tick(sim, monitor=monitor, track=track):
        monitor.tick(sim)
        track.append((sim.time, sim.base_height))

    lab.sim.run(4.0, on_tick=tick, tick=0.01)
    summary = monitor.summary()
    print(f"{label:>20}: pelvis at {summary.base_height:.3f} m after {summary.sim_time:.1f} s, "
          f"at rest: {summary.at_rest}")

if len(sys.argv) > 1:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    for label, track in heights.items():
        plt.plot(*zip(*track, strict=True), label=label)
    plt.xlabel("sim time (s)")
    plt.ylabel("pelvis height (m)")
    plt.legend()
    plt.savefig(Path(sys.argv[1]) / "fall_and_stand.png", dpi=100)
