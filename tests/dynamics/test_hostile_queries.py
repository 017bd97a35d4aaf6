"""Hostile arguments to the dynamics and the linearisation: every one is a clear InputError (or
a result), never another exception, a NaN or a changed simulation."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from helpers import fuzz
from mexone.design import linearize, operating_point
from mexone.dynamics import Dynamics
from mexone.errors import InputError
from mexone.lab import Lab

pytestmark = pytest.mark.fuzz

_LAB = None


def _lab() -> Lab:
    global _LAB
    if _LAB is None:
        _LAB = Lab.create()
    return _LAB


names = st.one_of(st.text(max_size=12), st.sampled_from(["l_forearm", "sensor/imu", "world", "l_elbow", ""]),
                  st.integers(), st.none(), st.floats())
vectors = st.one_of(st.lists(st.floats(allow_nan=True, allow_infinity=True, width=32), max_size=30),
                    st.just(np.zeros(27)), st.text(max_size=5), st.none())


@fuzz(40)
@given(frame=names, point=st.one_of(st.none(), vectors), qacc=vectors)
def test_any_frame_point_or_acceleration_is_answered_or_refused_in_one_line(frame, point, qacc):
    lab = _lab()
    before = lab.sim.data.qpos.copy()
    dyn = Dynamics(lab.sim.model, lab.sim.data, lab.sim.compiled.bodies)
    for query in (lambda: dyn.jacobian(frame, point), lambda: dyn.pose(frame),
                  lambda: dyn.jacobian_dot_qdot(frame, point), lambda: dyn.inverse_dynamics(qacc),
                  lambda: dyn.dofs(frame if isinstance(frame, str) else [frame])):
        try:
            out = query()
        except InputError as exc:
            assert "\n" not in str(exc)
            continue
        for part in (out if isinstance(out, tuple) else (out,)):
            assert np.isfinite(part).all()
    np.testing.assert_array_equal(lab.sim.data.qpos, before)


@fuzz(25)
@given(period=st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.sampled_from([0.002, 0.001, -0.001])),
       inputs=st.sampled_from(["effort", "position", "velocity", "ctrl", "torque", ""]),
       joints=st.one_of(st.none(), st.lists(st.sampled_from(["l_elbow", "knee", "pelvis_free", ""]), max_size=2)))
def test_any_linearize_request_is_a_model_or_one_line(period, inputs, joints):
    lab = _lab()
    try:
        sys = linearize(lab, inputs=inputs, joints=joints, period=period)
    except InputError as exc:
        assert "\n" not in str(exc)
        return
    assert np.isfinite(sys.A).all() and np.isfinite(sys.B).all()
    assert sys.dt == pytest.approx(period or lab.sim.model.opt.timestep)


@fuzz(20)
@given(pose=st.dictionaries(st.sampled_from(["l_elbow", "r_knee", "pelvis_free", "nope"]),
                            st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=32),
                                      st.text(max_size=3), st.none()), max_size=2),
       support=st.sampled_from(["both", "left", "right", "fixed", "one"]))
def test_any_operating_point_request_is_a_point_or_one_line(pose, support):
    lab = _lab()
    try:
        point = operating_point(lab, pose, support=support)
    except InputError as exc:
        assert "\n" not in str(exc)
        return
    assert np.isfinite(point.efforts).all() and np.isfinite(point.residual).all()
    assert point.qpos.shape == (lab.sim.model.nq,)
    assert mujoco.mj_name2id(lab.sim.model, mujoco.mjtObj.mjOBJ_JOINT, "l_elbow") >= 0
