"""`mexone identify` at full size: a 20 s bag of Mex-One on a stand (21 joints, the shipped
excitation routine) whose damping, friction and armature differ from the model's by known
factors (0.5x to 3x); 63 parameters (+ the bag's command delay) fitted with the unchanged model,
validated on a second 10 s bag. Target: under 5 minutes on a 2-core machine.

    PYTHONPATH=src python benchmarks/identify.py [--seconds 20] [--json]

Prints wall time for recording, identifying (replay, fit, intervals, before/after) and the CPU
time identifying took (both threads: on a shared machine wall time says little), the largest
relative error per parameter kind and the validation RMS before and after. Record the output in
benchmarks/RESULTS.md when a change affects it.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "identify"))

import bagtools  # noqa: E402

from mexone.identify.session import Options, identify  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=20.0, help="length of the fitted bag")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        models = bagtools.make_models(folder, torso=False)
        start = time.perf_counter()
        fit = bagtools.record(folder / "fit.mcap", models.truth, models.controllers, "fixed",
                              args.seconds)
        val = bagtools.record(folder / "val.mcap", models.truth, models.controllers, "fixed",
                              10.0, seed=1)
        recorded = time.perf_counter() - start
        start, cpu = time.perf_counter(), time.process_time()
        result = identify([fit], Options(model=models.nominal, controllers=models.controllers),
                          [val])
        seconds = time.perf_counter() - start
        cpu = time.process_time() - cpu  # all threads: on a shared machine, what it cost
    worst: dict[str, float] = {}
    for i, u in enumerate(result.fit.unknowns):
        if u.name in models.values:
            err = abs(result.fit.values[i] / models.values[u.name] - 1)
            worst[u.kind] = max(worst.get(u.kind, 0.0), err)
    row = {"bag_seconds": args.seconds, "joints": len(result.experiments[0].joints),
           "parameters": len(result.fit.unknowns), "record_s": round(recorded, 1),
           "identify_s": round(seconds, 1), "identify_cpu_s": round(cpu, 1),
           "fit_s": round(result.fit.seconds, 1),
           "iterations": result.fit.iterations, "evaluations": result.fit.evaluations,
           "worst_relative_error": {k: float(f"{v:.2e}") for k, v in worst.items()},
           "rms_before_mrad": round(result.rms_before * 1000, 4),
           "rms_after_mrad": float(f"{result.rms_after * 1000:.3g}")}
    if args.json:
        print(json.dumps(row))
    else:
        for key, value in row.items():
            print(f"{key:<22} {value}")
    return 0 if seconds < 300 else 1


if __name__ == "__main__":
    sys.exit(main())
