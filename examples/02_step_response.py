"""A step on one joint through its command topic, the way a control course plots it.

    python examples/02_step_response.py [out_dir]
"""

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from mexone.lab import Lab  # noqa: E402
from mexone.msgs import Float64  # noqa: E402

lab = Lab.create()
sim = lab.sim
elbow = sim.joint_names.index("l_elbow")
lab.bus.publish("/mex_rb/l_elbow_position_controller/command", Float64(-1.0))
t, q = [], []
for _ in range(600):
    sim.step(1)
    t.append(sim.time)
    q.append(sim.joint_positions()[elbow])
q = np.array(q)
print(f"final {q[-1]:.4f} rad, overshoot {max(0.0, -q.min() - 1.0) * 100:.1f}% of the step")
plt.plot(t, q, label="l_elbow")
plt.axhline(-1.0, color="grey", linestyle="--", label="command")
plt.xlabel("sim time (s)")
plt.ylabel("position (rad)")
plt.legend()
out = Path(sys.argv[1] if len(sys.argv) > 1 else ".") / "step_response.png"
plt.savefig(out, dpi=100)
print(f"wrote {out}")
