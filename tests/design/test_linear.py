"""mexone.design.linearize against the analytic discrete models of a pendulum and a two-link arm
(MuJoCo's semi-implicit Euler step of the textbook equations), Mex-One's arm against its mass
matrix, and operating_point on Mex-One's feet."""

from __future__ import annotations

import control
import mujoco
import numpy as np
import pytest

from mexone.design import linearize, operating_point, state_deviation
from mexone.dynamics import Dynamics
from mexone.errors import InputError
from mexone.lab import Lab

G, H = 9.81, 0.005  # gravity, time step (Euler: v+ = v + h a, q+ = q + h v+)
M1, M2, L1, L2, C1, C2, I1, I2 = 1.3, 0.7, 0.5, 0.4, 0.22, 0.17, 0.031, 0.012


def euler_model(K, Minv):
    """The discrete model of q'' = K dq + Minv du under MuJoCo's semi-implicit Euler step."""
    n = K.shape[0]
    eye = np.eye(n)
    a = np.block([[eye + H**2 * K, H * eye], [H * K, eye]])
    b = np.vstack([H**2 * Minv, H * Minv])
    return a, b


def assert_relative(actual, expected, rtol=1e-5):
    """Entry-wise within rtol of the entry, zeros within rtol of the matrix's largest entry
    (the identity taken out of A, so its small dynamic entries are what is compared)."""
    scale = np.abs(expected).max()
    np.testing.assert_allclose(actual, expected, rtol=rtol, atol=rtol * 1e-3 * scale)


def pendulum(theta0):
    model = mujoco.MjModel.from_xml_string(f"""
    <mujoco>
      <option gravity="0 0 -{G}" timestep="{H}" integrator="Euler"/>
      <worldbody>
        <body name="rod">
          <joint name="hinge" type="hinge" axis="0 1 0"/>
          <inertial pos="0 0 -{C1}" mass="{M1}" diaginertia="{I1} {I1} 0.001"/>
          <site name="tip" pos="0 0 -{L1}"/>
        </body>
      </worldbody>
      <actuator><motor name="torque" joint="hinge"/></actuator>
      <sensor><framepos name="tip" objtype="site" objname="tip"/></sensor>
    </mujoco>""")
    data = mujoco.MjData(model)
    data.qpos[0] = theta0
    data.ctrl[0] = M1 * G * C1 * np.sin(theta0)  # holds it: an equilibrium
    return model, data


def test_a_pendulum_matches_its_analytic_discrete_model():
    theta0 = 0.4
    model, data = pendulum(theta0)
    sys = linearize(model, data, inputs="ctrl", outputs=["tip"])
    inertia = I1 + M1 * C1**2
    a, b = euler_model(np.array([[-M1 * G * C1 * np.cos(theta0) / inertia]]), np.array([[1 / inertia]]))
    assert_relative(sys.A - np.eye(2), a - np.eye(2))
    assert_relative(sys.B, b)
    # the tip (0, 0, -l) turned by theta about y: x = -l sin(theta), z = -l cos(theta)
    c = np.array([[-L1 * np.cos(theta0), 0], [0, 0], [L1 * np.sin(theta0), 0]])
    np.testing.assert_allclose(sys.C, c, rtol=1e-5, atol=1e-9)
    np.testing.assert_allclose(sys.D, 0, atol=1e-9)
    assert sys.dt == H
    assert sys.state_labels == ["hinge:q", "hinge:dq"]
    assert sys.input_labels == ["torque"] and sys.output_labels == ["tip:x", "tip:y", "tip:z"]
    # held over 5 steps: x[k+5] = A^5 x + (A^4 + ... + I) B u
    slow = linearize(model, data, inputs="ctrl", period=5 * H)
    a5 = np.linalg.matrix_power(a, 5)
    b5 = sum(np.linalg.matrix_power(a, k) for k in range(5)) @ b
    assert_relative(slow.A - np.eye(2), a5 - np.eye(2))
    assert_relative(slow.B, b5)
    assert slow.dt == pytest.approx(5 * H)


