"""`mexone <verb>`: one module per verb, each with `add_parser(subparsers)` and `run(args)`.

Exit codes: 0 ok, 1 findings or failed checks, 2 bad input or a failing machine such as a full
disk (one line on stderr, no traceback), 128 + N stopped by signal N before the verb could finish
its work (130 Ctrl-C, 143 SIGTERM), also when it stopped cleanly (its bag closed, its report or
summary printed, its finished sweep runs kept).
"""

from __future__ import annotations

import argparse
import gc
import logging
import os
import sys

from mexone import signals
from mexone.errors import MexoneError

__all__ = ["main", "build_parser", "add_input_limit_option"]


def add_input_limit_option(p: argparse.ArgumentParser) -> None:
    """--max-input-mb, for the verbs that read a user's model, world or controller YAML."""
    from mexone.inputs import DEFAULT_LIMIT_MB, LIMIT_ENV

    p.add_argument("--max-input-mb", type=float, metavar="MB",
                   help=f"refuse input files bigger than this (default {DEFAULT_LIMIT_MB:g} MB, or "
                        f"${LIMIT_ENV}); only regular files are read")


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage mistake is one line that says where to look, not a usage dump."""

    def error(self, message: str):
        verb = self.prog.removeprefix("mexone").strip()
        where = f"{verb}: " if verb else ""
        self.exit(2, f"mexone: {where}{message} (see '{self.prog} --help')\n")


def build_parser() -> argparse.ArgumentParser:
    from mexone.cli import (
        bench,
        certify,
        check,
        controllers,
        convert,
        edit,
        example_robot,
        exercise,
        identify,
        plot,
        record,
        render,
        rosenv,
        run,
        sim,
        sweep,
    )

    parser = _Parser(
        prog="mexone",
        description="Mex-One humanoid simulation lab: URDF robots on MuJoCo with "
                    "ros_control-style controllers and ROS-named topics.",
        epilog="Run 'mexone <verb> --help' for each verb's options.",
    )
    sub = parser.add_subparsers(dest="verb", metavar="<verb>", required=True)
    for module in (sim, run, record, plot, render, sweep, identify, check, convert, controllers,
                   bench, edit, rosenv, example_robot, exercise, certify):
        module.add_parser(sub)
    return parser


class _OneLine(logging.Formatter):
    def format(self, record: logging.LogRecord) -> str:
        return f"mexone: {record.levelname.lower()}: {record.getMessage()}"


def _setup_logging() -> None:
    """Warnings (e.g. what Gazebo 7 would have done differently) as one line on stderr."""
    root = logging.getLogger("mexone")
    if not root.handlers:
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(_OneLine())
        root.addHandler(handler)
        root.setLevel(logging.WARNING)


def _offscreen_gl() -> None:
    """Cameras and videos render offscreen; MuJoCo binds its OpenGL platform when first imported,
    which the verbs do, so the process chooses it here (EGL without a display)."""
    if not os.environ.get("MUJOCO_GL") and not os.environ.get("DISPLAY"):
        os.environ["MUJOCO_GL"] = "egl"
        os.environ.setdefault("PYOPENGL_PLATFORM", "egl")


def main(argv: list[str] | None = None) -> int:
    _offscreen_gl()
    try:
        return _main(argv)
    except KeyboardInterrupt:  # Python's own handler, before ours were installed
        return signals.exit_code()
    finally:
        signals.ignore_from_now()
        if argv is None:  # the process's own command line: it exits next
            # The interpreter's exit collects the whole heap again and again (finalize_modules):
            # seconds after `identify` or a GUI session, on a busy machine 5 s between a SIGTERM
            # and the process's end. Everything is written and closed by now; frozen objects
            # are skipped by those collections (and freed as the modules go).
            gc.freeze()


def _main(argv: list[str] | None) -> int:
    try:
        # A signal during start-up is only recorded (as every signal is): the verbs load, then
        # the run stops here, one line, exit 130/143. Later, each verb's loops ask for it.
        signals.stop_on_signals()
        _setup_logging()
        parser = build_parser()
        signals.check()
        args, extra = parser.parse_known_args(argv)
        if extra:  # ROS-style name:=value may follow options: `mexone run sweep --json _joint:=x`
            if not (hasattr(args, "params") and all(":=" in e for e in extra)):
                parser.error(f"unrecognized arguments: {' '.join(extra)}")
            args.params += extra
        if getattr(args, "max_input_mb", None) is not None:
            from mexone.inputs import set_input_limit_mb

            set_input_limit_mb(args.max_input_mb)
        return signals.final_status(int(args.run(args) or 0))
    except MexoneError as exc:
        if signals.requested():  # e.g. xacro, in our process group, ended by the same Ctrl-C
            return signals.interrupted()
        print(f"mexone: {exc.one_line()}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return signals.interrupted()
    except BrokenPipeError:
        return 0
    except OSError as exc:  # the machine, not mexone: a full disk, a vanished folder, stdout gone
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"mexone: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
