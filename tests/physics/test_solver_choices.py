"""The two speed choices compile makes (DECISIONS.md) change no physics: Euler for models without
actuators computes implicitfast's step, and big trees get CG with an arena that fits them."""

from __future__ import annotations

import mujoco
import numpy as np

from mexone.description.loader import load_model
from mexone.physics.compile import compile_model
from mexone.robots import mex_one


def test_without_actuators_euler_takes_implicitfasts_step():
    compiled = compile_model(load_model(mex_one.urdf_path()))  # no edits: no actuators
    model = compiled.model
    assert model.nu == 0 and model.opt.integrator == mujoco.mjtIntegrator.mjINT_EULER
    assert model.dof_damping.any()  # Mex-One's joints are damped: Euler treats that implicitly
    states = []
    for integrator in (mujoco.mjtIntegrator.mjINT_EULER, mujoco.mjtIntegrator.mjINT_IMPLICITFAST):
        model.opt.integrator = integrator
        data = mujoco.MjData(model)
        mujoco.mj_step(model, data, 500)  # falls and hits the ground
        states.append(np.r_[data.qpos, data.qvel])
    np.testing.assert_allclose(states[0], states[1], rtol=0, atol=1e-9)


def test_with_actuators_the_integrator_stays_implicitfast():
    def motor(spec, robot):
        spec.add_actuator(name="m", target="l_knee", trntype=mujoco.mjtTrn.mjTRN_JOINT)

    compiled = compile_model(load_model(mex_one.urdf_path()), edits=[motor])
    assert compiled.model.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    assert compiled.model.opt.solver == mujoco.mjtSolver.mjSOL_NEWTON  # 27 dofs: Newton
