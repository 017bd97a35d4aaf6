"""`mexone bench` runs every row and reports them in one JSON object (no timing thresholds:
the figures go to benchmarks/RESULTS.md, not into assertions)."""

from __future__ import annotations

import json
import os
import subprocess
import sys


def test_bench_quick_json():
    out = subprocess.run([sys.executable, "-m", "mexone", "bench", "--quick", "--json"],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    assert report["overhead"]["ratio"] > 0 and report["cold_start_s"] > 0
    assert report["overhead_sensors"]["ratio"] > 0 and report["overhead_balance"]["ratio"] > 0
    assert report["sensor_states"]["ratio"] > 0 and report["sensor_states"]["pd_s_per_sim_s"] > 0
    assert report["camera"]["rgb_ms_per_frame"] > 0 and report["camera"]["depth_cloud_ms_per_frame"] > 0
    pybullet = report["pybullet"]
    assert pybullet is not None, "pybullet (the [peers] extra) is part of the test install"
    assert pybullet["fall"]["mexone"]["base_height_m"] < 0.5  # both robots fell...
    assert pybullet["fall"]["pybullet"]["base_height_m"] < 0.5  # ...in both simulators
    backends = {(r["backend"], r["workers"]) for r in report["parallel"]}
    assert len(backends) == 2 * (os.cpu_count() or 1)
    controller = report["python_controller"]  # in the lab's process, and in a worker process
    assert controller["framework_us_per_update"] > 0 and controller["worker_round_trip_us"] > 0
    assert controller["worker_lab_cpu_us_per_update"] > 0 and controller["worker_start_s"] > 0
