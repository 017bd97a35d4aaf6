"""The walking stack's numbers (issue 39), with today's position-controlled walk in the same run:
the COM MPC per solve and the whole-body QP per update, 60 s of torque-level walking at 0.3 m/s
(real-time factor, each part's real-time budget and deadline misses), the largest 0.1 s torso
push survived while walking, forward and sideways, and the same for `mexone run walk`.

    OMP_NUM_THREADS=1 env PYTHONPATH=src python benchmarks/walking_stack.py [--seconds 60] [--quick]

The machine is shared: the load average is printed before and after. Record the figures in
benchmarks/RESULTS.md.
"""

from __future__ import annotations

import argparse
import math
import os
import time

import numpy as np

from mexone.lab import Lab
from mexone.robots import mex_one
from mexone.routines.runner import RoutineRunner
from mexone.walking.footsteps import FootstepPlanner, Gait
from mexone.walking.mpc import LipmMpc, supports

PUSH_AT = 5.0  # s: the push lands while walking at full speed
FALLEN = 0.4  # m: the base lower than this is a fall


def mpc_solve_times(n: int = 2000) -> np.ndarray:
    """s per COM MPC solve (the ComPlanner's defaults), over a model walk at 0.3 m/s."""
    mpc = LipmMpc(0.54, 0.05, 24, w_shift=0.3, max_shift=0.2)
    planner = FootstepPlanner(Gait(), np.array([[0, 0.06, 0, 0], [0, -0.06, 0, 0]]))
    planner.set_command(0.3, 0.0, 0.0)
    x, y = np.zeros(3), np.zeros(3)
    times = []
    for k in range(n):
        t = k * 0.002
        sup = supports(planner.update(t), t, 0.05, 24, (0.16, 0.08), 0.015)
        start = time.perf_counter()
        jx, jy, _ = mpc.solve(x, y, sup)
        times.append(time.perf_counter() - start)
        x, y = LipmMpc.advance(x, jx[0], 0.002), LipmMpc.advance(y, jy[0], 0.002)
    return np.array(times)


def stack(vx: float = 0.3, world=None) -> Lab:
    lab = Lab.create(controllers=mex_one.walking_path(), world=world)
    lab.sim.step(1000)
    lab.controllers.set_param("footsteps", "vx", vx)
    return lab


def walk_stack(seconds: float) -> dict:
    lab = stack()
    sim = lab.sim
    x0 = float(sim.data.qpos[0])
    wall, cpu = time.perf_counter(), time.process_time()
    lowest = 1.0
    for _ in range(round(seconds / 0.1)):
        sim.step(100)
        lowest = min(lowest, float(sim.data.qpos[2]))
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    mgr = lab.controllers
    parts = {n: c for n, c in mgr.controllers.items() if hasattr(c, "budget")}
    return {"seconds": seconds, "distance": float(sim.data.qpos[0]) - x0, "lowest": lowest,
            "rtf_wall": seconds / wall, "rtf_cpu": seconds / cpu,
            "budget": {n: c.budget() for n, c in parts.items()},
            "reports": {n: c.impl.report() for n, c in parts.items()}}


def survives_stack(impulse: float, direction: float) -> bool:
    lab = stack()
    sim = lab.sim
    force = impulse / 0.1
    sim.apply_wrench("torso", [force * math.cos(direction), force * math.sin(direction), 0.0],
                     duration=0.1, start=PUSH_AT)
    for _ in range(50):  # 5 s after the start of walking: the push and 4 s to fall or not
        sim.step(100)
        if sim.data.qpos[2] < FALLEN:
            return False
    return True


def routine_walk(impulse: float = 0.0, direction: float = 0.0) -> tuple[bool, float, float, float]:
    """`mexone run walk` over 2 m forward: (stood, speed m/s, RTF wall, RTF per CPU second)."""
    lab = Lab.create()
    sim = lab.sim
    if impulse:
        force = impulse / 0.1
        sim.apply_wrench("torso", [force * math.cos(direction), force * math.sin(direction), 0.0],
                         duration=0.1, start=PUSH_AT)
    runner = RoutineRunner(lab, "walk", {"_course": [["forward", 2.0]]})
    wall, cpu = time.perf_counter(), time.process_time()
    lowest = [1.0]
    runner.run(None, on_tick=lambda s: lowest.__setitem__(0, min(lowest[0], float(s.data.qpos[2]))))
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    walked = float(sim.data.qpos[0])
    return lowest[0] > FALLEN, walked / max(sim.time - 2.0, 1e-9), sim.time / wall, sim.time / cpu


def largest(survives, impulses) -> float:
    """The largest impulse of a rising scan survived before the first fall."""
    best = 0.0
    for impulse in impulses:
        if not survives(impulse):
            break
        best = impulse
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="s of walking for the RTF")
    parser.add_argument("--quick", action="store_true", help="no push scans")
    args = parser.parse_args()
    print(f"load average before: {os.getloadavg()}")
    t = mpc_solve_times() * 1e3
    print(f"COM MPC per solve (standalone, 2000 solves): median {np.median(t):.3f} ms, "
          f"p99 {np.percentile(t, 99):.3f} ms")
    result = walk_stack(args.seconds)
    print(f"stack, {args.seconds:g} s at 0.3 m/s: {result['distance']:.2f} m "
          f"({result['distance'] / (args.seconds - 0.6):.3f} m/s), lowest base {result['lowest']:.3f} m, "
          f"RTF {result['rtf_wall']:.2f} (wall), {result['rtf_cpu']:.2f} (per CPU second)")
    for name, budget in result["budget"].items():
        print(f"  {name:12s} {budget['update_ms_mean']:.3f} ms/update (max {budget['update_ms_max']:.2f}), "
              f"deadline {budget['deadline_ms']:g} ms, {budget['deadline_misses']} missed of "
              f"{budget['updates']}; {result['reports'][name]}")
    ok, speed, rtf_wall, rtf_cpu = routine_walk()
    print(f"today's walk (mexone run walk, 2 m): stood {ok}, {speed:.3f} m/s, RTF {rtf_wall:.2f} "
          f"(wall), {rtf_cpu:.2f} (per CPU second)")
    if not args.quick:
        impulses = [2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0]
        for label, direction in (("forward", 0.0), ("sideways (left)", math.pi / 2)):
            mine = largest(lambda i, d=direction: survives_stack(i, d), impulses)
            theirs = largest(lambda i, d=direction: routine_walk(i, d)[0], impulses)
            print(f"largest push survived while walking, {label}: stack {mine:g} N s "
                  f"(at 0.3 m/s), today's walk {theirs:g} N s (at ~0.17 m/s)")
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
