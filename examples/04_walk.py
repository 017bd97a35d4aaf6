"""Walk Mex-One 1 m forward and a quarter turn left, headless, and write where its pelvis went.

    python examples/04_walk.py [out_dir]

The shipped walk routine (`mexone run walk` walks its full course: 3 m, the turn, 1 m sideways)
with a shorter course; the figures are ground truth from the simulation, the CSV is t, x, y, yaw.
"""

import math
import sys
from pathlib import Path

from mexone.lab import Lab
from mexone.physics.monitor import has_fallen
from mexone.routines.runner import RoutineRunner

out = Path(sys.argv[1] if len(sys.argv) > 1 else ".")
lab = Lab.create()
sim = lab.sim
start_height = sim.base_height
track = []


def sample(s):
    position, quat = s.link_pose("pelvis")
    track.append((s.time, position[0], position[1], math.degrees(2 * math.atan2(quat[3], quat[0]))))


sim.add_periodic(0.1, sample)
runner = RoutineRunner(lab, "walk", {"_course": [["forward", 1.0], ["turn", 90]]})
runner.run(None)  # its course, then 5 s standing; a failed routine raises RoutineError
t, x, y, yaw = track[-1]
print(f"after {t:.1f} s: {x:.2f} m ahead, {y:+.2f} m aside, turned {yaw:.0f} deg, "
      f"{'fell' if has_fallen(sim, start_height) else 'standing'}")
(out / "walk.csv").write_text("t,x,y,yaw\n" + "".join(f"{a:.2f},{b:.4f},{c:.4f},{d:.2f}\n"
                                                     for a, b, c, d in track))
print(f"wrote {out / 'walk.csv'}")

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

plt.plot([p[1] for p in track], [p[2] for p in track])
plt.axis("equal")
plt.xlabel("x (m)")
plt.ylabel("y (m)")
plt.title("the pelvis's path, from above")
plt.savefig(out / "walk.png", dpi=100)
print(f"wrote {out / 'walk.png'}")
