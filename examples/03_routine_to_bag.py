"""Run the shipped arms routine headless, record it to a bag, and plot command vs actual.

    python examples/03_routine_to_bag.py [out_dir]
"""

import sys
from pathlib import Path

from mexone.lab import Lab
from mexone.record.bag import BagRecorder
from mexone.record.plot import pick_joints, plot_joints
from mexone.record.reader import read_joint_series
from mexone.routines.runner import RoutineRunner

out = Path(sys.argv[1] if len(sys.argv) > 1 else ".")
lab = Lab.create()
recorder = BagRecorder(lab, out / "arms.mcap", force=True)
RoutineRunner(lab, "arms").run(4.0)
recorder.close()
print(f"recorded {sum(recorder.counts.values())} messages: {recorder.counts}")
joints = pick_joints(read_joint_series(out / "arms.mcap"), ["l_shoulder_pitch", "l_elbow"])
plot_joints(joints, out / "arms.png", "arms routine")
print(f"wrote {out / 'arms.png'}")
