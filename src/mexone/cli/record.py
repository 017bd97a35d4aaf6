"""`mexone record -o BAG [ROUTINE]`: a headless run (optionally with a routine) to a bag."""

from __future__ import annotations

import argparse
from pathlib import Path

from mexone.cli.common import add_model_options, lab_from_args, positive, recording
from mexone.physics.watchdog import DivergenceError
from mexone.routines.runner import RoutineRunner, parse_param_args, shipped_routines

HELP = """\
Run the robot headless for --duration seconds of sim time (with a routine if one is given) and
record every topic -- joint states, controller commands, /clock, /tf -- to a bag stamped with
sim time: .mcap is rosbag2 with ROS 2 CDR messages (Foxglove, PlotJuggler, ros2 bag), .bag is
ROS 1. Ctrl-C or SIGTERM stops the run and leaves a valid bag. Then: mexone plot BAG."""


def add_parser(sub) -> None:
    p = sub.add_parser("record", help="record a run to a rosbag (.mcap or .bag)",
                       description=HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("routine", nargs="?",
                   help="routine file or shipped routine (" + ", ".join(shipped_routines()) + ")")
    p.add_argument("params", nargs="*", metavar="name:=value", help="routine parameters")
    p.add_argument("-o", "--output", required=True, type=Path,
                   metavar="BAG", help="bag to write: .mcap or .bag")
    p.add_argument("--duration", type=positive, default=10.0, metavar="S",
                   help="seconds of sim time (default 10)")
    p.add_argument("--force", action="store_true", help="overwrite BAG if it exists")
    add_model_options(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    params = parse_param_args(args.params)
    lab = lab_from_args(args)
    runner = RoutineRunner(lab, args.routine, params) if args.routine else None
    status = 0
    with recording(lab, args.output, args.force):
        try:
            if runner:
                runner.run(args.duration)
            else:
                lab.sim.run(args.duration)
        except DivergenceError as exc:
            print(f"mexone: {exc.one_line()}")
            status = 1
        except KeyboardInterrupt:
            if runner:
                runner.stop()
    if runner and runner.error:
        print(runner.error)
        status = 1
    return status
