"""Gain sweeps: the same experiment many times with different PID gains, in parallel.

A trial sets the gains of the swept joints on the full robot (controllers as configured), then
runs either a step response of one joint or a whole routine, and reports rise time, overshoot,
settling time, IAE, the largest effort and whether the robot fell. The simulation is
deterministic, so a trial's numbers do not depend on which worker -- or which backend, local
processes or a Ray cluster -- ran it.
"""

from __future__ import annotations

import csv
import itertools
import json
import math
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from mexone import signals
from mexone.cluster import ray_session
from mexone.control.metrics import overshoot, rise_time, settling_time
from mexone.control.spec import PidGains, controller_name
from mexone.errors import InputError
from mexone.lab import Lab, cached_lab
from mexone.physics.monitor import has_fallen
from mexone.ranges import GAINS, number_text

__all__ = ["SweepSpec", "Trial", "grid_trials", "random_trials", "run_trial", "run_sweep",
           "parse_range", "best_row", "best_yaml", "heatmap", "METRICS", "GAIN_KEYS"]

#: the gains a sweep varies (a PID's terms and its integral clamp)
GAIN_KEYS = ("p", "i", "d", "i_clamp")
#: what each trial measures: a row's columns, and what the best trial is chosen by
METRICS = ("rise_time", "overshoot", "settling_time", "iae", "max_effort", "fell")
DEFAULT_STEP = 0.5  # rad
STEP_AT = 0.1  # s: the step command comes after the robot has settled on its feet
POLL = 0.1  # s between looks at signals.requested() while the workers run


@dataclass(frozen=True)
class SweepSpec:
    joints: tuple[str, ...]  # whose gains are swept; the first one takes the step
    step: float = 0.5  # rad, step-response mode (the CLI's default: DEFAULT_STEP toward room)
    routine: str | None = None  # routine mode instead of a step
    duration: float = 2.0  # s of sim time per trial
    model: str | None = None  # None: built-in Mex-One
    controllers: str | None = None

    def key(self) -> str:
        """What identifies the sweep (its definition, for --resume)."""
        return json.dumps(asdict(self), sort_keys=True)


@dataclass(frozen=True)
class Trial:
    index: int
    gains: dict[str, float] = field(default_factory=dict)


MAX_VALUES = 10_000  # per gain range: more is a typo, and a grid of them would never end


def parse_range(text: str, name: str) -> np.ndarray:
    """'40' | '20,40,80' | '10:200:8' (start:stop:count, inclusive, linear)."""
    try:
        if ":" in text:
            start, stop, count = text.split(":")
            if not 1 <= int(count) <= MAX_VALUES:
                raise InputError(f"--{name} '{text}': the count must be 1 to {MAX_VALUES}",
                                 hint="e.g. --p 20:200:10")
            values = np.linspace(float(start), float(stop), int(count))
        else:
            values = np.array([float(v) for v in text.split(",")])
            if values.size > MAX_VALUES:
                raise InputError(f"--{name}: more than {MAX_VALUES} values")
    except ValueError:
        raise InputError(f"--{name} '{text}' is not a value, a list a,b,c or start:stop:count",
                         hint="e.g. --p 20:200:10") from None
    if not np.isfinite(values).all() or (values < 0).any() or values.size == 0:
        raise InputError(f"--{name} '{text}': gains must be finite and >= 0")
    if name in GAINS and not all(GAINS[name].contains(v) for v in values):
        worst = max(values)
        raise InputError(f"--{name} '{text}': {number_text(worst)} must be {GAINS[name].describe()}")
    return values


def grid_trials(ranges: dict[str, np.ndarray]) -> list[Trial]:
    """Every combination of the gains' values (key -> values), numbered."""
    keys = list(ranges)
    return [Trial(i, {k: float(v) for k, v in zip(keys, combo, strict=True)})
            for i, combo in enumerate(itertools.product(*(ranges[k] for k in keys)))]


def random_trials(ranges: dict[str, np.ndarray], count: int, seed: int = 0) -> list[Trial]:
    """Uniform in [min, max] of each range (log-uniform would need positive bounds)."""
    rng = np.random.default_rng(seed)
    return [Trial(i, {k: float(rng.uniform(v.min(), v.max())) for k, v in ranges.items()})
            for i in range(count)]


