"""Gain sweeps: metrics against the closed form, identical across backends, resumable."""

from __future__ import annotations

import csv
import json
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import yaml

from mexone.sweep import SweepSpec, Trial, grid_trials, parse_range, run_sweep, run_trial

CONTROLLERS = """turntable:
  joint_state_controller: {type: joint_state_controller/JointStateController, publish_rate: 50}
  yaw_position_controller: {type: effort_controllers/JointPositionController, joint: yaw, pid: {p: 1, d: 0.1}}
"""


@pytest.fixture(scope="module")
def spec(tmp_path_factory, turntable):
    folder = tmp_path_factory.mktemp("turntable")
    (folder / "c.yaml").write_text(CONTROLLERS)
    return SweepSpec(("yaw",), step=0.5, duration=4.0, model=str(turntable[0](folder)),
                     controllers=str(folder / "c.yaml"))


@pytest.mark.parametrize("p,d", [(4.0, 0.2), (10.0, 0.5)])
def test_step_metrics_match_the_second_order_closed_form(spec, turntable, p, d):
    inertia = turntable[1]
    row = run_trial(spec, Trial(0, {"p": p, "d": d}))
    zeta = d / (2 * np.sqrt(p * inertia))
    wn = np.sqrt(p / inertia)
    assert row["overshoot"] == pytest.approx(np.exp(-zeta * np.pi / np.sqrt(1 - zeta**2)), rel=0.05)
    # 2% settling of an underdamped second-order system: about 4 / (zeta wn)
    assert row["settling_time"] == pytest.approx(4 / (zeta * wn), rel=0.25)
    assert row["fell"] is False and row["max_effort"] == pytest.approx(p * 0.5, rel=0.02)


def test_backends_give_identical_numbers(tmp_path):
    pytest.importorskip("ray")
    spec = SweepSpec(("l_elbow",), step=-0.4, duration=0.6)
    trials = grid_trials({"p": np.array([30.0, 90.0]), "d": np.array([0.3, 1.0])})
    serial = run_sweep(spec, trials, tmp_path / "serial.csv", workers=1)
    local = run_sweep(spec, trials, tmp_path / "local.csv", workers=2)
    ray = run_sweep(spec, trials, tmp_path / "ray.csv", workers=2, backend="ray")
    for a, b, c in zip(serial, local, ray, strict=True):
        assert a == b == c
    assert len({r["iae"] for r in serial}) == 4  # the gains made a difference


def sweep_cli(*args, **kw):
    return subprocess.Popen([sys.executable, "-m", "mexone", "sweep", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)


def rows(path):
    with path.open() as handle:
        return list(csv.DictReader(handle))


def test_interrupt_keeps_finished_runs_and_resume_completes(tmp_path):
    out = tmp_path / "sweep"
    args = ["--joint", "l_elbow", "--step", "-0.5", "--p", "20:120:6", "--d", "0.3,1.2",
            "--duration", "1", "--workers", "1", "-o", str(out)]
    proc = sweep_cli(*args)
    deadline = time.time() + 120
    while time.time() < deadline and (not (out / "sweep.csv").exists()
                                      or len(rows(out / "sweep.csv")) < 3):
        time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    proc.wait(timeout=60)
    assert proc.returncode == 130
    kept = rows(out / "sweep.csv")
    assert 3 <= len(kept) < 12
    refused = sweep_cli(*args)
    refused.wait(timeout=60)
    assert refused.returncode == 2 and "--resume to continue it" in refused.stderr.read()
    resumed = sweep_cli(*args, "--resume")
    resumed.wait(timeout=300)
    assert resumed.returncode == 0, resumed.stderr.read()
    final = rows(out / "sweep.csv")
    assert sorted(int(r["index"]) for r in final) == list(range(12))
    assert final[: len(kept)] == kept  # the finished runs were kept as they were
    best = yaml.safe_load((out / "best_gains.yaml").read_text())
    pid = best["mex_rb"]["l_elbow_position_controller"]["pid"]
    assert set(pid) == {"p", "d"} and pid["p"] in {20, 40, 60, 80, 100, 120}
    from PIL import Image

    image = np.asarray(Image.open(out / "heatmap.png").convert("L"), dtype=float)
    assert image.shape[1] > 400 and image.std() > 10
    assert json.loads((out / "sweep.json").read_text())["ranges"]["d"] == [0.3, 1.2]


def test_bad_ranges():
    with pytest.raises(Exception, match="is not a value"):
        parse_range("abc", "p")
    with pytest.raises(Exception, match="must be finite and >= 0"):
        parse_range("-1,2", "d")
    assert parse_range("1:3:3", "p").tolist() == [1.0, 2.0, 3.0]


def test_routine_mode_scores_a_whole_routine():
    spec = SweepSpec(("l_shoulder_pitch", "r_shoulder_pitch"), routine="arms", duration=2.0)
    soft = run_trial(spec, Trial(0, {"p": 20.0, "d": 0.5}))
    stiff = run_trial(spec, Trial(1, {"p": 150.0, "d": 2.0}))
    assert soft["fell"] is False and stiff["fell"] is False
    assert soft["iae"] > stiff["iae"] > 0  # stiffer arms track the routine better
    assert soft["rise_time"] is None and soft["max_effort"] > 0


def test_a_step_beyond_the_joint_limits_is_refused_before_any_run(tmp_path):
    """l_elbow's home is 0.1 rad from its upper limit: a +5 rad step would be clipped to that
    and score a near-perfect IAE for doing nothing; the sweep refuses it, creating no files."""
    out = tmp_path / "sweep"
    refused = subprocess.run([sys.executable, "-m", "mexone", "sweep", "--joint", "l_elbow",
                              "--p", "10,50", "--step", "5", "-o", str(out)],
                             capture_output=True, text=True, timeout=120)
    assert refused.returncode == 2 and refused.stderr.count("\n") == 1, refused.stderr
    assert "leaves its limits" in refused.stderr and "at most +0.100 rad" in refused.stderr
    assert not out.exists()