def two_link_arm():
    model = mujoco.MjModel.from_xml_string(f"""
    <mujoco>
      <option gravity="0 0 -{G}" timestep="{H}" integrator="Euler"/>
      <worldbody>
        <body name="link1">
          <joint name="j1" type="hinge" axis="0 -1 0"/>
          <inertial pos="{C1} 0 0" mass="{M1}" diaginertia="0.001 {I1} {I1}"/>
          <body name="link2" pos="{L1} 0 0">
            <joint name="j2" type="hinge" axis="0 -1 0"/>
            <inertial pos="{C2} 0 0" mass="{M2}" diaginertia="0.001 {I2} {I2}"/>
            <site name="tip" pos="{L2} 0 0"/>
          </body>
        </body>
      </worldbody>
      <actuator><motor name="m1" joint="j1"/><motor name="m2" joint="j2"/></actuator>
      <sensor><framepos name="tip" objtype="site" objname="tip"/></sensor>
    </mujoco>""")
    return model, mujoco.MjData(model)


def test_a_two_link_arm_matches_its_analytic_discrete_model():
    model, data = two_link_arm()
    q = np.array([0.3, 0.9])
    s1, c1, s12, c12 = np.sin(q[0]), np.cos(q[0]), np.sin(q.sum()), np.cos(q.sum())
    g = np.array([(M1 * C1 + M2 * L1) * G * c1 + M2 * C2 * G * c12, M2 * C2 * G * c12])
    data.qpos[:], data.ctrl[:] = q, g  # held still by its gravity torques
    sys = linearize(model, data, inputs="ctrl", outputs=["tip", "com", "pose:link2"])
    c2 = np.cos(q[1])
    mass = np.array([[I1 + I2 + M1 * C1**2 + M2 * (L1**2 + C2**2 + 2 * L1 * C2 * c2),
                      I2 + M2 * (C2**2 + L1 * C2 * c2)],
                     [I2 + M2 * (C2**2 + L1 * C2 * c2), I2 + M2 * C2**2]])
    stiffness = np.array([[-(M1 * C1 + M2 * L1) * G * s1 - M2 * C2 * G * s12, -M2 * C2 * G * s12],
                          [-M2 * C2 * G * s12, -M2 * C2 * G * s12]])  # dg/dq
    minv = np.linalg.inv(mass)
    a, b = euler_model(-minv @ stiffness, minv)
    assert_relative(sys.A - np.eye(4), a - np.eye(4))
    assert_relative(sys.B, b)
    jac = np.array([[-L1 * s1 - L2 * s12, -L2 * s12], [0, 0], [L1 * c1 + L2 * c12, L2 * c12]])
    com_jac = (M1 * C1 * np.array([[-s1, 0], [0, 0], [c1, 0]])
               + M2 * np.array([[-L1 * s1 - C2 * s12, -C2 * s12], [0, 0], [L1 * c1 + C2 * c12, C2 * c12]])
               ) / (M1 + M2)
    link2 = np.array([[-L1 * s1, 0], [0, 0], [L1 * c1, 0], [0, 0], [-1, -1], [0, 0]])  # origin, axis -y
    expected = np.vstack([jac, com_jac, link2])
    assert_relative(sys.C, np.hstack([expected, np.zeros((12, 2))]))
    np.testing.assert_array_equal(sys.D, 0)
    assert sys.state_labels == ["j1:q", "j2:q", "j1:dq", "j2:dq"]
    assert sys.output_labels[3:9] == ["com:x", "com:y", "com:z", "link2:x", "link2:y", "link2:z"]


@pytest.fixture(scope="module")
def standing():
    lab = Lab.create()
    lab.sim.run(0.3)
    return lab