# ----- one trial ---------------------------------------------------------------------------------
def _lab(spec: SweepSpec) -> Lab:
    """This worker's Lab for `spec`, back at home (compiling costs more than a trial)."""
    lab = cached_lab(spec.model, spec.controllers)
    if lab.manager is None:
        raise InputError("the robot has no controllers to tune", hint="give --controllers")
    lab.sim.reset()  # controllers restart, holding home, with the configured gains
    for ctrl in lab.manager.controllers.values():
        if ctrl.gains is not None:
            lab.manager.set_gains(ctrl.name, [ctrl.pid_for(j) for j in ctrl.joints])
    return lab


def _apply_gains(lab: Lab, spec: SweepSpec, gains: dict[str, float]) -> np.ndarray:
    manager = lab.manager
    by_joint = manager.by_joint()
    for joint in spec.joints:
        ctrl = by_joint.get(joint)
        if ctrl is None or not (ctrl.holds_position and ctrl.tunable):
            raise InputError(f"joint '{joint}' has no running position controller to tune")
        base = ctrl.gains[ctrl.joints.index(joint)]
        clamp = gains.get("i_clamp", max(abs(base.i_clamp_min), abs(base.i_clamp_max)))
        tuned = PidGains(p=gains.get("p", base.p), i=gains.get("i", base.i),
                         d=gains.get("d", base.d), i_clamp_min=-clamp, i_clamp_max=clamp,
                         antiwindup=base.antiwindup)
        manager.set_gains(ctrl.name, tuned, joints=[joint])
    return manager.hw.rows(spec.joints)


def run_trial(spec: SweepSpec, trial: Trial) -> dict:
    """One trial in a lab of its own: the gains set, the step applied, the metrics (a row)."""
    lab = _lab(spec)
    sim = lab.sim
    rows = _apply_gains(lab, spec, trial.gains)
    start_height = sim.base_height
    metrics = _routine_trial(lab, spec, rows) if spec.routine else _step_trial(lab, spec, rows[0])
    metrics["fell"] = has_fallen(sim, start_height)
    metrics["max_effort"] = float(metrics["max_effort"])
    return {"index": trial.index, **trial.gains, **metrics}


def _home_and_limits(lab: Lab, joint: str) -> tuple[float, float, float]:
    hw = lab.manager.hw
    row = int(hw.rows((joint,))[0])
    return float(hw.position(np.array([row]))[0]), float(hw.lower[row]), float(hw.upper[row])


def toward_room(lab: Lab, spec: SweepSpec) -> float:
    """The step's size, signed toward the first joint's farther limit from home (l_elbow's
    home sits 0.1 rad below its upper limit: its default step goes down)."""
    start, lower, upper = _home_and_limits(lab, spec.joints[0])
    return abs(spec.step) if upper - start >= start - lower else -abs(spec.step)


def step_target(lab: Lab, spec: SweepSpec) -> float:
    """Where the step sends the first joint from its home; a step the joint's limits would
    clip to (nearly) nothing is refused: its metrics would measure nothing."""
    joint = spec.joints[0]
    start, lower, upper = _home_and_limits(lab, joint)
    target = float(np.clip(start + spec.step, lower, upper))
    if abs(target - start) < 0.5 * abs(spec.step):
        room = upper - start if spec.step > 0 else lower - start
        raise InputError(f"--step {spec.step:g} rad from {joint}'s home ({start:.3f} rad) leaves "
                         f"its limits [{lower:.3f}, {upper:.3f}]",
                         hint=f"give a step of at most {room:+.3f} rad")
    return target


def _step_trial(lab: Lab, spec: SweepSpec, row: int) -> dict:
    sim, hw, manager = lab.sim, lab.manager.hw, lab.manager
    joint = spec.joints[0]
    start = float(hw.position(np.array([row]))[0])
    target = step_target(lab, spec)
    sim.step(round(STEP_AT / sim.timestep))
    manager.command(manager.by_joint()[joint].name, {joint: target})
    n = round((spec.duration - STEP_AT) / sim.timestep)
    q, effort = np.empty(n), np.empty(n)
    one = np.array([row])
    for k in range(n):
        if k % 500 == 0:
            signals.check()  # --workers 1 runs trials in the CLI's process: stop between steps
        sim.step(1)
        q[k] = hw.position(one)[0]
        effort[k] = hw.effort(one)[0]
    t = np.arange(1, n + 1) * sim.timestep
    return {"rise_time": rise_time(t, q, start, target), "overshoot": overshoot(q, start, target),
            "settling_time": settling_time(t, q, target, target - start),
            "iae": float(np.abs(target - q).sum() * sim.timestep),
            "max_effort": np.abs(effort).max()}


