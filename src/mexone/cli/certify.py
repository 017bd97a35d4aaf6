"""`mexone certify CONTROLLERS.yaml --at POINT`: a controller's margins, their check on the
simulated robot, its saturation and, for a state feedback, its region of attraction."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from mexone.cli.common import Number
from mexone.errors import InputError

HELP = """\
Analyse the Python controllers a controllers YAML runs (a deployed design, a student's own
PythonController, chained ones) at an operating point: the closed loop linearised (the robot by
mjd_transitionFD, the controllers by finite differences of their own update, on a copy), the
gain, phase, delay and disk margins with the loop broken at each actuator and at all at once,
the sensitivity peaks, each all-channel prediction checked on the simulated robot (MuJoCo's
actuator delay, the commands scaled), when a deviation saturates an actuator, and, for a
StateFeedback designed on the whole robot, the region of attraction over two axes; with
--mismatch, why a StateFeedback and its model differ (compare's experiment decomposed).

--at: 'hold' (where the YAML's controllers hold the robot after --settle s), 'design' (the
operating point in the design file of a StateFeedback or observer it runs), or joint=angle
pairs (joint=angle,joint=angle: that pose at rest on --support, then settled).

Prints a summary (or the JSON with --json) and writes an HTML report with -o. Exit 0 when every
simulated check agrees with its prediction, 1 when one does not."""

SETTLE = Number(0.0, 60.0, hint="s of sim time")
GRID = Number(2, 1000, integer=True)


def add_parser(sub) -> None:
    p = sub.add_parser("certify", help="margins, delays, saturation of a controller, checked "
                                       "on the robot", description=HELP,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("controllers", type=Path, metavar="CONTROLLERS.yaml")
    p.add_argument("--at", default="hold", metavar="POINT",
                   help="hold | design | joint=angle,... (default hold)")
    p.add_argument("--support", choices=("both", "left", "right", "fixed"),
                   help="for --at joint=angle: the feet on the ground (default both; fixed with "
                        "--fixed-base)")
    p.add_argument("--controller", action="append", metavar="NAME",
                   help="certify this one (repeatable; default: every running Python controller)")
    p.add_argument("--settle", type=SETTLE, default=1.0, metavar="S",
                   help="sim seconds the controllers hold the point before the analysis (default 1)")
    p.add_argument("--no-verify", action="store_true",
                   help="skip the simulated checks of the delay and gain margins")
    p.add_argument("--region", nargs=2, metavar="STATE=LOW:HIGH",
                   help="the region of attraction over two of the plant's states, e.g. "
                        "base:vx=-0.3:0.3 base:vy=-0.2:0.2 (a StateFeedback on the whole robot)")
    p.add_argument("--grid", default="16x16", metavar="NxM", help="region grid (default 16x16)")
    p.add_argument("--mismatch", metavar="STATE=VALUE,...",
                   help="compare a StateFeedback with its model from this deviation and say why "
                        "they differ (dry friction, effort and joint limits, contacts, amplitude), "
                        "e.g. l_elbow:q=0.01")
    p.add_argument("--backend", choices=("threads", "ray"), default="threads",
                   help="region rollouts: MuJoCo's threads (default) or a Ray cluster")
    p.add_argument("--model", type=Path, help="robot model (default: the built-in Mex-One)")
    p.add_argument("--fixed-base", action="store_true", help="weld the robot's root (a stand)")
    p.add_argument("-o", "--output", type=Path, metavar="REPORT.html", help="write the HTML report")
    p.add_argument("--force", action="store_true", help="overwrite the report")
    p.add_argument("--json", action="store_true", help="print the JSON instead of the summary")
    p.set_defaults(run=run)


def _region(texts: list[str] | None) -> dict[str, tuple[float, float]] | None:
    if texts is None:
        return None
    out = {}
    for text in texts:
        label, sep, span = text.rpartition("=")
        low, colon, high = span.partition(":")
        try:
            values = (float(low), float(high))
        except ValueError:
            values = (math.nan, math.nan)
        if not sep or not colon or not all(math.isfinite(v) for v in values) or values[0] >= values[1]:
            raise InputError(f"--region {text!r}: give STATE=LOW:HIGH with LOW < HIGH",
                             hint="e.g. base:vx=-0.3:0.3")
        out[label] = values
    return out


def _pairs(text: str, usage: str, hint: str | None = None) -> dict[str, float]:
    """NAME=NUMBER[,NAME=NUMBER] as a dict (the last '=' splits: names may hold ':'), or the
    one line `usage` says."""
    out = {}
    for item in text.split(","):
        name, sep, value = item.rpartition("=")
        try:
            number = float(value)
        except ValueError:
            number = math.nan
        if not sep or not name.strip() or not math.isfinite(number):
            raise InputError(usage, hint=hint)
        out[name.strip()] = number
    return out


def _grid(text: str) -> tuple[int, int]:
    parts = text.lower().split("x")
    if len(parts) != 2:
        raise InputError(f"--grid {text!r}: give NxM, e.g. 32x32")
    try:
        return GRID(parts[0]), GRID(parts[1])
    except argparse.ArgumentTypeError as exc:
        raise InputError(f"--grid {text!r}: {exc}") from None


def run(args: argparse.Namespace) -> int:
    from mexone.design.certify import certify
    from mexone.files import check_output
    from mexone.lab import Lab
    from mexone.physics.compile import CompileOptions

    region = _region(args.region)
    deviation = None if args.mismatch is None else _pairs(
        args.mismatch, f"--mismatch {args.mismatch!r}: give STATE=VALUE[,STATE=VALUE]",
        hint="e.g. l_elbow:q=0.01")
    shape = _grid(args.grid)
    pose = None if args.at in ("hold", "design") else _pairs(
        args.at, f"--at {args.at!r}: give hold, design or joint=angle,joint=angle")
    if args.output is not None:
        check_output(args.output, args.force)
    if not args.controllers.is_file():
        raise InputError("controllers file does not exist", file=args.controllers)
    from mexone.control.config import load_control_config

    # the user's own controllers on their own machine, imported here (as a notebook's): the
    # analysis differentiates their update on copies of the object
    config = load_control_config(args.controllers, in_process=True)
    lab = Lab.create(args.model, config, options=CompileOptions(fixed_base=args.fixed_base))
    if lab.manager is None:
        raise InputError("the lab has no controllers", file=args.controllers)
    _place(lab, args, pose)
    lab.sim.run(args.settle)
    result = certify(lab, args.controller, verify=not args.no_verify, region=region,
                     shape=shape, backend=args.backend, deviation=deviation)
    if args.output is not None:
        result.write_html(args.output, args.force)
    if args.json:
        print(result.json())
    else:
        print("\n".join(result.lines()))
        if args.output is not None:
            print(f"wrote {args.output}", file=sys.stderr)
    return 0 if result.passed else 1


def _place(lab, args, pose) -> None:
    """The robot at the point, at rest, its controllers holding it there."""
    from mexone.design.twin import place, python_runners

    sim = lab.sim
    if args.at == "hold":
        return
    if args.at == "design":
        points = [getattr(getattr(r.impl, "design", None), "point", None)
                  for r in python_runners(lab, args.controller)]
        points = [p for p in points if p is not None]
        if not points:
            raise InputError("--at design: no running controller has a design with a point",
                             hint="a StateFeedback or an observer from a design file")
        qpos = sim.data.qpos.copy()
        qpos[points[0].qpos_index] = points[0].qpos
    else:
        from mexone.design.linear import operating_point

        support = args.support or ("fixed" if args.fixed_base or not sim.compiled.free else "both")
        qpos = operating_point(lab, pose, support=support).qpos
    place(lab, qpos)
