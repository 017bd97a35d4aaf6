"""The walking stack's parts against closed forms, without a simulation: the whole-body QP
against static equilibrium, the LIPM MPC against the triple integrator and the capture point,
the Kalman filter against the discrete Riccati equation, the footstep planner against its rules."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest
import scipy.linalg

from mexone.dynamics import Dynamics
from mexone.walking import body as walking_body
from mexone.walking import qp
from mexone.walking.estimator import H_POSITION, H_VELOCITY, BaseKalman
from mexone.walking.footsteps import FootstepPlanner, Gait, Steps, swing_point
from mexone.walking.mpc import G, LipmMpc, Reach, lipm_matrices, supports
from mexone.walking.wbc import Foot, Task, WholeBodyQP, corner_jacobians, sole_corners

LEGS = ["l_hip_yaw", "l_hip_roll", "l_hip_pitch", "l_knee", "l_ankle_pitch", "l_ankle_roll",
        "r_hip_yaw", "r_hip_roll", "r_hip_pitch", "r_knee", "r_ankle_pitch", "r_ankle_roll"]


# ----- the whole-body QP ------------------------------------------------------------------------
@pytest.fixture(scope="module")
def standing():
    """Mex-One's model at the stack's standing posture, its soles on z = 0, at rest."""
    from mexone.lab import Lab

    lab = Lab.create(controllers=False)
    model = lab.sim.model
    data = mujoco.MjData(model)
    joints = [model.joint(j).name for j in range(1, model.njnt)]
    body = walking_body.Body.of(model, joints)
    data.qpos[:] = lab.sim.data.qpos
    data.qpos[body.qpos] = body.posture()
    dyn = Dynamics(model, data, copy=False)
    sole = dyn.pose("l_foot")[0] + dyn.pose("l_foot")[1] @ walking_body.SOLE_OFFSET
    data.qpos[2] -= sole[2]
    dyn.refresh()
    return model, dyn, body


def _feet(dyn, contact=(True, True)):
    feet = []
    for f, name in enumerate(walking_body.FEET):
        p, r = dyn.pose(name)
        centre = p + r @ walking_body.SOLE_OFFSET
        feet.append(Foot(dyn.jacobian(name, centre), dyn.jacobian_dot_qdot(name, centre), r,
                         sole_corners(*walking_body.SOLE_SIZE), contact[f]))
    return feet


def _hold_still(model) -> Task:
    """Every acceleration zero: the robot stands still."""
    return Task(np.eye(model.nv), np.zeros(model.nv), np.zeros(model.nv), 10.0)


def test_standing_still_the_feet_carry_the_weight_under_the_com(standing):
    model, dyn, body = standing
    wbc = WholeBodyQP(model.nv, body.dofs, np.full(len(body.dofs), 100.0))
    sol = wbc.solve(dyn.mass_matrix(), dyn.bias(), [_hold_still(model)], _feet(dyn))
    weight = dyn.mass() * 9.81
    total = sol.forces.sum(axis=(0, 1))
    assert total[2] == pytest.approx(weight, rel=1e-4)
    assert np.abs(total[:2]).max() < 1e-3 * weight
    # the centre of pressure is under the centre of mass (moments balance at rest)
    points = []
    for f, foot in enumerate(_feet(dyn)):
        p, r = dyn.pose(walking_body.FEET[f])
        points += [p + r @ walking_body.SOLE_OFFSET + r @ c for c in foot.corners]
    points = np.array(points)
    fz = sol.forces[:, :, 2].ravel()
    cop = fz @ points[:, :2] / fz.sum()
    assert cop == pytest.approx(dyn.com()[:2], abs=1e-4)
    # tau is the actuated rows of M q'' + h - J^T f
    jct = np.hstack([corner_jacobians(foot).reshape(12, -1).T for foot in _feet(dyn)])
    expected = (dyn.mass_matrix() @ sol.qdd + dyn.bias() - jct @ sol.forces.ravel())
    assert sol.tau == pytest.approx(expected[body.dofs], abs=1e-6)
    assert np.abs(expected[:6]).max() < 1e-6  # nothing pushes the floating base but the feet


def test_forces_stay_in_the_friction_pyramids_and_torques_in_their_limits(standing):
    model, dyn, body = standing
    limits = np.full(len(body.dofs), 100.0)
    limits[[body.joints.index(j) for j in ("l_knee", "r_knee")]] = 4.0
    wbc = WholeBodyQP(model.nv, body.dofs, limits, mu=0.3)
    # ask for a large sideways COM acceleration: the forces lean, within the pyramid
    com = Task(dyn.com_jacobian(), np.zeros(3), np.array([0.0, 3.0, 0.0]), 100.0)
    sol = wbc.solve(dyn.mass_matrix(), dyn.bias(), [com, _hold_still(model)], _feet(dyn))
    f = sol.forces.reshape(-1, 3)
    assert (f[:, 2] >= wbc.min_force - 1e-6).all()
    assert (np.abs(f[:, :2]) <= 0.3 * f[:, 2:3] + 1e-6).all()
    assert (np.abs(sol.tau) <= limits + 1e-6).all()


def test_a_foot_in_the_air_carries_nothing(standing):
    model, dyn, body = standing
    wbc = WholeBodyQP(model.nv, body.dofs, np.full(len(body.dofs), 100.0))
    sol = wbc.solve(dyn.mass_matrix(), dyn.bias(), [_hold_still(model)], _feet(dyn, (True, False)))
    assert np.abs(sol.forces[1]).max() == 0.0
    assert sol.forces[0, :, 2].sum() > 0


def test_an_impossible_or_nan_qp_is_refused_not_a_wrong_answer(standing):
    """The QP is feasible by construction (the feet are held by a stiff task, not an equality),
    so what can fail is a contradiction (here: torque limits no torque meets) or a NaN from
    upstream: both are an Infeasible, never a wrong torque."""
    model, dyn, body = standing
    wbc = WholeBodyQP(model.nv, body.dofs, np.full(len(body.dofs), -1.0))
    with pytest.raises(qp.Infeasible, match="whole-body QP has no solution"):
        wbc.solve(dyn.mass_matrix(), dyn.bias(), [_hold_still(model)], _feet(dyn))
    wbc = WholeBodyQP(model.nv, body.dofs, np.full(len(body.dofs), 100.0))
    com = Task(dyn.com_jacobian(), np.zeros(3), np.array([np.nan, 0.0, 0.0]), 100.0)
    with pytest.raises(qp.Infeasible, match="whole-body QP's cost are not finite"):
        wbc.solve(dyn.mass_matrix(), dyn.bias(), [com], _feet(dyn))


def test_an_uninstalled_solver_is_one_line():
    from mexone.errors import InputError

    with pytest.raises(InputError, match="QP solver 'nope' is not installed"):
        qp.check_solver("nope")


# ----- the LIPM MPC -----------------------------------------------------------------------------
def test_the_stacked_predictions_are_the_triple_integrator():
    T, n, h = 0.05, 12, 0.5
    A, B, ps, pu, vs, vu, as_, au, zs, zu = lipm_matrices(T, n, h)
    rng = np.random.default_rng(1)
    x0, jerks = rng.normal(size=3), rng.normal(size=n)
    x = x0.copy()
    for k in range(n):
        x = A @ x + B * jerks[k]
        assert ps[k] @ x0 + pu[k] @ jerks == pytest.approx(x[0])
        assert vs[k] @ x0 + vu[k] @ jerks == pytest.approx(x[1])
        assert zs[k] @ x0 + zu[k] @ jerks == pytest.approx(x[0] - h / G * x[2])
    # advance() is the same model over any dt
    assert LipmMpc.advance(x0, jerks[0], T) == pytest.approx(A @ x0 + B * jerks[0])


def _standing_steps(width=0.12):
    return Steps.pack(np.array([[0, width / 2, 0, 0], [0, -width / 2, 0, 0]]), [])


def test_at_rest_between_the_feet_the_plan_stays_at_rest():
    mpc = LipmMpc(0.54, 0.05, 24)
    sup = supports(_standing_steps(), 0.0, 0.05, 24, (0.16, 0.08), 0.015)
    jx, jy, shifts = mpc.solve(np.zeros(3), np.zeros(3), sup)
    assert np.abs(jx).max() < 1e-6 and np.abs(jy).max() < 1e-6 and shifts.shape == (0, 2)


W_SHIFT = 0.3  # the ComPlanner's default


def _model_walk(seconds, command=(0.3, 0.0, 0.0), push=None, h=0.54, T=0.05, n=24, dt=0.01):
    """The MPC closed on the LIPM itself for `seconds`, the feet landing where it moved them
    (the planner goes on from there, as on the robot); `push`: (t, (dvx, dvy)) added to the
    COM's velocity. Yields (t, x, y, support, jerks x, y, shift, steps) each period."""
    mpc = LipmMpc(h, T, n, w_shift=W_SHIFT, max_shift=0.2)
    planner = FootstepPlanner(Gait(), np.array([[0, 0.06, 0, 0], [0, -0.06, 0, 0]]))
    planner.set_command(*command)
    x, y = np.zeros(3), np.zeros(3)
    landing = None  # (row, shift) of the step in the air
    for k in range(round(seconds / dt)):
        t = k * dt
        if push is not None and abs(t - push[0]) < dt / 2:
            x[1] += push[1][0]
            y[1] += push[1][1]
        if landing is not None and t >= landing[0][8]:  # it landed where the MPC said
            feet = planner.feet.copy()
            feet[int(landing[0][0]), :2] = landing[0][1:3] + landing[1]
            planner.measured(feet, t)
            landing = None
        steps = planner.update(t)
        sup = supports(steps, t, T, n, (0.16, 0.08), 0.015)
        rows = Steps.rows(steps)
        adjustable = len(rows) > 0 and t < rows[0][8] - 0.05
        jx, jy, d = mpc.solve(x, y, sup, adjustable)
        if adjustable:
            landing = (rows[0].copy(), d[0].copy())
        yield t, x, y, sup, mpc, jx, jy, d, steps
        x, y = LipmMpc.advance(x, jx[0], dt), LipmMpc.advance(y, jy[0], dt)


