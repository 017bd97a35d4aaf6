"""TrackingRecorder keeps running statistics, not every sample: its metrics equal those of the
whole series (full_metrics, the algorithm it replaced), and its memory does not grow with the
run's length (a 66,000 s `mexone run` grew to 5.5 GB before)."""

from __future__ import annotations

import tracemalloc
from dataclasses import dataclass, field

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mexone.control import metrics
from mexone.control.metrics import SAMPLE_RATE, TrackingRecorder, full_metrics


@dataclass
class _Hw:
    q: np.ndarray

    def position(self, rows):
        return self.q[rows]


@dataclass
class _Ctrl:
    joints: list[str]
    hw: _Hw
    setpoint: np.ndarray
    rows: np.ndarray
    tracks_position: bool = True  # a position or a trajectory controller
    running: bool = True


@dataclass
class _Manager:
    controllers: dict = field(default_factory=dict)

    @property
    def hw(self):
        return next(iter(self.controllers.values())).hw


@dataclass
class _Sim:
    time: float = 0.0

    def add_periodic(self, period, callback):
        return None


def _feed(series: np.ndarray, chunk: int, monkeypatch, history: float = 0.0, recorder=None):
    """A recorder (new, or `recorder` fed on) fed `series` (rows of t, setpoint, actual) of
    one joint 'j'."""
    monkeypatch.setattr(metrics, "CHUNK", chunk)
    if recorder is None:
        hw = _Hw(np.zeros(1))
        ctrl = _Ctrl(["j"], hw, np.zeros(1), np.array([0]))
        recorder = TrackingRecorder(_Sim(), _Manager({"c": ctrl}), history=history)
    ctrl = recorder.manager.controllers["c"]
    sim = _Sim()
    for t, sp, q in series:
        sim.time, ctrl.setpoint[0], ctrl.hw.q[0] = t, sp, q
        recorder.sample(sim)
    return recorder


def _series(levels: list[float], hold: int, seed: int) -> np.ndarray:
    """Setpoint steps through `levels`, each held `hold` samples, tracked by a damped
    second-order response with noise (overshoot, settling, some never settled)."""
    rng = np.random.default_rng(seed)
    sp = np.repeat(levels, hold)
    q, v, out = sp[0], 0.0, []
    for k, target in enumerate(sp):
        v += 0.3 * (target - q) - 0.25 * v
        q += v + rng.normal(0, 0.002)
        out.append((k / SAMPLE_RATE, target, q))
    return np.array(out)


@settings(derandomize=True, max_examples=40, deadline=None)
@given(levels=st.lists(st.sampled_from([0.0, 0.004, 0.3, 0.6, -0.5, 1.2]), min_size=1, max_size=8),
       hold=st.integers(1, 60), chunk=st.integers(1, 70), seed=st.integers(0, 9))
def test_streamed_metrics_equal_the_whole_series(levels, hold, chunk, seed):
    series = _series(levels, hold, seed)
    with pytest.MonkeyPatch.context() as mp:
        got = _feed(series, chunk, mp).metrics()["j"]
    want = full_metrics("j", series)
    assert got.rms_error == pytest.approx(want.rms_error, rel=1e-12)
    assert (got.max_error, got.overshoot, got.settling_time, got.steps, got.moves,
            got.unsettled_for) == (want.max_error, want.overshoot, want.settling_time,
                                   want.steps, want.moves, want.unsettled_for)
    assert got.as_json() == want.as_json()  # what the report prints (6 decimals)


def test_metrics_mid_run_then_on(monkeypatch):
    """metrics() may be asked mid-run (the page's step test): the run goes on the same."""
    series = _series([0.0, 0.5, -0.2, 0.5], 50, 1)
    recorder = _feed(series[:77], 16, monkeypatch)
    assert recorder.metrics()["j"] == full_metrics("j", series[:77])
    _feed(series[77:], 16, monkeypatch, recorder=recorder)
    got, want = recorder.metrics()["j"], full_metrics("j", series)
    assert got.as_json() == want.as_json()


