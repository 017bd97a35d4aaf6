"""`mexone render ROUTINE -o out.mp4|out.gif`: film a routine offscreen at real-time speed."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from tqdm import tqdm

from mexone.cli.common import add_model_options, lab_from_args, positive
from mexone.errors import InputError, OutputExistsError
from mexone.physics.watchdog import DivergenceError
from mexone.record.video import VideoWriter, ensure_gl_backend, parse_camera
from mexone.routines.runner import RoutineRunner, parse_param_args, shipped_routines

HELP = """\
Run a routine headless and film it with MuJoCo's offscreen renderer (EGL, falling back to
OSMesa), one frame per 1/fps s of sim time, so the video plays at real-time speed. --camera:
track (default, follows the robot), fixed, or 'azimuth,elevation,distance' (degrees, metres)."""


def add_parser(sub) -> None:
    p = sub.add_parser("render", help="render a routine to .mp4 or .gif", description=HELP,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("routine", help="routine file or one of: " + ", ".join(shipped_routines()))
    p.add_argument("params", nargs="*", metavar="name:=value", help="routine parameters")
    p.add_argument("-o", "--output", type=Path, required=True, help="out.mp4 or out.gif")
    p.add_argument("--duration", type=positive, default=6.0, metavar="S",
                   help="seconds of sim time (default 6)")
    p.add_argument("--camera", default="track", help="track, fixed or azimuth,elevation,distance")
    p.add_argument("--fps", type=positive, default=30.0, help="frames per second (default 30)")
    p.add_argument("--size", default="640x480", help="WIDTHxHEIGHT (default 640x480)")
    p.add_argument("--force", action="store_true", help="overwrite the output if it exists")
    add_model_options(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    out: Path = args.output
    if out.exists() and not args.force:
        raise OutputExistsError("already exists; nothing was written", file=out,
                                hint="pass --force to overwrite it")
    try:
        width, height = (int(v) for v in args.size.lower().split("x"))
    except ValueError:
        raise InputError(f"--size '{args.size}' is not WIDTHxHEIGHT", hint="e.g. 640x480") from None
    if not (16 <= width <= 3840 and 16 <= height <= 2160):
        raise InputError(f"--size {args.size}: must be 16x16 to 3840x2160")
    camera = parse_camera(args.camera)
    ensure_gl_backend(sys.argv[1:])
    lab = lab_from_args(args)
    runner = RoutineRunner(lab, args.routine, parse_param_args(args.params))
    video = VideoWriter(out, lab.sim.model, args.fps, (width, height))
    root = lab.sim.compiled.root_body
    bar = tqdm(total=round(args.duration * args.fps), unit="frame", desc=f"rendering {out.name}")

    def frame(sim) -> None:
        video.capture(sim.data, camera, root)
        bar.update(1)

    status = 0
    try:
        frame(lab.sim)
        runner.run(args.duration - 1.0 / args.fps, on_tick=frame, tick=1.0 / args.fps)
    except DivergenceError as exc:
        print(f"mexone: {exc.one_line()}")
        status = 1
    except KeyboardInterrupt:
        runner.stop()
    finally:
        bar.close()
        video.close()
    print(f"wrote {out}: {video.frames} frames at {args.fps:g} fps")
    if runner.error:
        print(runner.error)
        status = 1
    return status
