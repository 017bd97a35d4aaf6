"""`mexone <verb>`: one module per verb, each with `add_parser(subparsers)` and `run(args)`.

Exit codes: 0 ok, 1 findings or failed checks, 2 bad input (one line on stderr, no traceback),
130 interrupted.
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading

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
    from mexone.cli import bench, check, convert, plot, record, render, run, sim, sweep

    parser = _Parser(
        prog="mexone",
        description="Mex-One humanoid simulation lab: URDF robots on MuJoCo with "
                    "ros_control-style controllers and ROS-named topics.",
        epilog="Run 'mexone <verb> --help' for each verb's options.",
    )
    sub = parser.add_subparsers(dest="verb", metavar="<verb>", required=True)
    for module in (sim, run, record, plot, render, sweep, check, convert, bench):
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


def _terminate(_signum, _frame) -> None:
    raise KeyboardInterrupt  # SIGTERM ends a run like Ctrl-C: recordings close, files stay valid


def main(argv: list[str] | None = None) -> int:
    _setup_logging()
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, _terminate)
    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if extra:  # ROS-style name:=value may follow options: `mexone run sweep --json _joint:=x`
        if not (hasattr(args, "params") and all(":=" in e for e in extra)):
            parser.error(f"unrecognized arguments: {' '.join(extra)}")
        args.params += extra
    try:
        if getattr(args, "max_input_mb", None) is not None:
            from mexone.inputs import set_input_limit_mb

            set_input_limit_mb(args.max_input_mb)
        return int(args.run(args) or 0)
    except MexoneError as exc:
        print(f"mexone: {exc.one_line()}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("mexone: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 0


if __name__ == "__main__":
    sys.exit(main())
