"""Issue 38's numbers: `linearize` against the raw `mjd_transitionFD` it runs at the standing
point (paired, interleaved), `mexone certify` of the arm LQR and of the one-foot LQR (wall time
of the whole command), and a region of attraction of the one-foot LQR on a grid of 1000 pushes
(wall and CPU time, MuJoCo's threads).

    PYTHONPATH=src python benchmarks/robust.py [--grid 40x25] [--threads 2] [--skip-region]

Prints the load (the machine is shared: CPU seconds over threads is what a quiet machine's
wall time would be). Record the table in benchmarks/RESULTS.md.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import mujoco
import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples" / "control_design"))

import one_foot_lqr as lq  # noqa: E402

from mexone.design import (  # noqa: E402
    deploy,
    linearize,
    lqr,
    operating_point,
    region_of_attraction,
    save_design,
)
from mexone.lab import Lab  # noqa: E402
from mexone.robots import mex_one  # noqa: E402

ARM = ["l_shoulder_pitch", "l_shoulder_roll", "l_elbow"]


def load() -> str:
    return "load " + ", ".join(f"{x:.1f}" for x in os.getloadavg())


def linearize_ratio(pairs: int = 200) -> tuple[float, float, float]:
    """(linearize ms, raw mjd_transitionFD ms, median of the paired ratios)."""
    lab = Lab.create()
    lab.sim.run(0.3)
    point = operating_point(lab)
    linearize(lab, point=point)
    model = lab.sim.model
    data = mujoco.MjData(model)
    mujoco.mj_copyData(data, model, lab.sim.data)
    data.qpos[:], data.qvel[:] = point.qpos, 0.0
    mujoco.mj_forward(model, data)
    nx = 2 * model.nv + model.na
    a, b = np.zeros((nx, nx)), np.zeros((nx, model.nu))
    ours, raw = [], []
    for _ in range(pairs):
        start = time.perf_counter()
        mujoco.mjd_transitionFD(model, data, 1e-6, True, a, b, None, None)
        raw.append(time.perf_counter() - start)
        start = time.perf_counter()
        linearize(lab, point=point)
        ours.append(time.perf_counter() - start)
    ours_a, raw_a = np.array(ours), np.array(raw)
    return 1e3 * np.median(ours_a), 1e3 * np.median(raw_a), float(np.median(ours_a / raw_a))


def _yaml(folder: Path, name: str, entry: dict) -> Path:
    shipped = yaml.safe_load(mex_one.controllers_path().read_text())
    ns, controllers = next(iter(shipped.items()))
    joints = set(entry["joints"])
    kept = {k: v for k, v in controllers.items() if v.get("joint") not in joints}
    path = folder / f"{name}.yaml"
    path.write_text(yaml.safe_dump({ns: {name: entry, **kept}}, sort_keys=False))
    return path


def certify_seconds(folder: Path) -> dict[str, tuple[float, int]]:
    """Wall seconds and exit code of `mexone certify --at design` on the arm and one-foot LQRs."""
    lab = Lab.create()
    lab.sim.run(0.3)
    plant = linearize(lab, point=operating_point(lab, support="fixed"), joints=ARM, held="rigid",
                      fixed_base=True, period=0.002)
    K, _, _ = lqr(plant, np.diag([1000.0] * 3 + [1.0] * 3), np.eye(3))
    save_design(folder / "arm.npz", K, plant)
    arm = _yaml(folder, "arm_lqr", {"type": "mexone/StateFeedback", "joints": ARM,
                                    "update_rate": 500, "design_file": "arm.npz"})
    lq.setup(lab)
    point = lq.one_foot_pose(lab)
    d = lq.design(lab, point)
    save_design(folder / "one_foot.npz", d.K, d.sys)
    joints = [n.split(":")[0] for n in d.sys.input_labels]
    foot = _yaml(folder, "balance", {"type": "mexone/StateFeedback", "joints": joints,
                                     "update_rate": 1000, "design_file": "one_foot.npz"})
    out = {}
    for name, path in (("arm LQR", arm), ("one-foot LQR", foot)):
        start = time.perf_counter()
        done = subprocess.run([sys.executable, "-m", "mexone", "certify", str(path), "--at",
                               "design", "--settle", "0.5", "--json"], capture_output=True,
                              text=True)
        out[name] = (time.perf_counter() - start, done.returncode)
    return out


def region_seconds(shape: tuple[int, int], threads: int) -> tuple[float, float, float]:
    """(wall s, CPU s, fraction back) of the one-foot LQR's region over pushes."""
    lab = Lab.create()
    lq.setup(lab)
    point = lq.one_foot_pose(lab)
    d = lq.design(lab, point)
    run = lq._fresh_lab(point, False)
    controller = deploy(run, d.K, d.sys, name="balance")
    run.sim.run(0.3)
    cpu = time.process_time()
    region = region_of_attraction(run, controller, d.sys, {"base:vx": (-0.25, 0.25),
                                                           "base:vy": (-0.2, 0.2)},
                                  shape=shape, duration=1.5, threads=threads)
    return region.seconds, time.process_time() - cpu, region.fraction


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grid", default="40x25", help="region grid (default 40x25 = 1000)")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--skip-region", action="store_true")
    args = parser.parse_args()
    print(f"start: {load()}")
    ours, raw, ratio = linearize_ratio()
    print(f"linearize at the standing point {ours:.2f} ms, raw mjd_transitionFD {raw:.2f} ms: "
          f"{ratio:.2f}x (median of 200 paired ratios)   [{load()}]", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        for name, (seconds, code) in certify_seconds(Path(tmp)).items():
            print(f"mexone certify {name}: {seconds:.1f} s wall, exit {code}   [{load()}]",
                  flush=True)
    if not args.skip_region:
        shape = tuple(int(n) for n in args.grid.split("x"))
        wall, cpu, back = region_seconds(shape, args.threads)
        print(f"region of attraction, {shape[0] * shape[1]} pushes x 1.5 s, {args.threads} "
              f"threads: {wall:.1f} s wall, {cpu:.1f} CPU s, {100 * back:.0f} % came back   "
              f"[{load()}]")


if __name__ == "__main__":
    main()