def test_walking_plan_keeps_the_zmp_in_the_support_and_the_capture_point_bounded():
    h = 0.54
    omega = math.sqrt(G / h)
    at_4s = None
    for t, x, y, sup, mpc, jx, jy, d, steps in _model_walk(6.0):
        # the ZMP relative to its support, which moves with each landing's shift as E says
        zx = mpc.zs @ x + mpc.zu @ jx - sup.shifted @ d[:, 0]
        zy = mpc.zs @ y + mpc.zu @ jy - sup.shifted @ d[:, 1]
        c, s = np.cos(sup.yaw), np.sin(sup.yaw)
        u = c * (zx - sup.centre[:, 0]) + s * (zy - sup.centre[:, 1])
        w = -s * (zx - sup.centre[:, 0]) + c * (zy - sup.centre[:, 1])
        assert (np.abs(u) <= sup.half[:, 0] + 1e-6).all() and (np.abs(w) <= sup.half[:, 1] + 1e-6).all()
        if at_4s is None and t >= 4.0:
            at_4s = x[0]
        plan = steps
    feet = Steps.feet(plan)
    # it walked at the command's speed once up to speed, the capture point between the feet
    assert (x[0] - at_4s) / 2.0 == pytest.approx(0.3, abs=0.02)
    assert abs(y[0] + y[1] / omega) < 0.1
    assert feet[:, 0].min() - 0.1 < x[0] + x[1] / omega < feet[:, 0].max() + 0.15


