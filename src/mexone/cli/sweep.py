"""`mexone sweep`: PID gains over a grid or at random, in parallel, to CSV, heatmap and YAML."""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

from tqdm import tqdm

from mexone.errors import InputError, OutputExistsError
from mexone.sweep import (
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
)

HELP = """\
Sweep PID gains of one or more joints on the full robot and measure each run: rise time
(10-90%), overshoot, settling time (2%), IAE, the largest effort, and whether the robot fell.
Each trial is either a step response of the first --joint (by --step rad, after 0.1 s) or a
whole routine (--routine). Gains are given as a value, a list (a,b,c) or a range
start:stop:count; --random N draws N points uniformly in the ranges instead of the grid.

Runs go to every local core (--workers) with a progress bar, or to a Ray cluster with
--backend ray [--address ADDR] (a local Ray instance without --address). The simulation is
deterministic, so every backend gives the same numbers.

Writes OUT/sweep.csv (one row per run, appended as runs finish), OUT/heatmap.png (the metric
over the first two swept gains), OUT/best_gains.yaml (ready to paste into controllers.yaml)
and OUT/sweep.json (the sweep's definition). Ctrl-C keeps the finished runs; --resume runs the
rest."""


def add_parser(sub) -> None:
    p = sub.add_parser("sweep", help="sweep PID gains in parallel (local cores or Ray)",
                       description=HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--joint", nargs="+", required=True, metavar="JOINT",
                   help="joint(s) whose gains are swept; the first takes the step")
    for key in GAIN_KEYS:
        p.add_argument(f"--{key.replace('_', '-')}", dest=key, metavar="RANGE",
                       help=f"{key} values: v | a,b,c | start:stop:count")
    p.add_argument("--step", type=float, default=0.5, help="step size in rad (default 0.5)")
    p.add_argument("--routine", help="run this routine instead of a step response")
    p.add_argument("--duration", type=float, default=2.0, metavar="S",
                   help="sim seconds per run (default 2)")
    p.add_argument("--random", type=int, metavar="N", help="N random points instead of the grid")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--metric", default="iae", choices=[m for m in METRICS if m != "fell"],
                   help="what 'best' minimises and the heatmap shows (default iae)")
    p.add_argument("-o", "--output", type=Path, default=Path("sweep"), help="output folder")
    p.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                   help="parallel runs (default: every core)")
    p.add_argument("--backend", choices=("local", "ray"), default="local")
    p.add_argument("--address", help="Ray cluster address (default: start a local Ray)")
    p.add_argument("--resume", action="store_true", help="continue the sweep in OUT")
    p.add_argument("--force", action="store_true", help="start over, replacing OUT's results")
    p.add_argument("--model", help="robot (default: the built-in Mex-One)")
    p.add_argument("--controllers", help="controller YAML (default: the robot's own)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    ranges = {key: parse_range(getattr(args, key), key) for key in GAIN_KEYS
              if getattr(args, key) is not None}
    if not ranges:
        raise InputError("nothing to sweep", hint="give at least one of --p, --i, --d, --i-clamp")
    if args.duration <= 0.2 or args.workers < 1:
        raise InputError("--duration must be > 0.2 s and --workers >= 1")
    spec = SweepSpec(tuple(args.joint), args.step, args.routine, args.duration, args.model,
                     args.controllers)
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
                         progress=bar.update)
    except KeyboardInterrupt:
        bar.close()
        print(f"mexone: interrupted; finished runs are in {csv_path}; --resume continues")
        return 130
    bar.close()
    return _report(spec, rows, ranges, args, out, len(trials))


def _prepare(out: Path, definition: dict, resume: bool, force: bool) -> None:
    meta = out / "sweep.json"
    if out.exists() and (out / "sweep.csv").exists():
        if resume:
            if not meta.exists() or json.loads(meta.read_text()) != definition:
                raise InputError("the sweep in this folder was defined differently", file=out,
                                 hint="resume with the same options, or pick another -o")
            return
        if not force:
            raise OutputExistsError("holds a sweep already; nothing was run", file=out,
                                    hint="--resume to continue it, --force to start over")
        (out / "sweep.csv").unlink()
    out.mkdir(parents=True, exist_ok=True)
    meta.write_text(json.dumps(definition, indent=2))


def _report(spec, rows, ranges, args, out: Path, total: int) -> int:
    best = best_row(rows, args.metric)
    swept = [k for k, v in ranges.items() if len(set(v.tolist())) > 1 or args.random]
    if len(swept) >= 2:
        heatmap(rows, swept[0], swept[1], args.metric, out / "heatmap.png",
                f"{', '.join(spec.joints)}: {args.metric} over {len(rows)} runs")
    if best is None:
        print(f"{len(rows)}/{total} runs; none both stood and reached a {args.metric}")
        return 1
    from mexone.lab import Lab  # the namespace the YAML fragment belongs under

    namespace = Lab.create(spec.model, spec.controllers).namespace
    (out / "best_gains.yaml").write_text(best_yaml(spec, best, args.metric, namespace, len(rows)))
    gains = ", ".join(f"{k}={float(best[k]):g}" for k in ranges)
    print(f"{len(rows)}/{total} runs in {out}/sweep.csv; best {args.metric} "
          f"{float(best[args.metric]):.4g} at {gains} -> {out}/best_gains.yaml")
    return 0
