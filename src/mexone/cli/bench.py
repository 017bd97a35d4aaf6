"""`mexone bench`: overhead over bare MuJoCo, PyBullet side by side, cold start, parallel runs."""

from __future__ import annotations

import argparse
import json
import sys

from mexone import signals
from mexone.bench import __doc__ as BENCH_DOC
from mexone.bench import format_report, run_bench


def add_parser(sub) -> None:
    p = sub.add_parser("bench", help="measure speed: overhead, PyBullet, cold start, parallel",
                       description=BENCH_DOC, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--json", action="store_true", help="print the figures as one JSON object")
    p.add_argument("--quick", action="store_true",
                   help="1 s measurements, fewer repeats (a smoke test, not for RESULTS.md)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    def progress(name: str) -> None:
        signals.check()  # between two measurements: a signal stops the bench here
        print(f"measuring {name}...", file=sys.stderr)

    report = run_bench(args.quick, progress=progress)
    signals.check()
    print(json.dumps(report.as_json(), indent=2) if args.json else format_report(report))
    return 0
