"""`mexone edit [MODEL]`: the model editor's page (Gazebo 7's Model Editor, in a browser)."""

from __future__ import annotations

import argparse
import sys
import threading
from pathlib import Path

from mexone.cli import add_input_limit_option
from mexone.cli.common import PORT, check_can_serve, host
from mexone.errors import InputError

HELP = """\
Serve the model editor at http://127.0.0.1:8080: build a robot from CAD parts (STL, OBJ, DAE
uploaded from the page, units chosen or guessed from their size), give links masses, inertias
computed from their meshes, fitted collision shapes, friction and colour; join them with
revolute, continuous, prismatic or fixed joints whose frames snap to hole axes, face centres or
edge midpoints; add motors with controllers (auto gains to start from); watch `mexone check`'s
findings live; save URDF, SDF, the ros_control YAML or a ROS package; Simulate turns the page
into `mexone sim`'s for the model (Back to editing returns).

MODEL (URDF, xacro, SDF, Gazebo model folder or MJCF) is the starting point; without it the
editor starts empty. The working model and its undo history live in --workdir (default
.mexone_edit/<name> in the current folder): a reload of the page, or a restart with the same
--workdir, finds them again. Saved files go to --out (default: the current folder); an existing
file is replaced only when the page's Overwrite box is ticked.

The page listens on this machine only unless --host says otherwise (then anyone who can reach
it can edit and save files in --out)."""


def add_parser(sub) -> None:
    p = sub.add_parser("edit", help="build or edit a robot in the browser (model editor)",
                       description=HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("model", nargs="?", type=Path, help="robot to start from (default: empty)")
    p.add_argument("--name", default="robot", help="name of a new robot (default: robot)")
    p.add_argument("--workdir", type=Path, help="folder for the working model and its history")
    p.add_argument("--out", type=Path, default=Path.cwd(), help="folder saved files go to")
    p.add_argument("--port", type=PORT, default=8080, help="page port (default 8080; 0: a free one)")
    p.add_argument("--host", type=host, default="127.0.0.1",
                   help="address to listen on (default 127.0.0.1: this machine only)")
    p.add_argument("--duration", type=float, help=argparse.SUPPRESS)  # tests: stop after seconds
    add_input_limit_option(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from mexone.editor.app import EditorApp
    from mexone.editor.parts import safe_name
    from mexone.editor.session import EditSession

    if not args.out.is_dir():
        raise InputError("is not a folder", file=args.out, hint=f"create it first: mkdir -p {args.out}")
    if args.model is not None and not args.model.exists():
        raise InputError("no such file (check the path)", file=args.model)
    name = safe_name(args.model.stem.split(".")[0] if args.model else args.name)
    workdir = args.workdir or Path.cwd() / ".mexone_edit" / name
    check_can_serve(args.host)
    session = EditSession.open(workdir, args.model, name=name)
    try:
        app = EditorApp(session, args.out, host=args.host, port=args.port)
    except OSError as exc:
        raise InputError(f"cannot serve the editor on {args.host}:{args.port}: {exc.strerror}",
                         hint="pick another --port") from None
    url = app.access.page_url(args.host, app.server.get_port())  # a hub's proxied URL in a hub
    print(f"mexone: editing {session.model.name} at {url} "
          f"(working folder {workdir}; Ctrl-C stops)", file=sys.stderr)
    if args.duration is not None:
        threading.Timer(args.duration, app.stopping.set).start()
    try:
        app.serve_forever()  # until a signal asks it to stop (signals.requested)
    finally:
        app.stop()
    return 0
