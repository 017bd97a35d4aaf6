"""`mexone record -o BAG [ROUTINE]`: a headless run (optionally with a routine) to a bag; and
`mexone record --recover BAG`: rebuild the bag a killed recording left."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from mexone import signals
from mexone.cli.common import DURATION, add_model_options, lab_from_args, recording
from mexone.errors import InputError, RoutineError
from mexone.files import check_output, move_into_place, temporary_path, usable
from mexone.physics.divergence import DivergenceError
from mexone.routines.runner import RoutineRunner, parse_param_args, shipped_routines

HELP = """\
Run the robot headless for --duration seconds of sim time (with a routine if one is given) and
record every topic -- joint states, controller commands, /clock, /tf -- to a bag stamped with
sim time: .mcap is rosbag2 with ROS 2 CDR messages (Foxglove, PlotJuggler, ros2 bag), .bag is
ROS 1. Ctrl-C or SIGTERM stops the run and leaves a valid bag (a second Ctrl-C does not cut the
closing short), exit 130/143. Then: mexone plot BAG.

While recording, the bag is BAG.active; it becomes BAG when it is closed. A recording that was
killed (kill -9, a crash) leaves BAG.active with everything up to
0.25 s of sim time before the kill: --recover BAG rebuilds a valid BAG from it and says how many
messages it recovered (a truncated BAG from elsewhere is repaired in place, the original kept as
NAME.orig.mcap or NAME.orig.bag)."""


def add_parser(sub) -> None:
    p = sub.add_parser("record", help="record a run to a rosbag (.mcap or .bag)",
                       description=HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("routine", nargs="?",
                   help="routine file or shipped routine (" + ", ".join(shipped_routines()) + ")")
    p.add_argument("params", nargs="*", metavar="name:=value", help="routine parameters")
    p.add_argument("-o", "--output", type=Path, metavar="BAG",
                   help="bag to write: .mcap or .bag (with --recover: where the rebuilt bag goes)")
    p.add_argument("--recover", type=Path, metavar="BAG",
                   help="rebuild a valid bag from a killed recording (BAG.active) or a truncated BAG")
    p.add_argument("--duration", type=DURATION, default=10.0, metavar="S",
                   help="seconds of sim time (default 10)")
    p.add_argument("--force", action="store_true", help="overwrite BAG if it exists")
    add_model_options(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    if args.recover is not None:
        if args.routine:
            raise InputError("--recover rebuilds a bag; it runs no routine",
                             hint=f"drop '{args.routine}'")
        return recover_bag(args.recover, args.output, args.force)
    if args.output is None:
        raise InputError("record needs -o BAG, the bag to write (.mcap or .bag)",
                         hint="e.g. mexone record arms -o arms.mcap")
    params = parse_param_args(args.params)
    lab = lab_from_args(args)
    runner = RoutineRunner(lab, args.routine, params) if args.routine else None
    status = 0
    with recording(lab, args.output, args.force):
        try:
            if runner:
                runner.run(args.duration, hold=True)
            else:
                lab.sim.run(args.duration, until=signals.requested)  # a signal ends it early
        except RoutineError as exc:  # the bag keeps what happened up to the failure
            print(exc.details, file=sys.stderr)
            status = 1
        except DivergenceError as exc:
            print(f"mexone: {exc.one_line()}")
            status = 1
    return status


def recover_bag(bag: Path, output: Path | None, force: bool) -> int:
    """Rebuild BAG from BAG.active (or a truncated BAG, kept as NAME.orig.EXT) or into OUTPUT."""
    from mexone.record.bag import BAG_SUFFIXES
    from mexone.record.recover import (
        bag_kind,
        bag_suffix,
        is_complete,
        killed_recording,
        misnamed,
        not_a_bag,
        recover,
    )

    if bag_suffix(bag) not in BAG_SUFFIXES:
        raise InputError(f"cannot recover '{bag.suffix or bag.name}' files", file=bag,
                         hint="give the .mcap or .bag that was being recorded")
    source = killed_recording(usable(bag))
    wrong = misnamed(source or bag) if (source or bag).is_file() else None
    if wrong:  # recovered, it would be written under the wrong kind's name
        kind = bag_kind(source or bag)
        raise InputError(f"is {wrong}", file=source or bag,
                         hint=f"rename it {Path(bag.name).stem}{kind} and recover that; "
                              "mexone plot and identify read it as it is")
    if source is None:
        if bag.is_file() and is_complete(bag):
            print(f"{bag} is complete; nothing to recover")
            return 0
        if bag.is_file():
            raise not_a_bag(bag)
        raise InputError("no such file, and no killed recording of it (BAG.active)", file=bag)
    name = Path(source.name.removesuffix(".active"))
    in_place = output is None and source.name == name.name
    target = output or source.with_name(name.name)
    if target.suffix.lower() != bag_suffix(source):
        raise InputError(f"a recovered {bag_suffix(source)} bag cannot be written as "
                         f"'{target.suffix or target.name}'", file=target,
                         hint=f"name it {bag_suffix(source)}")
    backup = source.with_name(f"{name.stem}.orig{name.suffix}")
    check_output(backup if in_place else target, force)
    temporary = temporary_path(target)
    try:
        found = recover(source, temporary)
        if in_place:
            move_into_place(source, backup, force)
            move_into_place(temporary, target, True)
        else:
            move_into_place(temporary, target, force)
            if source.name.endswith(".active"):
                source.unlink()  # mexone's own unfinished file: everything readable is in target
    except OSError as exc:
        raise InputError(f"cannot write: {exc.strerror or exc}", file=target) from None
    finally:
        temporary.unlink(missing_ok=True)
    kept = f"; the original is kept as {backup}" if in_place else ""
    print(f"recovered {found.describe()} from {source} into {target}{kept}")
    return 0
