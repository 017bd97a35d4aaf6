"""Cost of mexone's layers over bare MuJoCo on the same compiled Mex-One model.

    python benchmarks/control_overhead.py [--seconds 5] [--repeats 5]

Every figure is measured in this one run, so the ratios hold on a noisy machine. The bare rows
step the very model mexone compiled, with the same actuator settings and controls, so the ratio
is what mexone's Python layers add:
  physics only         Simulation.step (watchdog, event scheduling) vs mj_step; no controllers
  controllers          21 PID position controllers + joint_state_controller at 50 Hz
  controllers + I      the same with an active integral term on every joint (Python per step)
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

import mujoco

from mexone.control import load_control_config
from mexone.lab import Lab
from mexone.robots import mex_one


def wall_per_sim_second(step, reset, sim_seconds: float, repeats: int, dt: float) -> float:
    best = float("inf")
    n = round(sim_seconds / dt)
    for _ in range(repeats):
        reset()
        start = time.perf_counter()
        step(n)
        best = min(best, time.perf_counter() - start)
    return best / sim_seconds


def _pair(name: str, lab: Lab, sim_seconds: float, repeats: int) -> tuple[str, float, float]:
    """(name, bare wall s per sim s, mexone wall s per sim s) on the lab's own model."""
    model = lab.sim.model
    data = mujoco.MjData(model)
    dt = model.opt.timestep
    lab.sim.reset()
    ctrl = lab.sim.data.ctrl.copy()

    def bare_reset() -> None:
        mujoco.mj_resetData(model, data)
        data.ctrl[:] = ctrl

    bare = wall_per_sim_second(lambda n: mujoco.mj_step(model, data, n), bare_reset,
                               sim_seconds, repeats, dt)
    ours = wall_per_sim_second(lab.sim.step, lab.sim.reset, sim_seconds, repeats, dt)
    return name, bare, ours


def rows(sim_seconds: float, repeats: int) -> list[tuple[str, float, float]]:
    config = load_control_config(mex_one.controllers_path())
    for name, spec in config.controllers.items():
        if spec.pid:
            config.controllers[name] = replace(spec, pid=replace(spec.pid, i=1.0, i_clamp_min=-1.0,
                                                                 i_clamp_max=1.0))
    return [
        _pair("physics only", Lab.create(controllers=False), sim_seconds, repeats),
        _pair("controllers", Lab.create(), sim_seconds, repeats),
        _pair("controllers + I", Lab.create(controllers=config), sim_seconds, repeats),
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=5.0, help="sim seconds per measurement")
    parser.add_argument("--repeats", type=int, default=5, help="best of this many")
    args = parser.parse_args()
    print(f"{'Mex-One, 1 ms steps':<20} {'bare s/sim s':>13} {'mexone s/sim s':>15} "
          f"{'overhead':>9}")
    for name, bare, ours in rows(args.seconds, args.repeats):
        print(f"{name:<20} {bare:13.4f} {ours:15.4f} {ours / bare:9.3f}")


if __name__ == "__main__":
    main()