def test_mex_one_arm_on_a_fixed_base_is_its_mass_matrix_block(standing):
    """Effort inputs, the rest welded: the velocity rows of B are the implicit step's
    h (M + h D)^-1 with M the arm's block of Mex-One's mass matrix, D the joints' damping."""
    arm = ["l_shoulder_pitch", "l_shoulder_roll", "l_elbow"]
    sys = linearize(standing, joints=arm, held="rigid", fixed_base=True)
    assert sys.state_labels == [f"{j}:q" for j in arm] + [f"{j}:dq" for j in arm]
    assert sys.input_labels == [f"{j}:effort" for j in arm]
    dyn = Dynamics.snapshot(standing)
    dofs = dyn.dofs(arm)
    model = standing.sim.model
    step = model.opt.timestep
    mass = dyn.mass_matrix()[np.ix_(dofs, dofs)]
    expected = step * np.linalg.inv(mass + step * np.diag(model.dof_damping[dofs]))
    assert_relative(sys.B[3:], expected)
    k, _, _ = control.dlqr(sys, np.eye(6), np.eye(3))  # a usable design model
    assert k.shape == (3, 6)
    qpos = standing.sim.data.qpos.copy()
    qpos[model.jnt_qposadr[model.joint("l_elbow").id]] += 0.01
    dx = state_deviation(sys, qpos, standing.sim.data.qvel)
    np.testing.assert_allclose(dx, [0, 0, 0.01, 0, 0, 0], atol=1e-12)


def test_mex_one_standing_model_predicts_a_step_through_the_contacts(standing):
    """The full model (54 states, 21 effort inputs) at an operating point: one nonlinear step
    from a small deviation lands where A dx + B du says."""
    point = operating_point(standing)
    sys = linearize(standing, point=point)
    assert sys.nstates == 54 and sys.ninputs == 21
    assert sys.state_labels[:3] == ["base:x", "base:y", "base:z"]
    lin = sys.linearization
    model = lin.model
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:], data.act[:] = lin.qpos, lin.qvel, lin.act
    rng = np.random.default_rng(4)
    dv = rng.normal(scale=1e-4, size=model.nv)
    du = rng.normal(scale=1e-3, size=21)
    data.qvel[:] += dv
    ctrl0 = _ctrl_at(standing, point)
    data.ctrl[:] = ctrl0
    for col, joint in enumerate(point.joints):  # effort inputs: the motors' feed-forward
        motor = model.actuator(joint).id
        data.ctrl[model.actuator_ctrladr[motor] + 2] += du[col] / model.actuator_gear[motor, 0]
    x0 = np.r_[np.zeros(model.nv), dv]
    mujoco.mj_step(model, data)
    moved = state_deviation(sys, data.qpos, data.qvel)
    rest = mujoco.MjData(model)
    rest.qpos[:], rest.qvel[:], rest.ctrl[:] = lin.qpos, lin.qvel, ctrl0
    mujoco.mj_step(model, rest)
    drift = state_deviation(sys, rest.qpos, rest.qvel)  # the point's own motion (its residual)
    predicted = sys.A @ x0 + sys.B @ du
    np.testing.assert_allclose(moved - drift, predicted, atol=1e-4 * np.abs(predicted).max())


def _ctrl_at(lab, point):
    """The controls linearize used at `point`: each PID holding its joint, the effort as
    feed-forward."""
    model = lab.sim.model
    ctrl = np.zeros(model.nu)
    for joint, effort in zip(point.joints, point.efforts, strict=True):
        motor, integral = model.actuator(joint).id, model.actuator(joint + "/i").id
        gear = model.actuator_gear[motor, 0]
        q = point.qpos[model.jnt_qposadr[model.joint(joint).id]]
        adr = model.actuator_ctrladr[motor]
        ctrl[adr:adr + 3] = gear * q, 0.0, effort / gear
        ctrl[model.actuator_ctrladr[integral]] = q
    return ctrl


