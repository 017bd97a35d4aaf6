"""A student's walking part in its own process (issue 36) against the same class in the lab's
process: the shipped skeleton (`mexone controllers new --part KIND`) swapped into the walking
stack, run twice -- named by the YAML (a worker process) and handed over in Python (in-process).
Per update of that part: the wall time, the lab's CPU, the student's own update as the worker
timed it, the worker's overhead (wall minus that), and from the worker's /proc schedstat how
long it waited, runnable, for a CPU (the machine's share of the overhead).

    OMP_NUM_THREADS=1 env PYTHONPATH=src python benchmarks/student_walking_part.py [KIND] [SECONDS]

KIND: whole_body (default), estimator, com_planner, footsteps. The machine is shared: the load
average is printed before and after. Record the figures in benchmarks/RESULTS.md.
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from mexone.control import load_control_config
from mexone.lab import Lab
from mexone.walking.skeletons import KINDS, walking_skeleton_files


def _schedstat(pid: int) -> list[int]:
    """ns on a CPU, ns waiting runnable, slices (Linux)."""
    return [int(x) for x in Path(f"/proc/{pid}/schedstat").read_text().split()]


def measure(folder: Path, kind: str, seconds: float, in_process: bool) -> str:
    stem = f"my_{kind}"
    cls_name = "My" + "".join(p.title() for p in kind.split("_"))
    yaml_path = folder / "controllers.yaml"
    if in_process:
        namespace: dict = {"__name__": stem}
        path = folder / f"{stem}.py"
        exec(compile(path.read_text(), str(path), "exec"), namespace)
        lab = Lab.create(controllers=load_control_config(
            yaml_path, classes={f"{stem}/{cls_name}": namespace[cls_name]}))
    else:
        lab = Lab.create(controllers=yaml_path)
    runner = lab.manager.controllers[KINDS[kind][2]]
    walls, cpus, own = [], [], []
    real = runner.update

    def timed(t: float, dt: float) -> None:
        if not runner.due:
            return real(t, dt)
        wall, cpu = time.perf_counter(), time.thread_time()
        real(t, dt)
        walls.append(time.perf_counter() - wall)
        cpus.append(time.thread_time() - cpu)
        if not in_process:
            own.append(float(runner._out[0]))  # the worker's own timing of the student's update

    runner.update = timed
    lab.sim.step(500)  # warm
    walls.clear(), cpus.clear(), own.clear()
    pid = None if in_process else runner.worker.process.pid
    before = _schedstat(pid) if pid else None
    lab.sim.step(round(seconds / lab.sim.timestep))
    after = _schedstat(pid) if pid else None
    lab.manager.close()
    wall, cpu = np.array(walls) * 1e6, np.array(cpus) * 1e6
    line = (f"{'in-process' if in_process else 'worker':10s} {len(wall)} updates: wall us median "
            f"{np.median(wall):.0f} mean {wall.mean():.0f}, the lab's CPU us median {np.median(cpu):.0f}")
    if pid:
        over = wall - np.array(own) * 1e6
        n = len(wall)
        line += (f"\n           the student's own update us median {1e6 * np.median(own):.0f}; "
                 f"overhead (wall - own) us median {np.median(over):.0f}, p90 "
                 f"{np.percentile(over, 90):.0f}; the worker waited runnable for a CPU "
                 f"{(after[1] - before[1]) / n / 1e3:.0f} us per update")
    return line + (f"; fault: {runner.fault}" if runner.fault else "")


def main() -> None:
    kind = sys.argv[1] if len(sys.argv) > 1 else "whole_body"
    seconds = float(sys.argv[2]) if len(sys.argv) > 2 else 2.0
    print(f"load average before: {os.getloadavg()}")
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        for file, text in walking_skeleton_files(f"my_{kind}", kind).items():
            (folder / file).write_text(text)
        print(f"{kind}, {seconds:g} s of walking:")
        for in_process in (False, True):
            print(measure(folder, kind, seconds, in_process))
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