def test_a_push_moves_the_next_landing_by_about_the_capture_point_offset():
    """Pushed sideways standing on the left foot (the right one in the air), the right foot
    lands further out by about the capture point's offset v / omega (the LIPM's closed form)."""
    h, T, n = 0.54, 0.05, 24
    omega = math.sqrt(G / h)
    mpc = LipmMpc(h, T, n, w_shift=0.01, max_shift=0.3)
    rows = [np.array([1, 0.0, -0.06, 0, 0, 0, 0, -0.1, 0.2]),
            np.array([0, 0.0, 0.06, 0, 0, 0, 0, 0.3, 0.6])]
    steps = Steps.pack(np.array([[0, 0.06, 0, 0], [0, -0.06, 0, 0]]), rows)
    sup = supports(steps, 0.0, T, n, (0.16, 0.08), 0.015)
    v = -0.3  # pushed toward the right foot's side
    _, _, shifts = mpc.solve(np.array([0.0, 0.0, 0.0]), np.array([0.06, v, 0.0]), sup)
    assert shifts[0, 1] < 0  # out to the right
    assert abs(shifts[0, 1]) == pytest.approx(abs(v) / omega * math.exp(omega * 0.2), rel=0.6)


def test_a_push_towards_the_standing_foot_moves_the_step_after_out_within_reach():
    """Pushed left standing on the left foot (the right one in the air): the right foot cannot
    cross over (it keeps min_apart), so the left foot's next landing goes out, by more than the
    right's moves and never beyond max_apart of where the right one lands."""
    h, T, n = 0.54, 0.05, 24
    mpc = LipmMpc(h, T, n, w_shift=0.01, max_shift=0.4)
    rows = [np.array([1, 0.0, -0.06, 0, 0, 0, 0, -0.1, 0.2]),
            np.array([0, 0.1, 0.06, 0, 0, 0, 0, 0.3, 0.6]),
            np.array([1, 0.2, -0.06, 0, 0, 0, 0, 0.7, 1.0])]
    steps = Steps.pack(np.array([[0, 0.06, 0, 0], [0, -0.06, 0, 0]]), rows)
    sup = supports(steps, 0.0, T, n, (0.16, 0.08), 0.015)
    assert sup.shifted.shape == (n, 3)
    reach = Reach(min_apart=0.09, max_apart=0.3)
    _, _, shifts = mpc.solve(np.zeros(3), np.array([0.03, 0.3, 0.0]), sup, reach=reach)
    right, left = rows[0][1:3] + shifts[0], rows[1][1:3] + shifts[1]
    assert right[1] <= 0.06 - 0.09 + 1e-9  # not across the standing left foot
    assert shifts[1, 1] > 0.05 and shifts[1, 1] > shifts[0, 1]  # the left foot steps out
    assert left[1] - right[1] <= 0.3 + 1e-9
    # a plan already out of reach stays as planned rather than being infeasible
    far = [rows[0], np.array([0, 0.1, 0.6, 0, 0, 0, 0, 0.3, 0.6])]
    sup = supports(Steps.pack(np.array([[0, 0.06, 0, 0], [0, -0.06, 0, 0]]), far), 0.0, T, n,
                   (0.16, 0.08), 0.015)
    _, _, shifts = mpc.solve(np.zeros(3), np.array([0.03, 0.0, 0.0]), sup, reach=reach)
    assert np.isfinite(shifts).all()