def test_linearize_leaves_the_live_model_as_it_found_it(standing):
    """linearize edits the lab's own model while it differentiates (no 3 MB copy: issue 38):
    the claimed joints' gains, the dry friction and the sensor flag are back afterwards, also
    after a refused request, and `linearization.model` is the model as linearised."""
    model = standing.sim.model
    fields = ("actuator_biasprm", "actuator_gainprm", "dof_frictionloss")
    before = {name: getattr(model, name).copy() for name in fields}
    flags = model.opt.disableflags
    sys = linearize(standing, outputs=["imu/gyro"])
    with pytest.raises(InputError):
        linearize(standing, outputs=["imu/gyro"], period=0.0015)
    for name in fields:
        np.testing.assert_array_equal(getattr(model, name), before[name])
    assert model.opt.disableflags == flags
    linearised = sys.linearization.model
    assert linearised is not model and not linearised.dof_frictionloss.any()
    motor = model.actuator("l_knee").id
    assert linearised.actuator_biasprm[motor, 1] == 0.0 != model.actuator_biasprm[motor, 1]


def test_operating_point_on_both_feet_and_on_one(standing):
    both = operating_point(standing)
    assert both.contacts == ("l_foot", "r_foot")
    assert abs(both.residual[2]) < 1e-6  # the contacts carry the weight
    dyn = Dynamics(standing.sim.model, _data(standing.sim.model, both.qpos))
    tau = dyn.inverse_dynamics(np.zeros(dyn.model.nv), contacts=True)
    np.testing.assert_allclose(tau[dyn.dofs(list(both.joints))], both.efforts, atol=1e-6)
    assert abs(both.effort("l_knee")) > 0.1  # knees bent under the weight
    with pytest.raises(InputError, match="l_foot, r_foot touches the ground, not l_foot alone"):
        operating_point(standing, support="left")
    lifted = operating_point(standing, {"r_hip_pitch": -0.5, "r_knee": 1.0}, support="left")
    assert lifted.contacts == ("l_foot",)
    fixed = operating_point(standing, support="fixed")
    assert fixed.contacts == () and abs(fixed.residual[2]) == pytest.approx(
        Dynamics.snapshot(standing).mass() * 9.81, rel=1e-3)


def _data(model, qpos):
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    return data


def test_bad_requests_are_one_line_errors(standing):
    with pytest.raises(InputError, match="inputs 'torque' is not one of effort, position, velocity, ctrl"):
        linearize(standing, inputs="torque")
    with pytest.raises(InputError, match="not a multiple of the time step"):
        linearize(standing, period=0.0015)
    with pytest.raises(InputError, match="no sensor named 'gyro'.*imu/gyro"):
        linearize(standing, outputs=["gyro"])
    with pytest.raises(InputError, match="'knee': not an actuated joint.*l_knee"):
        linearize(standing, joints=["knee"])
    with pytest.raises(InputError, match="joints is empty.*l_knee"):  # was: "this model has none"
        linearize(standing, joints=[])
    with pytest.raises(InputError, match="joints names 'l_elbow' twice"):
        linearize(standing, joints=["l_elbow", "l_knee", "l_elbow"])
    with pytest.raises(InputError, match="support 'one' is not one of both, left, right, fixed"):
        operating_point(standing, support="one")
    with pytest.raises(InputError, match="'elbow', which is not a hinge"):
        operating_point(standing, {"elbow": 0.1})
    with pytest.raises(InputError, match=r"pose angle 1 of 'l_elbow' is outside its limits \[-2.5, 0.1\]"):
        operating_point(standing, {"l_elbow": 1.0})
    model, data = pendulum(0.1)
    with pytest.raises(InputError, match="needs mexone's joint actuators"):
        linearize(model, data)
    elbow = linearize(standing, joints=["l_elbow"], held="rigid", fixed_base=True)
    nv = standing.sim.model.nv
    with pytest.raises(InputError, match="qpos has 3 values; give the simulation's whole qpos or "
                                         "the model's 1"):  # was an IndexError
        state_deviation(elbow, np.zeros(3), np.zeros(nv))
    with pytest.raises(InputError, match="qvel has a NaN or inf"):
        state_deviation(elbow, standing.sim.data.qpos, np.full(nv, np.nan))
    assert state_deviation(elbow, standing.sim.data.qpos, np.zeros(nv)).shape == (2,)


