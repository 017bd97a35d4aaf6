"""`mexone identify`: fit joint damping, friction, armature, link masses or gains to bags."""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from mexone import signals
from mexone.cli.common import Number
from mexone.errors import InputError

HELP = """\
Fit the model to recordings: simulate the recorded controller commands through the model and
its controllers, and adjust the chosen parameters until the simulated joint positions match the
recorded ones. MuJoCo's own system identification (mujoco.sysid: bounded Levenberg-Marquardt,
Jacobians from batched rollouts) does the fitting.

Bags are ROS 1 .bag or ROS 2 .mcap with sensor_msgs/JointState and the controllers' command
topics (<ns>/<controller>/command: Float64, Float64MultiArray or JointTrajectory), from mexone
or a real robot's drivers. Record good data with `mexone record excitation` (see its routine's
help). A robot hung on a stand (no base motion in /tf) is fitted with a welded base; a standing
one with a free base on the ground.

Parameters (--params, comma-separated): damping, frictionloss, armature (per joint, default all
three), mass and com (per link, with --links), gains (the position controllers' p and d).

Writes into -o DIR: the patched URDF (only identified values change, each with a comment saying
from what), the patched controllers YAML (with gains), identify.json and report.md with a PNG per
bag (recorded vs simulated before and after, and the residual, per joint). Ctrl-C stops the fit
and writes the best values found so far (exit 130)."""

ITERATIONS = Number(1, 1000, integer=True)
THREADS = Number(1, 256, integer=True)


def _names(text: str) -> tuple[str, ...]:
    return tuple(n.strip() for n in text.split(",") if n.strip())


def add_parser(sub) -> None:
    from mexone.cli import add_input_limit_option

    p = sub.add_parser("identify", help="fit damping, friction, armature, masses to bags",
                       description=HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("bags", nargs="+", type=Path, metavar="BAG", help=".bag or .mcap files to fit")
    p.add_argument("--model", type=Path, help="robot (URDF, xacro, SDF, MJCF; default: the built-in Mex-One)")
    p.add_argument("--controllers", type=Path,
                   help="controller YAML the bags were recorded with (default: the robot's own)")
    p.add_argument("--params", dest="fit_params", type=_names,
                   default=("damping", "frictionloss", "armature"), metavar="LIST",
                   help="what to fit (default damping,frictionloss,armature)")
    p.add_argument("--joints", type=_names, default=(), metavar="LIST",
                   help="joints to fit (default: every recorded joint with a motor)")
    p.add_argument("--links", type=_names, default=(), metavar="LIST",
                   help="links whose mass/com to fit, e.g. torso")
    p.add_argument("--validate", type=Path, action="append", default=[], metavar="BAG",
                   help="held-out bag: not fitted, simulated before and after (repeatable)")
    p.add_argument("--base", choices=("auto", "fixed", "free"), default="auto",
                   help="robot on a stand (fixed) or standing (free); default: from /tf")
    p.add_argument("--no-delay", dest="delay", action="store_false",
                   help="do not fit each bag's command delay (fit it unless the commands' "
                        "receive times are exact, as in mexone's own bags)")
    p.add_argument("--max-iterations", type=ITERATIONS, default=30, metavar="N",
                   help="optimiser iterations (default 30)")
    p.add_argument("--threads", type=THREADS, default=os.cpu_count() or 1,
                   help="rollout threads (default: every core)")
    p.add_argument("-o", "--output", type=Path, default=Path("identified"), metavar="DIR",
                   help="output folder (default identified/)")
    p.add_argument("--force", action="store_true", help="overwrite files in DIR")
    p.add_argument("-v", "--verbose", action="store_true",
                   help="say each stage on stderr (a progress bar does when stderr is a terminal)")
    p.add_argument("--json", action="store_true",
                   help='print one JSON object {"params": ..., "rms_before": ..., "rms_after": ...}')
    add_input_limit_option(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from mexone.identify.outputs import plan_outputs, write_outputs
    from mexone.identify.parameters import check_kinds
    from mexone.identify.session import Options, identify, load_inputs

    for bag in [*args.bags, *args.validate]:
        if not bag.is_file():
            raise InputError("no such bag", file=bag, hint="give a .bag or .mcap file")
    check_kinds(args.fit_params)
    robot, config = load_inputs(args.model, args.controllers)
    plan = plan_outputs(args.output, robot.source, config.source, "gains" in args.fit_params,
                        [*args.bags, *args.validate], args.force)
    options = Options(model=args.model, controllers=args.controllers, params=args.fit_params,
                      joints=args.joints, links=args.links, base=args.base,
                      max_iterations=args.max_iterations, threads=args.threads, delay=args.delay)
    bar = tqdm(total=args.max_iterations, unit="it", desc="identify", disable=None,
               file=sys.stderr, leave=False)

    def on_progress(progress) -> None:
        if progress.iteration > bar.n:
            bar.update(progress.iteration - bar.n)
        if progress.best_rms < float("inf"):
            bar.set_postfix_str(f"rms {progress.best_rms * 1000:.3g} mrad, "
                                f"{progress.rollouts} rollouts", refresh=False)

    def on_stage(text: str) -> None:
        if bar.disable:
            if args.verbose:
                print(f"mexone: {text}", file=sys.stderr, flush=True)
        else:
            bar.set_description_str(text, refresh=True)

    try:
        result = identify(args.bags, options, args.validate, on_progress, on_stage)
    finally:
        bar.close()
    write_outputs(result, plan)
    for note in result.notes:  # what was left out of the bags, assumed or not written back
        print(f"mexone: note: {note}", file=sys.stderr)
    if args.json:
        print(json.dumps(result.as_json()))
    else:
        _summary(result, plan)
    if result.fit.interrupted:
        print(f"mexone: interrupted after {result.fit.iterations} iterations; the best fit so far "
              f"(RMS {result.rms_before * 1000:.3g} -> {result.rms_after * 1000:.3g} mrad) is in "
              f"{plan.folder}", file=sys.stderr)
        return signals.exit_code()
    return 0


def _summary(result, plan) -> None:
    from mexone.identify.patch import value_text

    fit = result.fit
    width = max(len(u.name) for u in fit.unknowns) if fit.unknowns else 10
    for i, u in enumerate(fit.unknowns):
        half = "" if fit.halfwidth is None else f" +- {value_text(fit.halfwidth[i])}"
        print(f"{u.name:<{width}}  {value_text(fit.nominal[i]):>10} -> "
              f"{value_text(fit.values[i])}{half} {u.unit}")
    where = "held-out" if result.held_out else "fitted"
    print(f"RMS joint error ({where} bags): {result.rms_before * 1000:.4g} -> "
          f"{result.rms_after * 1000:.4g} mrad in {fit.iterations} iterations, {fit.seconds:.1f} s")
    print(f"wrote {plan.urdf}, {plan.report} and {plan.json}")
