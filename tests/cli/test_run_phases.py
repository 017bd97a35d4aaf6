"""`mexone run`'s phases (the walk's legs) from the base samples nearest each declared start and
end, kept as the run goes (PhaseMarks), equal those found in the whole track (argmin over every
sample, as the run kept it before: without bound)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from mexone.cli.run import TRACK_PERIOD, PhaseMarks, _phases


def whole_track_phases(declared, track: np.ndarray) -> list[tuple]:
    out = []
    for name, start, end in declared:
        if start > track[-1, 0]:
            break
        a = track[np.argmin(np.abs(track[:, 0] - start))]
        b = track[np.argmin(np.abs(track[:, 0] - end))]
        out.append((name, round(float(a[0]), 3), round(float(b[0] - a[0]), 3)))
    return out


@settings(derandomize=True, max_examples=60, deadline=None)
@given(samples=st.integers(1, 300), seed=st.integers(0, 99),
       bounds=st.lists(st.tuples(st.floats(0, 7), st.floats(0.001, 3)), min_size=1, max_size=5))
def test_phases_from_the_kept_samples_equal_the_whole_tracks(samples, seed, bounds):
    rng = np.random.default_rng(seed)
    first = np.array([0.0, 0.0, 0.0, 0.0])
    track = [first] + [np.array([k * TRACK_PERIOD, *rng.normal(size=3)])
                       for k in range(1, samples + 1)]
    declared = [[f"leg{i}", round(s, 3), round(s + d, 3)] for i, (s, d) in enumerate(bounds)]
    marks = PhaseMarks(first)
    for sample in track[1:]:
        marks.add(declared, sample)
    got = _phases(declared, marks)
    want = whole_track_phases(declared, np.array(track))
    assert [(p["leg"], p["start"], p["seconds"]) for p in got] == want
    for p, (name, start, end) in zip(got, declared, strict=False):  # the figures from a, b
        whole = np.array(track)
        a = whole[np.argmin(np.abs(whole[:, 0] - start))]
        b = whole[np.argmin(np.abs(whole[:, 0] - end))]
        c, s = np.cos(a[3]), np.sin(a[3])
        assert p["distance_x"] == round(float(c * (b[1] - a[1]) + s * (b[2] - a[2])), 4), name