def test_a_reduced_model_follows_the_pose_it_is_taken_at(standing):
    """The welded model is compiled once per joint set and posed per call: the second pose's
    model is the one a fresh compile gives there, not the first pose's."""
    from mexone.design import linear

    arm = ["r_shoulder_pitch", "r_elbow"]
    first = linearize(standing, joints=arm, held="rigid", fixed_base=True)
    model = standing.sim.model
    data = mujoco.MjData(model)
    mujoco.mj_copyData(data, model, standing.sim.data)
    data.qpos[model.jnt_qposadr[model.joint("r_shoulder_roll").id]] = -0.6  # welded, moved
    mujoco.mj_forward(model, data)
    plant = linear._take(standing, None)
    plant.data = data
    welded = [j for j in linear._moving_joints(plant) if j not in arm]
    cached = linear._welded(plant, welded, True)
    linear._REDUCED.clear()
    fresh = linear._welded(plant, welded, True)
    np.testing.assert_array_equal(cached.model.body_pos, fresh.model.body_pos)
    np.testing.assert_array_equal(cached.data.xpos, fresh.data.xpos)
    m_cached, m_fresh = (Dynamics(p.model, p.data).mass_matrix() for p in (cached, fresh))
    np.testing.assert_array_equal(m_cached, m_fresh)
    # and the pose mattered: rolling the shoulder out changed the arm's inertia about its pitch
    standing_dyn = Dynamics.snapshot(standing)
    dofs = standing_dyn.dofs(arm)
    before = standing_dyn.mass_matrix()[np.ix_(dofs, dofs)]
    assert abs(m_cached[0, 0] - before[0, 0]) > 1e-3 * before[0, 0]
    assert first.B.shape == (4, 2)


def test_mex_one_gyro_output_is_the_imu_sites_angular_jacobian(standing):
    """MuJoCo's sensor derivative (C) of the torso gyro against the dynamics' Jacobian: the gyro
    reads the site's angular velocity in the site's frame, so d gyro / d qvel = R^T J_rot."""
    sys = linearize(standing, outputs=["imu/gyro", "com"])
    dyn = Dynamics.snapshot(standing)
    nv = dyn.model.nv
    _, rotation = dyn.pose("sensor/imu")
    expected = rotation.T @ dyn.jacobian("sensor/imu")[3:]
    np.testing.assert_allclose(sys.C[:3, nv:2 * nv], expected, atol=1e-6)
    np.testing.assert_allclose(sys.C[3:, :nv], dyn.com_jacobian(), atol=1e-12)
    assert sys.output_labels == ["imu/gyro:x", "imu/gyro:y", "imu/gyro:z", "com:x", "com:y", "com:z"]


