"""`mexone render ROUTINE -o out.mp4|out.gif`: film a routine offscreen at real-time speed."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from tqdm import tqdm

from mexone.cli.common import DURATION, Number, add_model_options, lab_from_args
from mexone.errors import RoutineError
from mexone.files import check_output, replacing
from mexone.physics.divergence import DivergenceError
from mexone.record.video import Camera, VideoWriter, check_video_path, ensure_gl_backend
from mexone.routines.runner import RoutineRunner, parse_param_args, shipped_routines

HELP = """\
Run a routine headless and film it with MuJoCo's offscreen renderer (EGL, falling back to
OSMesa), one frame per 1/fps s of sim time, so the video plays at real-time speed. --camera:
track (default, follows the robot), fixed, or 'azimuth,elevation,distance' (degrees, metres).
The video is written as it renders and gets its name when complete; Ctrl-C keeps what was
rendered so far. A routine that fails (or a simulation that diverges) leaves no video: one line
naming the routine's FILE:LINE, exit 1 (`mexone run` shows its whole traceback).

exit status: 0 written, 1 the routine failed or the simulation diverged (nothing written),
2 bad input, 130/143 stopped by Ctrl-C/SIGTERM (the frames so far are kept)"""

FPS = Number(1, 240, hint="a frame per 1/fps s of sim time")
AZIMUTH, ELEVATION = Number(-360, 360), Number(-90, 90)
DISTANCE = Number(0, 1000, low_open=True)
WIDTH, HEIGHT = Number(16, 3840, integer=True), Number(16, 2160, integer=True)


def camera(text: str) -> Camera:
    """argparse type: track, fixed or 'azimuth,elevation,distance' with each number checked."""
    if text in ("track", "fixed"):
        return Camera(track=text == "track")
    parts = text.split(",")
    if len(parts) != 3:
        raise argparse.ArgumentTypeError(f"'{text}' is not track, fixed or "
                                         "'azimuth,elevation,distance' (e.g. 90,-20,3)")
    try:
        values = [kind(part.strip()) for kind, part in zip((AZIMUTH, ELEVATION, DISTANCE), parts,
                                                            strict=True)]
    except argparse.ArgumentTypeError as exc:
        names = "azimuth (degrees), elevation (degrees), distance (m)"
        raise argparse.ArgumentTypeError(f"'{text}': {exc} ({names})") from None
    return Camera(True, *values)


def frame_size(text: str) -> tuple[int, int]:
    """argparse type: WIDTHxHEIGHT, 16x16 to 3840x2160."""
    width, sep, height = text.lower().partition("x")
    if not sep:
        raise argparse.ArgumentTypeError(f"'{text}' is not WIDTHxHEIGHT (e.g. 640x480)")
    try:
        return WIDTH(width), HEIGHT(height)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"{text}: must be WIDTHxHEIGHT from 16x16 to "
                                         "3840x2160") from None


def add_parser(sub) -> None:
    p = sub.add_parser("render", help="render a routine to .mp4 or .gif", description=HELP,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("routine", help="routine file or one of: " + ", ".join(shipped_routines()))
    p.add_argument("params", nargs="*", metavar="name:=value", help="routine parameters")
    p.add_argument("-o", "--output", type=Path, required=True, help="out.mp4 or out.gif")
    p.add_argument("--duration", type=DURATION, default=None, metavar="S",
                   help="seconds of sim time (default: the routine's ~duration if it sets one, "
                        "else 6)")
    p.add_argument("--camera", type=camera, default=Camera(),
                   help="track, fixed or azimuth,elevation,distance")
    p.add_argument("--fps", type=FPS, default=30.0, help="frames per second (default 30)")
    p.add_argument("--size", type=frame_size, default=(640, 480),
                   help="WIDTHxHEIGHT (default 640x480)")
    p.add_argument("--force", action="store_true", help="overwrite the output if it exists")
    add_model_options(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    out: Path = args.output
    check_video_path(out)
    check_output(out, args.force)
    params = parse_param_args(args.params)
    ensure_gl_backend(sys.argv[1:])
    lab = lab_from_args(args)
    runner = RoutineRunner(lab, args.routine, params)
    root = lab.sim.compiled.root_body
    try:  # a failed routine or simulation leaves no video: the temporary file is deleted
        with replacing(out, args.force) as temporary:
            video = VideoWriter(temporary, lab.sim.model, args.fps, args.size)
            total = round(args.duration * args.fps) if args.duration is not None else None
            bar = tqdm(total=total, unit="frame", desc=f"rendering {out.name}")

            def frame(sim) -> None:
                video.capture(sim.data, args.camera, root)
                bar.update(1)

            try:
                frame(lab.sim)
                length = None if args.duration is None else args.duration - 1.0 / args.fps
                runner.run(length, on_tick=frame, tick=1.0 / args.fps, default=6.0 - 1.0 / args.fps,
                           hold=True)
            finally:
                bar.close()
                video.close()
    except (RoutineError, DivergenceError) as exc:
        print(f"mexone: {exc.one_line()}; no video written", file=sys.stderr)
        return 1
    print(f"wrote {out}: {video.frames} frames at {args.fps:g} fps")
    return 0
