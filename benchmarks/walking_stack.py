"""The walking stack's numbers (issue 39), with today's position-controlled walk in the same run:
the COM MPC per solve and the whole-body QP per solve (problems recorded from a walk, solved
again by each solver), each part's time per update (CPU time), the stack's real-time factor at
the shipped rates and with every part at 500 Hz, 60 s of walking paced at real time (each part's
deadline misses), the largest 0.1 s torso push survived while walking, forward and sideways,
and the same for `mexone run walk`.

    OMP_NUM_THREADS=1 env PYTHONPATH=src python benchmarks/walking_stack.py [--seconds 60] [--quick]
    OMP_NUM_THREADS=1 env PYTHONPATH=src python benchmarks/walking_stack.py --pushes [--phases]
    OMP_NUM_THREADS=1 env PYTHONPATH=src python benchmarks/walking_stack.py --phases fine
    OMP_NUM_THREADS=1 env PYTHONPATH=src python benchmarks/walking_stack.py --cpu [--seconds 60]

--cpu: only each part's thread CPU time per update (median, p99, p99.9, max) and every garbage
collection over `--seconds` of walking through the lab's loop unpaced, then the paced walk's
deadline misses; --quick: the solves, the per-update costs, the 60 s paced walk and today's
walk (no courses, no pushes); --pushes: only the push scans (a bisection over 2-8 N s: 3 walks
per direction and walker), --phases with 6 N s at each tenth of a stride; --phases fine: only
6 N s pushed left and right every 0.025 s from 5.0 to 5.775 s (32 phases each) and forward every
0.1 s (8), 72 pushes on forks of one warmed-up walk, 2 at a time (as tests/walking/test_pushes.py
runs its 24): each direction's S/F string and each push's lowest base.

The machine is shared: the load average is printed before and after. What the code costs is
measured on a core of its own: run it as root under `chrt -f 20 taskset -c 1` (SCHED_FIFO on one
core: other processes do not preempt it; the paced run sleeps, so the kernel's real-time
throttling never cuts in); without, the figures are the machine's load as much as the code's.
Record the figures in benchmarks/RESULTS.md.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import math
import os
import time

import numpy as np
import yaml

from mexone.lab import Lab
from mexone.robots import mex_one
from mexone.routines.runner import RoutineRunner

PUSH_AT = 5.0  # s: the push lands while walking at full speed
FALLEN = 0.4  # m: the base lower than this is a fall


def record_problems(seconds: float = 7.0) -> dict:
    """Every COM MPC and whole-body QP the shipped stack solves walking at 0.3 m/s for
    `seconds`, pushed 4 N s forward at 5 s: (args, kwargs) of each solve, and the solvers."""
    from mexone.walking import mpc, wbc

    problems: dict = {"mpc": [], "wbc": []}
    solve_mpc, solve_wbc = mpc.LipmMpc.solve, wbc.WholeBodyQP.solve

    def rec_mpc(self, *args, **kwargs):
        problems["mpc"].append(copy.deepcopy((args, kwargs)))
        return solve_mpc(self, *args, **kwargs)

    def rec_wbc(self, *args, **kwargs):
        problems["wbc"].append(copy.deepcopy((args, kwargs)))
        return solve_wbc(self, *args, **kwargs)

    mpc.LipmMpc.solve, wbc.WholeBodyQP.solve = rec_mpc, rec_wbc
    try:
        lab = stack()
        lab.sim.apply_wrench("torso", [40.0, 0.0, 0.0], duration=0.1, start=5.0)
        lab.sim.step(round((seconds - 1.0) / lab.sim.model.opt.timestep))
    finally:
        mpc.LipmMpc.solve, wbc.WholeBodyQP.solve = solve_mpc, solve_wbc
    parts = lab.manager.controllers
    problems["mpc_of"] = parts["com_planner"].impl.mpc
    problems["wbc_of"] = parts["whole_body"].impl.qp
    return problems


def bare_step_ms(steps: int = 3000) -> float:
    """CPU ms per bare MuJoCo step of Mex-One walking (the state of a walk, no controller): the
    yardstick the parts' costs are given against, measured in the same run (the machine's speed
    drifts with its load by tens of percent; the ratios do not)."""
    import mujoco

    lab = stack()
    lab.sim.step(2000)
    model, data = lab.sim.model, mujoco.MjData(lab.sim.model)
    data.qpos[:], data.qvel[:], data.ctrl[:] = lab.sim.data.qpos, lab.sim.data.qvel, lab.sim.data.ctrl
    data.qfrc_applied[:] = lab.sim.data.qfrc_applied
    start = time.thread_time()
    for _ in range(steps):
        mujoco.mj_step(model, data)
    return (time.thread_time() - start) / steps * 1e3


def solve_times(problems: dict, solver: str) -> dict:
    """ms per solve (median, p99) of the recorded problems, each solved again by `solver`, and
    how many it found no solution to."""
    from mexone.walking import mpc, qp, wbc

    m, w = problems["mpc_of"], problems["wbc_of"]
    solvers = {"mpc": mpc.LipmMpc(m.h, m.T, m.n, w_jerk=m.w_jerk, w_shift=m.w_shift,
                                  max_shift=m.max_shift, solver=solver),
               "wbc": wbc.WholeBodyQP(w.nv, w.actuated, w.limit, mu=w.mu, solver=solver)}
    out = {}
    for name, obj in solvers.items():
        times, failed = [], 0
        for _ in range(2):  # the first pass warms the caches
            times, failed = [], 0
            for args, kwargs in problems[name]:
                start = time.perf_counter()
                try:
                    obj.solve(*args, **kwargs)
                except qp.Infeasible:
                    failed += 1
                times.append(time.perf_counter() - start)
        t = np.array(times) * 1e3
        out[name] = (len(t), float(np.median(t)), float(np.percentile(t, 99)), failed)
    return out


def per_update(seconds: float, every_500: bool) -> dict:
    """CPU ms per update of each part (median, p99) and the stack's real-time factor (wall and
    per CPU second), walking at 0.3 m/s; `every_500`: every part at 500 Hz."""
    lab = stack(rates=500 if every_500 else None)
    times: dict[str, list[float]] = {}
    for name, runner in lab.manager.controllers.items():
        impl = getattr(runner, "impl", None)
        if impl is None:
            continue
        spent = times.setdefault(name, [])

        def timed(state, t, dt, update=impl.update, spent=spent):
            start = time.thread_time()
            out = update(state, t, dt)
            spent.append(time.thread_time() - start)
            return out

        impl.update = timed
    lab.sim.step(2000)  # up to speed
    for spent in times.values():
        spent.clear()
    wall, cpu = time.perf_counter(), time.process_time()
    lab.sim.step(round(seconds / lab.sim.model.opt.timestep))
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    parts = {name: (len(t), float(np.median(t) * 1e3), float(np.percentile(t, 99) * 1e3))
             for name, t in ((n, np.array(v)) for n, v in times.items())}
    return {"rtf_wall": seconds / wall, "rtf_cpu": seconds / cpu, "parts": parts}


def cpu_profile(seconds: float) -> dict:
    """`seconds` of walking at 0.3 m/s (shipped rates) as fast as the machine goes, through the
    lab's loop (`Simulation.run`, unpaced): each part's THREAD CPU time per update (ns, every
    update: what another process's load does not add) and every garbage collection (generation,
    CPU ns, inside a part's update or not). Wall-clock misses on a shared machine mostly measure
    the other processes; this is what the code costs."""
    import gc
    import resource

    usage, thread = resource.getrusage, resource.RUSAGE_THREAD
    lab = stack()
    spent: dict[str, list[int]] = {}
    inside = [""]
    clock = time.thread_time_ns
    for name, runner in lab.manager.controllers.items():
        impl = getattr(runner, "impl", None)
        if impl is None:
            continue
        times = spent.setdefault(name, [])

        def timed(state, t, dt, update=impl.update, times=times, name=name):
            inside[0] = name
            switches = usage(thread).ru_nivcsw
            start = clock()
            out = update(state, t, dt)
            elapsed = clock() - start
            # preempted meanwhile (its caches someone else's when it came back): flagged negative
            times.append(elapsed if usage(thread).ru_nivcsw == switches else -elapsed)
            inside[0] = ""
            return out

        impl.update = timed
    collections: list[tuple[int, int, str]] = []  # generation, CPU ns, the part it ran in
    began = [0]

    def watch(phase: str, info: dict) -> None:
        if phase == "start":
            began[0] = clock()
        else:
            collections.append((info["generation"], clock() - began[0], inside[0]))

    lab.sim.run(2.0)  # up to speed
    for times in spent.values():
        times.clear()
    gc.callbacks.append(watch)
    try:
        cpu = time.process_time()
        lab.sim.run(seconds)
        cpu = time.process_time() - cpu
    finally:
        gc.callbacks.remove(watch)
    return {"rtf_cpu": seconds / cpu, "parts": {n: np.array(v) for n, v in spent.items()},
            "deadline_ms": {n: c.budget()["deadline_ms"] for n, c in lab.manager.controllers.items()
                            if hasattr(c, "budget")},
            "collections": collections}


def print_profile(result: dict) -> None:
    """The per-part CPU distributions and the collections, one line each."""
    print(f"  {result['rtf_cpu']:.2f} s of sim per CPU second")
    for name, t in result["parts"].items():
        ms, alone = np.abs(t) / 1e6, t >= 0
        deadline = result["deadline_ms"][name]
        over = ms > deadline
        print(f"  {name:12s} CPU per update (ms): median {np.median(ms):.3f}, p99 "
              f"{np.percentile(ms, 99):.3f}, p99.9 {np.percentile(ms, 99.9):.3f}, max {ms.max():.3f} "
              f"(not preempted: max {ms[alone].max():.3f}); over its {deadline:g} ms deadline: "
              f"{int(over.sum())} of {len(ms)}, {int((over & alone).sum())} not preempted")
    for gen in (0, 1, 2):
        mine = [(ns, part) for g, ns, part in result["collections"] if g == gen]
        if not mine:
            print(f"  gc generation {gen}: none")
            continue
        ms = np.array([ns for ns, _ in mine]) / 1e6
        during = sum(1 for _, part in mine if part)
        print(f"  gc generation {gen}: {len(ms)} collections, CPU median {np.median(ms):.3f} ms, "
              f"max {ms.max():.3f} ms; {during} inside a part's update")


def stack(vx: float = 0.3, world=None, rates: int | None = None) -> Lab:
    """The shipped stack walking at `vx` after a second's settling; `rates`: every part's."""
    controllers = mex_one.walking_path()
    if rates is not None:
        import re
        import tempfile

        text = re.sub(r"update_rate: \d+", f"update_rate: {rates}", controllers.read_text())
        controllers = os.path.join(tempfile.mkdtemp(), "walking.yaml")
        with open(controllers, "w") as out:
            out.write(text)
    lab = Lab.create(controllers=controllers, world=world)
    lab.sim.step(1000)
    lab.manager.set_param("footsteps", "vx", vx)
    return lab


def walk_stack(seconds: float) -> dict:
    """`seconds` of walking at 0.3 m/s paced at real time (as `mexone sim` runs): the distance,
    the lowest base, each part's real-time budget (deadline misses) and report."""
    lab = stack()
    sim = lab.sim
    sim.target_rtf = 1.0
    x0 = float(sim.data.qpos[0])
    wall, cpu = time.perf_counter(), time.process_time()
    lowest = [1.0]
    sim.run(seconds, on_tick=lambda s: lowest.__setitem__(0, min(lowest[0], float(s.data.qpos[2]))))
    lowest = lowest[0]
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    mgr = lab.manager
    parts = {n: c for n, c in mgr.controllers.items() if hasattr(c, "budget")}
    return {"seconds": seconds, "distance": float(sim.data.qpos[0]) - x0, "lowest": lowest,
            "rtf_wall": seconds / wall, "rtf_cpu": seconds / cpu,
            "budget": {n: c.budget() for n, c in parts.items()},
            "reports": {n: c.impl.report() for n, c in parts.items()}}


def print_paced(result: dict, seconds: float) -> None:
    """walk_stack's figures: the walk, then each part's budget (wall clock: the machine's load
    counts) and report."""
    print(f"stack, {seconds:g} s at 0.3 m/s paced at real time: {result['distance']:.2f} m, "
          f"lowest base {result['lowest']:.3f} m, RTF {result['rtf_wall']:.2f} (wall), "
          f"{result['rtf_cpu']:.2f} (per CPU second)")
    for name, budget in result["budget"].items():
        print(f"  {name:12s} {budget['update_ms_mean']:.3f} ms/update (max {budget['update_ms_max']:.2f}), "
              f"deadline {budget['deadline_ms']:g} ms, {budget['deadline_misses']} missed of "
              f"{budget['updates']}; {result['reports'][name]}")


def survives_stack(impulse: float, direction: float, at: float = PUSH_AT) -> bool:
    """A 0.1 s push of `impulse` N s at the torso, `direction` rad (0 forward, pi/2 left),
    `at` s (walking at 0.3 m/s from 1 s): still standing 4 s later?"""
    lab = stack()
    sim = lab.sim
    force = impulse / 0.1
    sim.apply_wrench("torso", [force * math.cos(direction), force * math.sin(direction), 0.0],
                     duration=0.1, start=at)
    while sim.time < at + 4.0:
        sim.step(100)
        if sim.data.qpos[2] < FALLEN:
            return False
    return True


def course(world: str | None = None, seconds: float = 20.0) -> dict:
    """The issue's course on the shipped stack (the estimator in the loop): on flat ground 0.3
    m/s forward (speed over 3 s once up to speed), a stop, a quarter turn left, a stop, 1 m to
    the right; on `world` ("slope", "step") straight on at 0.3 m/s for `seconds`."""
    from mexone.physics.world import read_world

    lab = stack(world=read_world(mex_one.world_path(world)) if world else None)
    sim = lab.sim
    out: dict = {"lowest": 1.0}

    def run(seconds: float) -> None:
        for _ in range(round(seconds / 0.05)):
            sim.step(50)
            out["lowest"] = min(out["lowest"], float(sim.data.qpos[2]))

    def command(vx=0.0, vy=0.0, wz=0.0) -> None:
        for key, value in (("vx", vx), ("vy", vy), ("wz", wz)):
            lab.manager.set_param("footsteps", key, value)

    def yaw() -> float:
        q = sim.data.qpos
        return math.degrees(2 * math.atan2(q[6], q[3]))

    if world:
        run(seconds)
        out["x"] = float(sim.data.qpos[0])
    else:
        run(4.0)
        x0, t0 = float(sim.data.qpos[0]), sim.time
        run(3.0)
        out["speed"] = (float(sim.data.qpos[0]) - x0) / (sim.time - t0)
        command()
        run(1.5)
        yaw0, t0 = yaw(), sim.time
        command(wz=0.75)
        while yaw() - yaw0 < 90.0 and sim.time < t0 + 15.0:
            run(0.1)
        out["turn_s"] = sim.time - t0 if yaw() - yaw0 >= 90.0 else math.inf
        command()
        run(1.5)
        heading, start, t0 = math.radians(yaw()), sim.data.qpos[:2].copy(), sim.time

        def right() -> float:
            moved = sim.data.qpos[:2] - start
            return -(-moved[0] * math.sin(heading) + moved[1] * math.cos(heading))

        command(vy=-0.3)
        while right() < 1.0 and sim.time < t0 + 30.0:
            run(0.1)
        out["sideways_s"] = sim.time - t0 if right() >= 1.0 else math.inf
        command()
        run(1.5)
    out["reports"] = {n: c.impl.report() for n, c in lab.manager.controllers.items()
                      if hasattr(c, "impl")}
    return out


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


def largest(survives, impulses: list[float]) -> float:
    """The largest of the rising `impulses` survived, by bisection (survival taken as monotonic
    in the impulse: log2 of the list's length runs, 3 for 7 values); 0 when the first falls."""
    low, high = -1, len(impulses)  # impulses[low] survived, impulses[high] fell
    while high - low > 1:
        mid = (low + high) // 2
        if survives(impulses[mid]):
            low = mid
        else:
            high = mid
    return impulses[low] if low >= 0 else 0.0


def push_scan(phases: bool) -> None:
    """The largest push survived while walking, the stack's (0.3 m/s) and today's walk's (~0.17
    m/s), forward and sideways, in one run; `phases`: 6 N s at each tenth of a stride too."""
    impulses = [2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0]
    for label, direction in (("forward", 0.0), ("sideways (left)", math.pi / 2),
                             ("sideways (right)", -math.pi / 2)):
        cpu = time.process_time()
        mine = largest(lambda i, d=direction: survives_stack(i, d), impulses)
        theirs = largest(lambda i, d=direction: routine_walk(i, d)[0], impulses)
        print(f"largest push survived while walking, {label}, at t = {PUSH_AT:g} s: stack "
              f"{mine:g} N s (at 0.3 m/s), today's walk {theirs:g} N s (at ~0.17 m/s) "
              f"[{time.process_time() - cpu:.0f} CPU s]", flush=True)
    if not phases:
        return
    at = [PUSH_AT + 0.1 * k for k in range(8)]  # a stride: two steps of 0.4 s
    for label, direction in (("forward", 0.0), ("left", math.pi / 2), ("right", -math.pi / 2)):
        stood = [survives_stack(6.0, direction, when) for when in at]
        print(f"6 N s {label} over a stride (pushed at {at[0]:g}..{at[-1]:g} s by 0.1 s): "
              f"survived {sum(stood)} of {len(stood)} ({''.join('S' if ok else 'F' for ok in stood)})",
              flush=True)


def fine_phases(at_once: int = 2, settings: tuple[str, ...] = ()) -> dict:
    """6 N s left and right every 0.025 s over 5.0-5.775 s and forward every 0.1 s over 5.0-5.7 s,
    each on a fork of one walk warmed up to 4.95 s (tests/walking/test_pushes.py's forks), with
    `settings` ("part.param=value", set before the walk starts: an A/B in one run):
    {(angle, at): (lowest base m, "" or what went wrong)}."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "walking"))
    import test_pushes as tp

    def push_one(lab: Lab, x0: float, angle: float, at: float) -> str:
        lowest: list = []
        verdict = tp._pushed(lab, x0, angle, at, lowest)
        return f"{lowest[0] if lowest else math.nan:.4f} {verdict}"

    pushes = [(a, round(5.0 + 0.025 * k, 3)) for a in (90, -90) for k in range(32)]
    pushes += [(0, round(5.0 + 0.1 * k, 1)) for k in range(8)]
    lab = tp._walking()
    for part in lab.manager.controllers.values():  # a loaded machine stalls a fork for seconds:
        if hasattr(part, "plugin"):               # that is no hang of the walking stack's
            part.plugin = dataclasses.replace(part.plugin, hang_timeout=60.0)
    for setting in settings:
        name, _, value = setting.partition("=")
        part, _, param = name.partition(".")
        lab.manager.set_param(part, param, yaml.safe_load(value))
    x0 = float(lab.sim.data.qpos[0])
    lab.sim.step(round((5.0 - 0.05 - lab.sim.time) / lab.sim.timestep))
    out = {}
    for push, said in tp._in_forks(lab, x0, pushes, at_once, push_one).items():
        lowest, _, verdict = said.partition(" ")
        try:
            out[push] = (float(lowest), verdict)
        except ValueError:  # the child died before it said
            out[push] = (math.nan, said)
    return out


def print_fine_phases(result: dict) -> None:
    """fine_phases' S/F string per direction, the survivors' lowest base and each fall."""
    for label, angle in (("left", 90), ("right", -90), ("forward", 0)):
        mine = sorted((at, r) for (a, at), r in result.items() if a == angle)
        flags = "".join("S" if not verdict else "F" for _, (_, verdict) in mine)
        stood = [low for _, (low, verdict) in mine if not verdict]
        print(f"6 N s {label}, {len(mine)} phases {mine[0][0]:g}..{mine[-1][0]:g} s: survived "
              f"{len(stood)} of {len(mine)} {flags}; survivors' lowest base "
              f"{min(stood) if stood else math.nan:.3f} m", flush=True)
        for at, (_, verdict) in mine:
            if verdict:
                print(f"  {label} at {at:g} s: {verdict}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="s of walking for the RTF")
    parser.add_argument("--quick", action="store_true", help="no push scans, no courses")
    parser.add_argument("--pushes", action="store_true", help="only the push scans")
    parser.add_argument("--cpu", action="store_true",
                        help="only each part's thread CPU time per update and the collections")
    parser.add_argument("--phases", nargs="?", const="tenths", choices=("tenths", "fine"),
                        help="6 N s at each tenth of a stride too (with --pushes); fine: only the "
                        "72 pushes every 0.025 s (left, right) and 0.1 s (forward), on forks")
    parser.add_argument("--set", action="append", default=[], metavar="PART.PARAM=VALUE",
                        help="with --phases fine: a part's parameter set before the walk starts")
    args = parser.parse_args()
    print(f"load average before: {os.getloadavg()}; scheduler: "
          f"{'SCHED_FIFO' if os.sched_getscheduler(0) == os.SCHED_FIFO else 'normal'}, "
          f"cores {sorted(os.sched_getaffinity(0))}")
    if args.cpu:
        print(f"stack, {args.seconds:g} s at 0.3 m/s through the lab's loop, unpaced (thread CPU time):")
        print_profile(cpu_profile(args.seconds))
        print_paced(walk_stack(args.seconds), args.seconds)
        print(f"load average after: {os.getloadavg()}")
        return
    if args.phases == "fine":
        wall, cpu = time.perf_counter(), time.process_time()
        print_fine_phases(fine_phases(settings=tuple(args.set)))
        forks = os.times()
        print(f"{time.perf_counter() - wall:.0f} s wall; CPU: {time.process_time() - cpu:.0f} s the "
              f"warm-up, {forks.children_user + forks.children_system:.0f} s the forks")
        print(f"load average after: {os.getloadavg()}")
        return
    if args.pushes:
        push_scan(bool(args.phases))
        print(f"load average after: {os.getloadavg()}")
        return
    bare = bare_step_ms()
    print(f"bare MuJoCo step of Mex-One walking: {bare * 1e3:.1f} us (CPU): the yardstick, 'x' below")
    problems = record_problems()
    import qpsolvers

    for solver in ["daqp"] + [s for s in ("proxqp", "osqp") if s in qpsolvers.available_solvers]:
        times = solve_times(problems, solver)
        for name, label in (("mpc", "COM MPC"), ("wbc", "whole-body QP")):
            n, median, p99, failed = times[name]
            none = f", no solution to {failed}" if failed else ""
            print(f"{label} per solve, {solver} ({n} problems from a walk): median {median:.3f} ms "
                  f"({median / bare:.1f}x), p99 {p99:.3f} ms{none}")
    for every in (False, True):
        result = per_update(8.0, every)
        print(f"stack walking 8 s, {'every part at 500 Hz' if every else 'shipped rates'}: RTF "
              f"{result['rtf_wall']:.2f} (wall), {result['rtf_cpu']:.2f} (per CPU second)")
        for name, (n, median, p99) in result["parts"].items():
            print(f"  {name:12s} CPU per update: median {median:.3f} ms ({median / bare:.1f}x), "
                  f"p99 {p99:.3f} ms ({n} updates)")
    print_paced(walk_stack(args.seconds), args.seconds)
    ok, speed, rtf_wall, rtf_cpu = routine_walk()
    print(f"today's walk (mexone run walk, 2 m): stood {ok}, {speed:.3f} m/s, RTF {rtf_wall:.2f} "
          f"(wall), {rtf_cpu:.2f} (per CPU second)")
    if not args.quick:
        flat = course()
        print(f"course, flat: {flat['speed']:.3f} m/s once up to speed, quarter turn in "
              f"{flat['turn_s']:.1f} s, 1 m to the right in {flat['sideways_s']:.1f} s, lowest base "
              f"{flat['lowest']:.3f} m; estimator {flat['reports']['estimator']}")
        for world in ("slope", "step"):
            walk = course(world)
            print(f"course, {world}.world 20 s at 0.3 m/s: x = {walk['x']:.2f} m (the terrain ends at "
                  f"5.5 m / 2.5 m), lowest base {walk['lowest']:.3f} m; "
                  f"{walk['reports']['whole_body']}")
        push_scan(bool(args.phases))
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
