"""Walking: the preview-controlled COM's ZMP follows the footsteps (the cart-table model, in
closed form), and Mex-One walks 1 m forward in the simulation without falling."""

from __future__ import annotations

import numpy as np

from mexone.lab import Lab
from mexone.motion.walk import Gait, preview_gains, zmp_reference
from mexone.physics.monitor import has_fallen
from mexone.routines.runner import RoutineRunner


def test_preview_control_keeps_the_zmp_on_the_footsteps():
    gait = Gait()
    feet = [np.array([0.02, 0.06]), np.array([0.02, -0.06])]
    ref, swings = zmp_reference(gait, feet, 8)
    z, horizon = 0.53, round(gait.preview / gait.dt)
    a, b, c, k_sum, k_state, k_preview = preview_gains(z, gait.dt, horizon)
    padded = np.vstack([ref, np.repeat(ref[-1:], horizon + 1, axis=0)])
    x, summed, zmp, com = np.zeros((3, 2)), np.zeros(2), [], []
    x[0] = ref[0]
    for i in range(len(ref)):
        summed += (c @ x)[0] - ref[i]
        x = a @ x + b @ (-k_sum * summed - k_state @ x - k_preview @ padded[i + 1:i + 1 + horizon])[None, :]
        zmp.append(x[0] - z / 9.81 * x[2])  # the cart-table's ZMP, p = x - (z/g) x''
        com.append(x[0].copy())
    error = np.abs(np.array(zmp) - ref).max(axis=1)
    # during each single support the ZMP sits on the stance foot (within 1 cm of its centre)...
    for start, end, _, _, _ in swings:
        assert error[start + 5:end].max() < 0.01
    # ...the COM sways between the feet, less than a foot's half width from the middle line,
    # and comes to rest over the middle of the final stance
    assert 0.01 < np.abs(np.array(com)[:, 1]).max() < 0.06
    assert np.allclose(com[-1], ref[-1], atol=1e-3)
    assert len(swings) == 8 and swings[-1][4][0] > feet[0][0] + 6 * gait.step_length - 1e-9


def test_mex_one_walks_one_metre_forward_without_falling():
    lab = Lab.create()
    sim = lab.sim
    start_height = sim.base_height
    fell = []
    sim.add_periodic(0.1, lambda s: fell.append(has_fallen(s, start_height)))
    runner = RoutineRunner(lab, "walk", {"_distance": 1.0})
    runner.run(11.0)  # 1 s stance, 18 steps of 0.4 s, 1 s standing
    assert runner.error is None
    position, quat = sim.link_pose("pelvis")
    assert not any(fell)
    assert position[0] > 0.9  # the plan's feet end 0.99 m ahead
    assert abs(position[1]) < 0.15
    yaw = np.degrees(2 * np.arctan2(quat[3], quat[0]))
    assert abs(yaw) < 10
