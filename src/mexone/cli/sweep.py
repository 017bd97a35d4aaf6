"""`mexone sweep`: PID gains over a grid or at random, in parallel, to CSV, heatmap and YAML."""

from __future__ import annotations

import argparse
import json
import math
import os
import socket
import sys
from dataclasses import replace
from pathlib import Path

from tqdm import tqdm

from mexone import signals
from mexone.cli.common import Number
from mexone.errors import InputError, OutputExistsError
from mexone.files import check_output, replacing, usable, write_text
from mexone.ranges import ANGLE
from mexone.sweep import (
    DEFAULT_STEP,
    GAIN_KEYS,
    METRICS,
    SweepSpec,
    best_row,
    best_yaml,
    grid_trials,
    heatmap,
    parse_range,
    random_trials,
    run_sweep,
    step_target,
    toward_room,
)

OUTPUTS = ("sweep.csv", "sweep.json", "heatmap.png", "best_gains.yaml")
MAX_TRIALS = 100_000  # a grid of three 100-value ranges is a typo, not a sweep
STEP = Number.of(ANGLE, "radians")
TRIAL_DURATION = Number(0.2, 3600.0, low_open=True, hint="s of sim time; the step comes at 0.1 s")
TRIALS = Number(1, MAX_TRIALS, integer=True)
SEED = Number(0, 2**32 - 1, integer=True)
WORKERS = Number(1, 256, integer=True)

HELP = """\
Sweep PID gains of one or more joints on the full robot and measure each run: rise time
(10-90%), overshoot, settling time (2%), IAE, the largest effort, and whether the robot fell.
Each trial is either a step response of the first --joint (by --step rad, after 0.1 s; by
default 0.5 rad toward the farther of its limits from home) or a whole routine (--routine).
Gains are given as a value, a list (a,b,c) or a range start:stop:count; --random N draws N
points uniformly in the ranges instead of the grid.

Runs go to every local core (--workers) with a progress bar, or to a Ray cluster with
--backend ray [--address ADDR] (a local Ray instance without --address). The simulation is
deterministic, so every backend gives the same numbers.

Writes OUT/sweep.csv (one row per run, appended as runs finish), OUT/heatmap.png (the metric
over the first two swept gains), OUT/best_gains.yaml (ready to paste into controllers.yaml)
and OUT/sweep.json (the sweep's definition). Ctrl-C keeps the finished runs; --resume runs the
rest. A folder that holds any of these files is not touched without --resume or --force."""


def add_parser(sub) -> None:
    p = sub.add_parser("sweep", help="sweep PID gains in parallel (local cores or Ray)",
                       description=HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--joint", nargs="+", required=True, metavar="JOINT",
                   help="joint(s) whose gains are swept; the first takes the step")
    for key in GAIN_KEYS:
        p.add_argument(f"--{key.replace('_', '-')}", dest=key, metavar="RANGE",
                       help=f"{key} values: v | a,b,c | start:stop:count")
    p.add_argument("--step", type=STEP, help="step size in rad (default 0.5 toward the joint's "
                                             "farther limit from home)")
    p.add_argument("--routine", help="run this routine instead of a step response")
    p.add_argument("--duration", type=TRIAL_DURATION, default=2.0, metavar="S",
                   help="sim seconds per run (default 2)")
    p.add_argument("--random", type=TRIALS, metavar="N", help="N random points instead of the grid")
    p.add_argument("--seed", type=SEED, default=0, help="random seed (default 0)")
    p.add_argument("--metric", default="iae", choices=[m for m in METRICS if m != "fell"],
                   help="what 'best' minimises and the heatmap shows (default iae)")
    p.add_argument("-o", "--output", type=Path, default=Path("sweep"), help="output folder")
    p.add_argument("--workers", type=WORKERS, default=min(os.cpu_count() or 1, 256),
                   help="parallel runs (default: every core)")
    p.add_argument("--backend", choices=("local", "ray"), default="local")
    p.add_argument("--address", help="Ray cluster address (default: start a local Ray)")
    p.add_argument("--resume", action="store_true", help="continue the sweep in OUT")
    p.add_argument("--force", action="store_true", help="start over, replacing OUT's results")
    p.add_argument("--model", help="robot: URDF, xacro, SDF or MJCF (default: the built-in Mex-One)")
    p.add_argument("--controllers", help="controller YAML (default: the robot's own)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    ranges = {key: parse_range(getattr(args, key), key) for key in GAIN_KEYS
              if getattr(args, key) is not None}
    if not ranges:
        raise InputError("nothing to sweep", hint="give at least one of --p, --i, --d, --i-clamp")
    if args.step == 0 and not args.routine:
        raise InputError("--step 0 moves nothing, so there is no response to measure",
                         hint="e.g. --step 0.5 (rad)")
    size = math.prod(len(v) for v in ranges.values())
    if not args.random and size > MAX_TRIALS:
        raise InputError(f"the grid has {size} points, more than {MAX_TRIALS}",
                         hint="fewer values per gain, or --random N")
    if args.address is not None:
        check_ray_address(args.address, args.backend)
    spec = SweepSpec(tuple(args.joint), DEFAULT_STEP if args.step is None else args.step,
                     args.routine, args.duration, args.model, args.controllers)
    spec, namespace = _check_spec(spec, step_given=args.step is not None)
    trials = random_trials(ranges, args.random, args.seed) if args.random else grid_trials(ranges)
    out: Path = args.output
    definition = {"spec": json.loads(spec.key()), "ranges": {k: v.tolist() for k, v in ranges.items()},
                  "random": args.random, "seed": args.seed}
    _prepare(out, definition, args.resume, args.force)
    csv_path = out / "sweep.csv"
    finished = len(csv_path.read_text().splitlines()) - 1 if csv_path.exists() else 0
    bar = tqdm(total=len(trials), unit="run", desc="sweep", initial=finished)
    try:
        rows = run_sweep(spec, trials, csv_path, args.workers, args.backend, args.address,
                         progress=bar.update)  # returns early on a signal (signals.requested)
    except KeyboardInterrupt:  # signals.Stop
        rows = None
    bar.close()
    if rows is None or signals.requested():
        print(f"mexone: interrupted; finished runs are in {csv_path}; --resume continues",
              file=sys.stderr)
        return signals.exit_code()
    return _report(spec, rows, ranges, args, out, len(trials), namespace)