# ----- the Kalman filter ------------------------------------------------------------------------
def test_the_filters_gain_settles_to_the_riccati_equations():
    dt, qa, rv, rp = 0.002, 2.0, 0.05**2, 0.005**2
    kf = BaseKalman(np.zeros(3), qa)
    H = np.vstack([H_VELOCITY, H_POSITION])
    R = np.diag([rv] * 3 + [rp] * 3)
    for _ in range(5000):
        kf.predict(np.zeros(3), dt)
        prior = kf.P.copy()
        kf.correct(np.zeros(3), H_VELOCITY, rv)
        kf.correct(np.zeros(3), H_POSITION, rp)
    F, B = BaseKalman.model(dt)
    Q = qa**2 * B @ B.T
    # the a-priori covariance's fixed point: the filtering DARE (A^T, H^T)
    P = scipy.linalg.solve_discrete_are(F.T, H.T, Q, R)
    assert prior == pytest.approx(P, rel=1e-3, abs=1e-12)


def test_the_filter_tracks_a_moving_base_from_noisy_odometry():
    rng = np.random.default_rng(0)
    dt = 0.002
    kf = BaseKalman(np.zeros(3), 2.0)
    p, v = np.zeros(3), np.zeros(3)
    errors = []
    for k in range(2000):
        a = np.array([math.sin(k * dt * 3), 0.5 * math.cos(k * dt * 2), 0.0])
        p, v = p + v * dt + a * dt * dt / 2, v + a * dt
        kf.predict(a + rng.normal(0, 0.1, 3), dt)
        kf.correct(v + rng.normal(0, 0.05, 3), H_VELOCITY, 0.05**2)
        kf.correct(p + rng.normal(0, 0.005, 3), H_POSITION, 0.005**2)
        errors.append(np.linalg.norm(kf.x[3:] - v))
    assert np.sqrt(np.mean(np.square(errors[500:]))) < 0.03