def _routine_trial(lab: Lab, spec: SweepSpec, rows: np.ndarray) -> dict:
    from mexone.routines.runner import RoutineRunner

    sim, hw, manager = lab.sim, lab.manager.hw, lab.manager
    totals = {"iae": 0.0, "max_effort": 0.0}

    def sample(s) -> None:
        error = manager.setpoints()[rows] - hw.position(rows)
        totals["iae"] += float(np.abs(error).sum()) * 0.01
        totals["max_effort"] = max(totals["max_effort"], float(np.abs(hw.effort(rows)).max()))

    timer = sim.add_periodic(0.01, sample)
    try:
        RoutineRunner(lab, spec.routine).run(spec.duration, hold=True)  # failed: RoutineError
    finally:
        sim.remove_periodic(timer)
    return {"rise_time": None, "overshoot": None, "settling_time": None, **totals}


# ----- many trials ---------------------------------------------------------------------------------
def _completed(csv_path: Path) -> dict[int, dict]:
    if not csv_path.exists():
        return {}
    with csv_path.open() as handle:
        return {int(r["index"]): r for r in csv.DictReader(handle)}


def run_sweep(spec: SweepSpec, trials: list[Trial], out_csv: Path, workers: int,
              backend: str = "local", address: str | None = None,
              progress: Callable[[int], None] | None = None) -> list[dict]:
    """Run the trials not yet in out_csv (so an interrupted sweep resumes), appending each
    result as it finishes. Returns every row, finished before or now, in trial order."""
    done = _completed(out_csv)
    todo = [t for t in trials if t.index not in done]
    columns = ["index", *trials[0].gains, *METRICS] if trials else ["index", *METRICS]
    new_file = not out_csv.exists()
    with out_csv.open("a", newline="") as handle:
        writer = csv.DictWriter(handle, columns, extrasaction="ignore")
        if new_file:
            writer.writeheader()
        runner = _ray_results if backend == "ray" else _local_results
        for row in runner(spec, todo, workers, address):
            writer.writerow({k: ("" if v is None else v) for k, v in row.items()})
            handle.flush()
            done[row["index"]] = row
            if progress:
                progress(1)
    return [done[t.index] for t in trials if t.index in done]


def _local_results(spec: SweepSpec, trials: list[Trial], workers: int, _address) -> Iterator[dict]:
    """Finished trials as they come. A signal (signals.requested) ends the sweep between two
    results: the workers are ended (their runs are lost, the finished ones are kept)."""
    if workers <= 1:
        for trial in trials:
            row = run_trial(spec, trial)
            if signals.requested():  # a routine trial ends early on a signal: not a result
                return
            yield row
        return
    pool = ProcessPoolExecutor(workers, initializer=signals.leave_to_parent)
    stopped = True
    try:
        pending = {pool.submit(run_trial, spec, t) for t in trials}
        while pending and not signals.requested():
            finished, pending = wait(pending, timeout=POLL, return_when=FIRST_COMPLETED)
            for future in finished:
                yield future.result()
        stopped = bool(pending)
    finally:
        if stopped:  # a signal, an error, or the caller stopped asking: do not wait for runs
            _end_workers(pool)
        pool.shutdown(wait=True, cancel_futures=True)


def _end_workers(pool: ProcessPoolExecutor) -> None:
    """SIGTERM to every worker (ProcessPoolExecutor.terminate_workers from Python 3.14 on)."""
    terminate = getattr(pool, "terminate_workers", None)
    if terminate is not None:
        terminate()
        return
    for process in list((getattr(pool, "_processes", None) or {}).values()):
        if process.is_alive():
            process.terminate()