def check_ray_address(address: str, backend: str) -> None:
    """A cluster that cannot be reached is one line now, not Ray retrying for minutes."""
    if backend != "ray":
        raise InputError("--address is the Ray cluster's", hint="add --backend ray")
    if address == "auto":
        return
    host, sep, port = address.removeprefix("ray://").rpartition(":")
    if not sep or not port.isdigit() or not 0 < int(port) < 65536:
        raise InputError(f"--address '{address}' is not HOST:PORT", hint="e.g. 10.0.0.5:6379")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=5).close()
    except OSError as exc:
        raise InputError(f"cannot reach the Ray cluster at {address}: "
                         f"{exc.strerror or exc}", hint="is `ray start --head` running there?"
                         ) from None


def _check_spec(spec: SweepSpec, step_given: bool) -> tuple[SweepSpec, str]:
    """Load the robot, its controllers and the routine once here, so a typo is one line before
    any worker starts (not a progress bar and an error from each worker). Returns the spec
    (the default step turned toward the joint's farther limit) and the controllers' namespace,
    which best_gains.yaml is written under."""
    from mexone.lab import Lab
    from mexone.routines.runner import resolve_routine

    if spec.routine:
        resolve_routine(spec.routine)
    lab = Lab.create(spec.model, spec.controllers)
    if lab.manager is None:
        raise InputError("the robot has no controllers to tune", hint="give --controllers")
    missing = [j for j in spec.joints if j not in lab.manager.by_joint()]
    if missing:
        raise InputError(f"no running controller moves joint {', '.join(missing)}",
                         hint="controlled joints: " + ", ".join(sorted(lab.manager.by_joint())))
    if not spec.routine:
        if not step_given:
            spec = replace(spec, step=toward_room(lab, spec))
        step_target(lab, spec)
    return spec, lab.namespace


def _prepare(out: Path, definition: dict, resume: bool, force: bool) -> None:
    """A folder holding a sweep is continued (--resume, same definition), started over (--force:
    all four files go, so no stale heatmap or best gains remain) or left alone."""
    if usable(out).exists() and not out.is_dir():
        raise InputError("is a file; -o names the folder the sweep writes into", file=out)
    existing = [name for name in OUTPUTS if (out / name).exists()]
    meta = out / "sweep.json"
    if existing and resume:
        try:
            same = json.loads(meta.read_text()) == definition
        except (OSError, ValueError):
            same = False
        if not same or "sweep.csv" not in existing:
            raise InputError("the sweep in this folder was defined differently", file=out,
                             hint="resume with the same options, or pick another -o")
        return
    if existing and not force:
        raise OutputExistsError(f"holds a sweep already ({', '.join(existing)}); nothing was run",
                                file=out, hint="--resume to continue it, --force to start over")
    try:
        for name in existing:
            check_output(out / name, True).unlink()
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot write the sweep here: {exc.strerror or exc}", file=out) from None
    write_text(meta, json.dumps(definition, indent=2), True)


def _report(spec, rows, ranges, args, out: Path, total: int, namespace: str) -> int:
    """heatmap.png and best_gains.yaml: this sweep's own files (_prepare made sure of that)."""
    best = best_row(rows, args.metric)
    swept = [k for k, v in ranges.items() if len(set(v.tolist())) > 1 or args.random]
    if len(swept) >= 2:
        with replacing(out / "heatmap.png", True) as temporary:
            heatmap(rows, swept[0], swept[1], args.metric, temporary,
                    f"{', '.join(spec.joints)}: {args.metric} over {len(rows)} runs")
    if best is None:
        print(f"{len(rows)}/{total} runs; none both stood and reached a {args.metric}")
        return 1
    write_text(out / "best_gains.yaml", best_yaml(spec, best, args.metric, namespace, len(rows)), True)
    gains = ", ".join(f"{k}={float(best[k]):g}" for k in ranges)
    print(f"{len(rows)}/{total} runs in {out}/sweep.csv; best {args.metric} "
          f"{float(best[args.metric]):.4g} at {gains} -> {out}/best_gains.yaml")
    return 0
