"""`mexone plot BAG -o out.png|out.csv`: command vs actual, error and effort per joint."""

from __future__ import annotations

import argparse
from pathlib import Path

from mexone.errors import InputError
from mexone.files import check_output, replacing
from mexone.record.plot import pick_joints, plot_joints, write_csv
from mexone.record.reader import read_joint_series

HELP = """\
Plot a recorded bag (.mcap or .bag): for each joint, command vs actual position (rad), then
tracking error (rad) with effort (N m) on a second axis, against sim time. By default the
joints a position controller commanded; --joints picks others. An -o ending .csv writes the same
data as CSV instead (time, joint, command, position, error, velocity, effort). A killed
recording (BAG.active, or a truncated BAG) is plotted from what can be recovered of it, with a
note; `mexone record --recover BAG` repairs the file itself."""


def add_parser(sub) -> None:
    p = sub.add_parser("plot", help="plot or export a recorded run", description=HELP,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("bag", type=Path, help="recorded .mcap or .bag")
    p.add_argument("-o", "--output", type=Path, required=True, help="out.png (or .pdf, .svg) or out.csv")
    p.add_argument("--joints", nargs="+", metavar="JOINT", help="joints to plot")
    p.add_argument("--force", action="store_true", help="overwrite the output if it exists")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    out: Path = args.output
    if out.suffix.lower() not in (".png", ".pdf", ".svg", ".csv"):
        raise InputError(f"cannot write '{out.suffix or out.name}'", file=out,
                         hint="name it .png, .pdf, .svg or .csv")
    check_output(out, args.force)
    joints = pick_joints(read_joint_series(args.bag), args.joints)
    with replacing(out, args.force) as temporary:
        if out.suffix.lower() == ".csv":
            rows = write_csv(joints, temporary)
        else:
            plot_joints(joints, temporary, f"{args.bag.name}")
    what = f"{rows} rows for {len(joints)} joints" if out.suffix.lower() == ".csv" else \
        f"{len(joints)} joints"
    print(f"wrote {out}: {what}")
    return 0