def test_a_urdf_arm_through_the_robot_stack_matches_its_analytic_model():
    """tests/data's two-link arm (welded to the world, shoulder geared 50:1) under mexone's own
    actuators: effort inputs through the motors' feed-forward, the implicit step's damping,
    the operating point's efforts = g(q); the analytic model of the same equations."""
    from pathlib import Path

    urdf = Path(__file__).parents[1] / "data" / "robots" / "arm" / "arm.urdf"
    lab = Lab.create(urdf, controllers="auto")
    q = np.array([0.4, 0.6])
    point = operating_point(lab, {"shoulder": q[0], "elbow": q[1]}, support="fixed")
    sys = linearize(lab, point=point)
    m1, c1, i1, m2, c2, i2, l1, g = 0.5, 0.15, 0.0038, 0.3, 0.125, 0.0016, 0.3, 9.81
    s1, s12, co1, co12, co2 = np.sin(q[0]), np.sin(q.sum()), np.cos(q[0]), np.cos(q.sum()), np.cos(q[1])
    gravity = -g * np.array([(m1 * c1 + m2 * l1) * s1 + m2 * c2 * s12, m2 * c2 * s12])
    np.testing.assert_allclose(point.efforts, gravity, rtol=1e-9)
    assert point.joints == ("shoulder", "elbow") and point.contacts == ()
    mass = np.array([[i1 + i2 + m1 * c1**2 + m2 * (l1**2 + c2**2 + 2 * l1 * c2 * co2),
                      i2 + m2 * (c2**2 + l1 * c2 * co2)],
                     [i2 + m2 * (c2**2 + l1 * c2 * co2), i2 + m2 * c2**2]])
    stiffness = -g * np.array([[(m1 * c1 + m2 * l1) * co1 + m2 * c2 * co12, m2 * c2 * co12],
                               [m2 * c2 * co12, m2 * c2 * co12]])  # dg/dq
    damping = np.diag([0.05, 0.05])
    h = lab.sim.model.opt.timestep
    solve = h * np.linalg.inv(mass + h * damping)  # implicitfast: (M + h D) dv = h f
    dv_dq, dv_dv = -solve @ stiffness, np.eye(2) - solve @ damping
    a = np.block([[np.eye(2) + h * dv_dq, h * dv_dv], [dv_dq, dv_dv]])
    b = np.vstack([h * solve, solve])
    assert_relative(sys.A - np.eye(4), a - np.eye(4))
    assert_relative(sys.B, b)
    assert sys.input_labels == ["shoulder:effort", "elbow:effort"]
    np.testing.assert_allclose(sys.linearization.u0, gravity, rtol=1e-9)
    # the same arm with its position PIDs closing the loop (auto gains, no I term here):
    # tau = kp (u - q) - kd dq, kd integrated implicitly with the damping
    from mexone.control.hardware import motor_gains

    model = lab.sim.model
    kp, kd = (np.diag(v) for v in zip(*(motor_gains(model, model.actuator(j).id) for j in point.joints),
                                        strict=True))
    closed = linearize(lab, point=point, inputs="position")
    solve = h * np.linalg.inv(mass + h * (damping + kd))
    dv_dq, dv_dv = -solve @ (stiffness + kp), np.eye(2) - solve @ (damping + kd)
    a = np.block([[np.eye(2) + h * dv_dq, h * dv_dv], [dv_dq, dv_dv]])
    b = np.vstack([h * solve @ kp, solve @ kp])
    assert_relative(closed.A - np.eye(4), a - np.eye(4))
    assert_relative(closed.B, b)
    np.testing.assert_allclose(closed.linearization.u0, q)
    assert np.all(np.abs(np.linalg.eigvals(closed.A)) < 1)  # the PIDs hold it


def test_an_integral_with_gain_is_a_state_and_one_without_is_not(standing):
    """A PID's integral (MuJoCo act) stays in the model only when its ki acts on something: an
    integral with ki = 0 would be a mode at 1 no input or cost sees (dlqr refuses those)."""
    import copy

    model = copy.copy(standing.sim.model)
    data = mujoco.MjData(model)
    mujoco.mj_copyData(data, model, standing.sim.data)
    integral = model.actuator("l_elbow/i").id
    model.actuator_gainprm[integral, 0] = 5.0  # ki, and its clamps (the hardware writes both)
    model.actuator_forcerange[integral] = (-1.0, 1.0)
    sys = linearize(model, data, inputs="ctrl")
    acts = [s for s in sys.state_labels if s.endswith(":act")]
    assert acts == ["l_elbow/i:act"]
    assert sys.nstates == 2 * model.nv + 1
    assert sys.ninputs == model.nu and "l_elbow:ff" in sys.input_labels
    row = sys.state_labels.index("l_elbow/i:act")
    elbow = sys.state_labels.index("l_elbow:q")
    assert sys.A[row, elbow] == pytest.approx(-model.opt.timestep, rel=1e-6)  # dz = (q_ref - q) dt
