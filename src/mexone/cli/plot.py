"""`mexone plot BAG -o out.png|out.csv`: command vs actual, error and effort per joint, or
`--topics` field paths as rqt_plot takes them."""

from __future__ import annotations

import argparse
from pathlib import Path

from mexone.errors import InputError
from mexone.files import check_output, replacing

HELP = """\
Plot a recorded bag (.mcap or .bag): for each joint, command vs actual position (rad), then
tracking error (rad) with effort (N m) on a second axis, against sim time. By default the
joints a position controller commanded; --joints picks others. An -o ending .csv writes the same
data as CSV instead (time, joint, command, position, error, velocity, effort). A killed
recording (BAG.active, or a truncated BAG) is plotted from what can be recovered of it, with a
note; `mexone record --recover BAG` repairs the file itself.

--topics plots any numeric fields instead, named as rqt_plot names them: a topic (all its
numeric fields but covariance matrices), a field or a sub-message, e.g.
  mexone plot run.mcap -o imu.png --topics /mex_rb/imu/linear_acceleration /mex_rb/l_ankle_ft/wrench/force/z
against the message's header stamp (sim time), one pane per group of sibling fields."""


def add_parser(sub) -> None:
    p = sub.add_parser("plot", help="plot or export a recorded run", description=HELP,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("bag", type=Path, help="recorded .mcap or .bag")
    p.add_argument("-o", "--output", type=Path, required=True, help="out.png (or .pdf, .svg) or out.csv")
    pick = p.add_mutually_exclusive_group()
    pick.add_argument("--joints", nargs="+", metavar="JOINT", help="joints to plot")
    pick.add_argument("--topics", nargs="+", metavar="PATH",
                      help="topic or field paths to plot instead (/mex_rb/imu/linear_acceleration/z)")
    p.add_argument("--force", action="store_true", help="overwrite the output if it exists")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    # here, not at the top: the CLI imports every verb, and rosbags would cost each lab ~6 MB
    from mexone.record.plot import pick_joints, plot_fields, plot_joints, write_csv, write_fields_csv
    from mexone.record.reader import read_field_series, read_joint_series

    out: Path = args.output
    if out.suffix.lower() not in (".png", ".pdf", ".svg", ".csv"):
        raise InputError(f"cannot write '{out.suffix or out.name}'", file=out,
                         hint="name it .png, .pdf, .svg or .csv")
    check_output(out, args.force)
    csv_out = out.suffix.lower() == ".csv"
    if args.topics:
        fields = read_field_series(args.bag, args.topics)
        with replacing(out, args.force) as temporary:
            if csv_out:
                rows = write_fields_csv(fields, temporary)
            else:
                plot_fields(fields, temporary, f"{args.bag.name}")
        print(f"wrote {out}: " + (f"{rows} rows for " if csv_out else "") + f"{len(fields)} fields")
        return 0
    joints = pick_joints(read_joint_series(args.bag), args.joints)
    with replacing(out, args.force) as temporary:
        if csv_out:
            rows = write_csv(joints, temporary)
        else:
            plot_joints(joints, temporary, f"{args.bag.name}")
    what = f"{rows} rows for {len(joints)} joints" if csv_out else f"{len(joints)} joints"
    print(f"wrote {out}: {what}")
    return 0
