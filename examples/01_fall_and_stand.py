"""Mex-One without and with its controllers: it falls (the seed's 4.2.3), then it stands (4.3.1).

    python examples/01_fall_and_stand.py
"""

from mexone.lab import Lab
from mexone.physics.monitor import RunMonitor

for controllers in (False, None):  # False: none; None: the robot's own controllers.yaml
    lab = Lab.create(controllers=controllers)
    monitor = RunMonitor(lab.sim)
    lab.sim.run(4.0, on_tick=monitor.tick, tick=0.01)
    summary = monitor.summary()
    label = "with controllers" if controllers is None else "without controllers"
    print(f"{label:>20}: pelvis at {summary.base_height:.3f} m after {summary.sim_time:.1f} s, "
          f"at rest: {summary.at_rest}")