def _ray_results(spec: SweepSpec, trials: list[Trial], workers: int,
                 address: str | None) -> Iterator[dict]:
    with ray_session(workers, address) as ray:
        remote = ray.remote(run_trial)
        pending = [remote.remote(spec, t) for t in trials]
        while pending and not signals.requested():
            finished, pending = ray.wait(pending, num_returns=1, timeout=POLL)
            if finished:
                yield ray.get(finished[0])
        for ref in pending:  # stopped by a signal: the runs in flight are dropped
            ray.cancel(ref, force=True)


# ----- results ---------------------------------------------------------------------------------
def _number(value) -> float:
    return float("nan") if value in ("", None) else float(value)


def _fell(row: dict) -> bool:
    return str(row["fell"]) in ("True", "true", "1")


def best_row(rows: list[dict], metric: str) -> dict | None:
    """Lowest metric among the runs that did not fall (and reached a value)."""
    ok = [r for r in rows if not _fell(r) and math.isfinite(_number(r[metric]))]
    return min(ok, key=lambda r: _number(r[metric])) if ok else None


def best_yaml(spec: SweepSpec, row: dict, metric: str, namespace: str, runs: int) -> str:
    """The controller YAML with the best trial's gains, with a comment on how it was chosen."""
    import yaml

    controllers = {}
    for joint in spec.joints:
        pid = {k: round(_number(row[k]), 6) for k in ("p", "i", "d") if k in row}
        if "i_clamp" in row:
            pid["i_clamp_min"], pid["i_clamp_max"] = -_number(row["i_clamp"]), _number(row["i_clamp"])
        controllers[controller_name(joint)] = {"pid": pid}
    header = (f"# best of {runs} runs by {metric} ({_number(row[metric]):.6g}), from mexone sweep;\n"
              "# paste over the matching entries of controllers.yaml\n")
    return header + yaml.safe_dump({namespace.strip("/"): controllers}, sort_keys=False)


def heatmap(rows: list[dict], x: str, y: str, metric: str, out: Path, title: str) -> None:
    """Metric over two gains (the best over any other swept gain); falls hatched in grey."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    xs = sorted({_number(r[x]) for r in rows})
    ys = sorted({_number(r[y]) for r in rows})
    grid = np.full((len(ys), len(xs)), np.nan)
    fell = np.zeros_like(grid, dtype=bool)
    for r in rows:
        i, j = ys.index(_number(r[y])), xs.index(_number(r[x]))
        if _fell(r):
            fell[i, j] = True
            continue
        value = _number(r[metric])
        if math.isfinite(value) and not value >= grid[i, j]:
            grid[i, j] = value
    fig, ax = plt.subplots(figsize=(7.5, 5.5))
    image = ax.imshow(grid, origin="lower", aspect="auto", cmap="viridis_r",
                      extent=_extent(xs) + _extent(ys))
    fig.colorbar(image, ax=ax, label=_METRIC_LABELS.get(metric, metric))
    for i, j in zip(*np.nonzero(fell), strict=True):
        ax.add_patch(plt.Rectangle((_edges(xs)[j], _edges(ys)[i]), _edges(xs)[j + 1] - _edges(xs)[j],
                                   _edges(ys)[i + 1] - _edges(ys)[i], color="0.6", hatch="xx",
                                   fill=False))
    if np.isfinite(grid).any():
        i, j = np.unravel_index(np.nanargmin(grid), grid.shape)
        ax.plot(xs[j], ys[i], marker="*", color="red", markersize=16, label="best")
        ax.legend(loc="upper right")
    ax.set_xlabel(f"{x} gain")
    ax.set_ylabel(f"{y} gain")
    ax.set_title(title)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


_METRIC_LABELS = {"rise_time": "rise time (s)", "overshoot": "overshoot (fraction of the step)",
                  "settling_time": "settling time (s)", "iae": "IAE (rad s)",
                  "max_effort": "max effort (N m)"}


def _edges(values: list[float]) -> list[float]:
    if len(values) == 1:
        return [values[0] - 0.5, values[0] + 0.5]
    mids = [(a + b) / 2 for a, b in zip(values[:-1], values[1:], strict=True)]
    return [values[0] - (mids[0] - values[0]), *mids, values[-1] + (values[-1] - mids[-1])]


def _extent(values: list[float]) -> list[float]:
    edges = _edges(values)
    return [edges[0], edges[-1]]