# ----- the footstep planner ---------------------------------------------------------------------
def _walk(planner, seconds, dt=0.01, t0=0.0):
    landed = {}
    for k in range(round(seconds / dt)):
        t = t0 + k * dt
        for row in Steps.rows(planner.update(t)):
            landed[(int(row[0]), round(row[7], 6))] = row
    return sorted(landed.values(), key=lambda row: row[7])


def test_forward_steps_alternate_ramp_up_and_keep_their_timing():
    gait = Gait()
    planner = FootstepPlanner(gait, np.array([[0, 0.06, 0, 0], [0, -0.06, 0, 0]]))
    planner.set_command(0.3, 0.0, 0.0)
    steps = _walk(planner, 6.0)
    feet = [int(r[0]) for r in steps]
    assert all(a != b for a, b in zip(feet, feet[1:], strict=False))
    assert steps[0][7] == pytest.approx(gait.start_delay)
    for a, b in zip(steps, steps[1:], strict=False):
        assert b[7] - a[7] == pytest.approx(gait.period)
        assert a[8] - a[7] == pytest.approx(gait.single_support)
    # each foot advances two steps' motion; the motion grows by max_change up to 0.3 m/s x period
    advance = [b[1] - a[1] for a, b in zip(steps, steps[2:], strict=False)]
    assert advance[0] == pytest.approx(2 * gait.max_change + 3 * gait.max_change, abs=1e-9)
    assert advance[-1] == pytest.approx(2 * 0.3 * gait.period, abs=1e-9)
    assert all(abs(abs(r[2]) - gait.width / 2) < 1e-9 for r in steps)


def test_a_stop_brings_the_feet_square_and_stands():
    planner = FootstepPlanner(Gait(), np.array([[0, 0.06, 0, 0], [0, -0.06, 0, 0]]))
    planner.set_command(0.2, 0.0, 0.3)
    _walk(planner, 3.0)
    planner.set_command(0.0, 0.0, 0.0)
    _walk(planner, 3.0, t0=3.0)
    assert not planner.walking
    feet = planner.feet
    assert feet[0, 3] == pytest.approx(feet[1, 3])
    across = np.array([-math.sin(feet[0, 3]), math.cos(feet[0, 3])])
    assert np.dot(feet[0, :2] - feet[1, :2], across) == pytest.approx(Gait().width)
    assert np.dot(feet[0, :2] - feet[1, :2], [across[1], -across[0]]) == pytest.approx(0, abs=1e-9)


def test_sideways_the_feet_never_come_closer_than_min_apart():
    gait = Gait()
    planner = FootstepPlanner(gait, np.array([[0, 0.06, 0, 0], [0, -0.06, 0, 0]]))
    planner.set_command(0.0, -1.0, 0.0)  # clipped to max_sideways
    feet = planner.feet.copy()
    for row in _walk(planner, 5.0):
        feet[int(row[0])] = row[[1, 2, 3, 4]]
        assert feet[0, 1] - feet[1, 1] >= gait.min_apart - 1e-9
    assert feet[:, 1].mean() < -0.3