def test_history_keeps_the_latest_samples(monkeypatch):
    series = _series([0.0, 0.5], 300, 2)
    recorder = _feed(series, 64, monkeypatch, history=1.0)
    np.testing.assert_array_equal(recorder.history("j"), series[-int(SAMPLE_RATE) - 1:])
    assert recorder.history("other").shape == (0, 3)


def _held_memory(samples: int) -> int:
    """Bytes a recorder of 4 joints holds after `samples` samples at 200 Hz."""
    joints = [f"j{i}" for i in range(4)]
    hw = _Hw(np.zeros(len(joints)))
    ctrl = _Ctrl(joints, hw, np.zeros(len(joints)), np.arange(len(joints)))
    sim = _Sim()
    tracemalloc.start()
    try:
        recorder = TrackingRecorder(sim, _Manager({"c": ctrl}))
        for k in range(samples):
            sim.time = k / SAMPLE_RATE
            ctrl.setpoint[:] = 0.3 * ((k // 400) % 2)  # a step every 2 s
            hw.q[:] = ctrl.setpoint * (1 - np.exp(-(k % 400) / 20))
            recorder.sample(sim)
        held = tracemalloc.get_traced_memory()[0]
    finally:
        tracemalloc.stop()
    assert recorder.metrics()["j0"].steps == (samples - 1) // 400
    return held


def test_memory_does_not_grow_with_the_run():
    """About 10 s and 40 s of 200 Hz samples of 4 joints hold the same memory (the old list of
    tuples held 4x: 3 MB more here, 5.5 GB after 66,000 s)."""
    short, long = _held_memory(2 * metrics.CHUNK), _held_memory(8 * metrics.CHUNK)
    assert long < short + 200_000, (short, long)



def test_a_joint_handed_to_another_controller(monkeypatch):
    """Samples of 'j' from two controllers in turn (a switch mid-chunk) are one series."""
    monkeypatch.setattr(metrics, "CHUNK", 64)
    series = _series([0.0, 0.4, -0.3], 70, 3)
    hw = _Hw(np.zeros(2))
    first = _Ctrl(["k", "j"], hw, np.zeros(2), np.array([0, 1]))
    second = _Ctrl(["j"], hw, np.zeros(1), np.array([1]), running=False)
    sim = _Sim()
    recorder = TrackingRecorder(sim, _Manager({"a": first, "b": second}))
    for n, (t, sp, q) in enumerate(series):
        if n == 100:
            first.running, second.running = False, True
        sim.time, hw.q[1] = t, q
        first.setpoint[1] = second.setpoint[0] = sp
        recorder.sample(sim)
    got = recorder.metrics()
    assert got["j"].as_json() == full_metrics("j", series).as_json()
    assert got["k"] == full_metrics("k", np.c_[series[:100, 0], np.zeros((100, 2))])


def test_the_robots_run_equals_its_whole_series(monkeypatch):
    """Mex-One's position controllers (read in one go from the position commands) during 2 s
    of the shipped sweep: each joint's metrics equal those of every sample, kept the old way
    (each controller's setpoint and position at each 5 ms)."""
    from mexone.lab import Lab
    from mexone.routines.runner import RoutineRunner

    monkeypatch.setattr(metrics, "CHUNK", 64)  # folds in the run, not only at its end
    lab = Lab.create()
    recorder = TrackingRecorder(lab.sim, lab.manager)
    rows: dict[str, list] = {}

    def keep(sim) -> None:
        for ctrl in lab.manager.controllers.values():
            if ctrl.running and ctrl.tracks_position:
                q = ctrl.hw.position(ctrl.rows)
                for joint, sp, actual in zip(ctrl.joints, ctrl.setpoint, q, strict=True):
                    rows.setdefault(joint, []).append((sim.time, float(sp), float(actual)))

    lab.sim.add_periodic(1.0 / SAMPLE_RATE, keep)
    RoutineRunner(lab, "joint_steps").run(2.0)
    got = recorder.metrics()
    assert set(got) == set(rows) and len(rows) > 10
    assert any(m.steps for m in got.values())  # the sweep moved something
    for joint, series in rows.items():
        assert got[joint].as_json() == full_metrics(joint, np.array(series)).as_json(), joint
