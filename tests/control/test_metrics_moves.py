"""What `mexone run` reports for a joint's setpoint is about the motion it was commanded: a
staircase the joint cannot follow step by step is one move (overshoot as a fraction of the
whole move, settling from its last step), and a move cut by the next command before the joint
settled says "> T", not "never". Series whose answers are known by construction: the joint
follows its setpoint with a pure delay (it is outside the band of each step when the next one
comes), sampled at the recorder's 200 Hz."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from mexone.control.metrics import SAMPLE_RATE, full_metrics

DELAY = 30  # samples: the joint is its setpoint 0.15 s late, longer than a step is held


def _series(setpoint: np.ndarray, bump: dict[int, float] | None = None) -> np.ndarray:
    """Rows (t, setpoint, q): q is the setpoint DELAY samples late, except at `bump`'s samples."""
    q = np.concatenate([np.full(DELAY, setpoint[0]), setpoint[:-DELAY]])
    for k, value in (bump or {}).items():
        q[k] = value
    return np.c_[np.arange(len(setpoint)) / SAMPLE_RATE, setpoint, q]


def _staircase(levels: list[float], hold: int = 20, tail: int = 200) -> np.ndarray:
    """Each level held `hold` samples (0.1 s, a 10 Hz routine), the last one `tail` more."""
    return np.concatenate([np.repeat(levels, hold), np.full(tail, levels[-1])])


def test_a_staircase_is_one_move():
    """0 -> 0.3 rad in 15 steps of 0.02 at 10 Hz; the joint, late, passes the top by 0.015 for
    50 ms: 5 % of the move (the old report: 75 % of a 0.02 step), settled 0.2 s after the last
    step (the old: never, each step being cut by the next)."""
    sp = _staircase([0.02 * k for k in range(16)])
    last = 15 * 20  # the sample of the last step
    series = _series(sp, {k: 0.315 for k in range(last + DELAY, last + DELAY + 10)})
    m = full_metrics("j", series)
    assert (m.steps, m.moves, m.unsettled_for) == (15, 1, None)
    assert m.overshoot == pytest.approx(0.015 / 0.3)
    assert m.settling_time == pytest.approx(0.2)
    assert m.settling_text == "0.200 s"


def test_up_and_straight_back_down_is_two_moves():
    """The `arms` routine's shape: up 15 steps, at once down 15 and held. The way up is cut at
    its top 0.1 s after its last step, the joint still 0.02 short: that says only that it takes
    longer than 0.1 s, and the way down settles 0.15 s after its last step."""
    up = [0.02 * k for k in range(16)]
    series = _series(_staircase(up + up[-2::-1]))
    m = full_metrics("j", series)
    assert (m.steps, m.moves, m.overshoot) == (30, 2, 0.0)
    assert m.unsettled_for == pytest.approx(0.1)
    assert m.settling_time == pytest.approx(0.15)


def test_steps_the_joint_settles_between_stay_steps():
    """Two held steps the same way, each followed at once: two moves, not one."""
    sp = np.concatenate([np.zeros(20), np.full(200, 0.3), np.full(200, 0.6)])
    m = full_metrics("j", np.c_[np.arange(len(sp)) / SAMPLE_RATE, sp, sp])
    assert (m.steps, m.moves, m.overshoot, m.settling_time, m.unsettled_for) == (2, 2, 0.0, 0.0, None)


def test_a_step_that_never_settles_says_how_long_it_was_watched():
    t = np.arange(400) / SAMPLE_RATE
    sp = np.where(t >= 0.1, 0.5, 0.0)
    q = sp + np.where(t >= 0.1, 0.1 * np.sin(40 * t), 0.0)  # rings for the whole run
    m = full_metrics("j", np.c_[t, sp, q])
    assert m.settling_time is None and m.unsettled_for == pytest.approx(t[-1] - 0.1)
    assert m.settling_text == f"> {t[-1] - 0.1:.3f} s"


@pytest.mark.slow
def test_run_arms_reports_the_motion_it_commanded():
    """`mexone run arms` (a 10 Hz staircase of 2-degree steps): every arm joint has a settling
    figure or a lower bound, never "never"; the shoulders, which lag the steps, have fewer moves
    than steps; the table says how to read it."""
    out = subprocess.run([sys.executable, "-m", "mexone", "run", "arms", "--duration", "3",
                          "--quiet"], capture_output=True, text=True, timeout=180)
    assert out.returncode == 0, out.stderr
    rows = {line.split()[0]: line.split() for line in out.stdout.splitlines()
            if line.split() and line.split()[0].endswith(("_elbow", "_shoulder_pitch"))}
    assert len(rows) == 4 and "never" not in out.stdout
    for joint, (_, rms, _, steps, moves, *_rest) in rows.items():
        assert float(rms) < 0.05 and int(moves) <= int(steps) >= 25, joint
    assert int(rows["l_shoulder_pitch"][4]) < int(rows["l_shoulder_pitch"][3])
    assert "a move: a setpoint step, or the steps in one direction" in out.stdout