def test_hurry_lands_the_step_in_the_air_sooner_and_takes_the_next_quick():
    """Step timing adaptation: mid-swing, the step lands `quick_landing` from now (its swing at
    least `quick_single` long), the next lifts `quick_double` later and swings `quick_single`;
    then the gait's timing again. Both feet down, the foot on the push's side steps next unless
    it just stepped."""
    gait = Gait()
    planner = FootstepPlanner(gait, np.array([[0, 0.06, 0, 0], [0, -0.06, 0, 0]]))
    planner.set_command(0.3, 0.0, 0.0)
    _walk(planner, 2.0)  # at t = 2.0 a step is in the air
    swing = planner.swing.copy()
    t = swing[7] + 0.2
    assert planner.hurry(t) and not planner.hurry(t)  # once per hurried step
    rows = Steps.rows(planner.update(t))
    assert rows[0][8] == pytest.approx(max(t + gait.quick_landing, swing[7] + gait.quick_single))
    assert rows[1][7] == pytest.approx(rows[0][8] + gait.quick_double)
    assert rows[1][8] - rows[1][7] == pytest.approx(gait.quick_single)
    assert rows[2][8] - rows[2][7] == pytest.approx(gait.single_support)  # then as before
    assert rows[2][7] - rows[1][8] == pytest.approx(gait.double_support)
    # both feet down: the foot on the push's side steps next (the other just stepped)
    steps = _walk(planner, 0.5, t0=t)
    t = steps[-1][8] + 0.01
    planner.update(t)
    just = planner.last_foot
    assert planner.swing is None or t >= planner.swing[8]
    assert planner.hurry(t, outward=just) and planner.next_foot == 1 - just  # it just stepped
    planner.quick = False
    assert planner.hurry(t, outward=1 - just) and planner.next_foot == 1 - just
    assert Steps.rows(planner.update(t))[0][7] == pytest.approx(t + gait.quick_double)


def test_a_late_foot_lands_later_and_the_steps_after_wait_with_it():
    """Touchdown-gated landing: the step in the air lands when asked (`late`), never more than
    `most` after its planned landing; every later step shifts by the same wait (the double
    support kept), and a swing is never shortened by it."""
    gait = Gait()
    planner = FootstepPlanner(gait, np.array([[0, 0.06, 0, 0], [0, -0.06, 0, 0]]))
    planner.set_command(0.3, 0.0, 0.0)
    _walk(planner, 2.0)  # at t = 2.0 a step is in the air
    before = Steps.rows(planner.update(2.0))
    land = before[0][8]
    t = land - 0.01
    assert not planner.late(t, land - 0.005, 0.05)  # sooner than planned: nothing changes
    assert planner.late(t, land + 0.02, 0.05)
    assert planner.late(t + 0.02, land + 0.04, 0.05)
    assert planner.late(t + 0.04, land + 0.09, 0.05)  # cut at `most` after the planned landing
    assert not planner.late(t + 0.05, land + 0.1, 0.05)  # waited that long already
    rows = Steps.rows(planner.update(t + 0.05))
    assert rows[0][8] == pytest.approx(land + 0.05)
    assert rows[0][7] == pytest.approx(before[0][7])
    for row, was in zip(rows[1:], before[1:], strict=True):
        assert row[7:9] == pytest.approx(was[7:9] + 0.05)
    assert not planner.late(land + 0.06, land + 0.2, 0.05)  # landed: nothing in the air


def test_the_swing_lands_softly_on_its_target():
    start, target = np.array([0.0, 0.1, 0.0, 0.0]), np.array([0.2, 0.12, 0.02, 0.3])
    for t in (0.0, 0.3):
        pos, vel, acc = swing_point(start, target, 0.0, 0.3, t, 0.04)
        assert pos == pytest.approx(start if t == 0 else target)
        assert np.abs(vel).max() < 1e-9 and np.abs(acc).max() < 1e-9
    pos, _, _ = swing_point(start, target, 0.0, 0.3, 0.15, 0.04)
    assert pos[2] == pytest.approx(0.01 + 0.04)
    # velocity is the derivative of position (finite difference)
    p1, v1, a1 = swing_point(start, target, 0.0, 0.3, 0.1, 0.04)
    p2, v2, _ = swing_point(start, target, 0.0, 0.3, 0.1 + 1e-6, 0.04)
    assert (p2 - p1) / 1e-6 == pytest.approx(v1, rel=1e-4, abs=1e-6)
    assert (v2 - v1) / 1e-6 == pytest.approx(a1, rel=1e-3, abs=1e-4)
