"""mexone.dynamics.Dynamics against closed forms (a two-link planar arm), finite differences of
MuJoCo's own kinematics, mj_inverse, and mass-weighted sums over the links (Mex-One)."""

from __future__ import annotations

import threading

import mujoco
import numpy as np
import pytest

from mexone.dynamics import Dynamics
from mexone.errors import InputError
from mexone.lab import Lab

G = 9.81
M1, M2, L1, L2, C1, C2, I1, I2 = 1.3, 0.7, 0.5, 0.4, 0.22, 0.17, 0.031, 0.012
# hinge axes along -y: each link turns from +x towards +z, gravity along -z (the textbook arm)
ARM = f"""
<mujoco>
  <option gravity="0 0 -{G}"/>
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
</mujoco>"""


def arm_closed_form(q, dq):
    """M, C dq and g of the two-link planar arm (Spong, Robot Modeling and Control, 7.4)."""
    c2, s2 = np.cos(q[1]), np.sin(q[1])
    m11 = I1 + I2 + M1 * C1**2 + M2 * (L1**2 + C2**2 + 2 * L1 * C2 * c2)
    m12 = I2 + M2 * (C2**2 + L1 * C2 * c2)
    m22 = I2 + M2 * C2**2
    h = M2 * L1 * C2 * s2
    coriolis = np.array([-h * (2 * dq[0] * dq[1] + dq[1]**2), h * dq[0]**2])
    g = np.array([(M1 * C1 + M2 * L1) * G * np.cos(q[0]) + M2 * C2 * G * np.cos(q[0] + q[1]),
                  M2 * C2 * G * np.cos(q[0] + q[1])])
    return np.array([[m11, m12], [m12, m22]]), coriolis, g


@pytest.fixture(scope="module")
def arm():
    model = mujoco.MjModel.from_xml_string(ARM)
    return model, mujoco.MjData(model)


@pytest.fixture(scope="module")
def mex():
    """Mex-One in a non-trivial state: joints and base moved and moving, contacts not."""
    lab = Lab.create()
    model = lab.sim.model
    rng = np.random.default_rng(7)
    data = mujoco.MjData(model)
    data.qpos[:] = lab.sim.data.qpos
    data.qpos[2] += 0.3  # off the ground
    data.qpos[3:7] = [0.95, 0.1, -0.2, 0.15]
    data.qpos[3:7] /= np.linalg.norm(data.qpos[3:7])
    data.qpos[7:] += rng.uniform(-0.4, 0.4, model.nq - 7)
    data.qvel[:] = rng.uniform(-1.0, 1.0, model.nv)
    mujoco.mj_forward(model, data)
    links = lab.sim.compiled.bodies
    return lab, model, data, Dynamics(model, data, links, links.values())


def test_two_link_arm_mass_matrix_bias_and_gravity_are_the_closed_forms(arm):
    model, data = arm
    rng = np.random.default_rng(1)
    for _ in range(5):
        data.qpos[:] = rng.uniform(-np.pi, np.pi, 2)
        data.qvel[:] = rng.uniform(-3, 3, 2)
        dyn = Dynamics(model, data)
        mass, coriolis, g = arm_closed_form(data.qpos, data.qvel)
        np.testing.assert_allclose(dyn.mass_matrix(), mass, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(dyn.gravity(), g, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(dyn.bias(), coriolis + g, rtol=1e-12, atol=1e-12)
        qacc = rng.normal(size=2)
        np.testing.assert_allclose(dyn.inverse_dynamics(qacc), mass @ qacc + coriolis + g,
                                   rtol=1e-12, atol=1e-12)


def test_two_link_arm_tip_jacobian_and_pose_are_the_closed_forms(arm):
    model, data = arm
    q = np.array([0.4, -1.1])
    data.qpos[:], data.qvel[:] = q, [0.7, -0.3]
    dyn = Dynamics(model, data)
    s1, c1 = np.sin(q[0]), np.cos(q[0])
    s12, c12 = np.sin(q.sum()), np.cos(q.sum())
    position, rotation = dyn.pose("tip")
    np.testing.assert_allclose(position, [L1 * c1 + L2 * c12, 0, L1 * s1 + L2 * s12], atol=1e-12)
    np.testing.assert_allclose(rotation @ [1, 0, 0], [c12, 0, s12], atol=1e-12)
    jac = dyn.jacobian("tip")
    expected = np.zeros((6, 2))
    expected[0] = [-L1 * s1 - L2 * s12, -L2 * s12]
    expected[2] = [L1 * c1 + L2 * c12, L2 * c12]
    expected[4] = [-1, -1]  # both axes along -y
    np.testing.assert_allclose(jac, expected, atol=1e-12)
    # J̇ dq of the tip: the centripetal acceleration of the closed form
    dq = data.qvel
    w1, w12 = dq[0], dq.sum()
    accel = [-L1 * c1 * w1**2 - L2 * c12 * w12**2, 0, -L1 * s1 * w1**2 - L2 * s12 * w12**2]
    np.testing.assert_allclose(dyn.jacobian_dot_qdot("tip")[:3], accel, atol=1e-12)
    np.testing.assert_allclose(dyn.com(), ((M1 * C1 + M2 * L1) * np.array([c1, 0, s1])
                                           + M2 * C2 * np.array([c12, 0, s12])) / (M1 + M2), atol=1e-12)


def _pose_at(model, data, qpos, frame_body, point_local):
    scratch = mujoco.MjData(model)
    scratch.qpos[:] = qpos
    mujoco.mj_kinematics(model, scratch)
    rotation = scratch.xmat[frame_body].reshape(3, 3)
    return scratch.xpos[frame_body] + rotation @ point_local, rotation


def _moved(model, qpos, direction, eps):
    out = qpos.copy()
    mujoco.mj_integratePos(model, out, direction, eps)
    return out


@pytest.mark.parametrize("frame", ["l_forearm", "r_foot", "head", "pelvis"])
def test_mex_one_jacobians_match_finite_differences_of_the_pose(mex, frame):
    _, model, data, dyn = mex
    body = model.body(frame).id
    position, rotation = dyn.pose(frame)
    point = position + rotation @ [0.05, -0.02, 0.03]  # a point on the link, off its origin
    local = rotation.T @ (point - position)
    jac = dyn.jacobian(frame, point)
    eps = 1e-6
    fd = np.zeros_like(jac)
    for i in range(model.nv):
        e = np.zeros(model.nv)
        e[i] = 1.0
        p1, r1 = _pose_at(model, data, _moved(model, data.qpos, e, eps), body, local)
        p0, r0 = _pose_at(model, data, _moved(model, data.qpos, e, -eps), body, local)
        fd[:3, i] = (p1 - p0) / (2 * eps)
        skew = (r1 - r0) / (2 * eps) @ rotation.T  # dR/dq R^T = [w]x
        fd[3:, i] = [skew[2, 1], skew[0, 2], skew[1, 0]]
    np.testing.assert_allclose(jac, fd, atol=1e-7)
    assert np.abs(jac).max() > 0.1  # the frame moves with many columns


def test_mex_one_jacobian_dot_qdot_matches_finite_differences(mex):
    """A frame's origin is a point of its link: J at the configurations a step ahead and behind
    along dq, differenced, times dq."""
    _, model, data, dyn = mex
    eps = 1e-6
    ahead = Dynamics(model, _state(model, _moved(model, data.qpos, data.qvel, eps), data.qvel))
    behind = Dynamics(model, _state(model, _moved(model, data.qpos, data.qvel, -eps), data.qvel))
    for frame in ("l_forearm", "r_foot", "sensor/imu"):
        fd = (ahead.jacobian(frame) - behind.jacobian(frame)) / (2 * eps) @ data.qvel
        np.testing.assert_allclose(dyn.jacobian_dot_qdot(frame), fd, atol=1e-6)
        # the IMU sits at the free root's origin, whose J̇ dq is zero (v = dq[:3], w x w = 0)
        assert np.abs(fd).max() > 0.1 or frame == "sensor/imu"


def _state(model, qpos, qvel):
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = qpos, qvel
    return data


def test_mex_one_inverse_dynamics_is_mj_inverse(mex):
    _, model, data, dyn = mex
    qacc = np.random.default_rng(3).normal(size=model.nv)
    check = mujoco.MjData(model)
    check.qpos[:], check.qvel[:], check.qacc[:] = data.qpos, data.qvel, qacc
    saved = model.opt.disableflags
    model.opt.disableflags |= (mujoco.mjtDisableBit.mjDSBL_CONSTRAINT
                                 | mujoco.mjtDisableBit.mjDSBL_DAMPER | mujoco.mjtDisableBit.mjDSBL_SPRING)
    try:
        mujoco.mj_inverse(model, check)
    finally:
        model.opt.disableflags = saved
    np.testing.assert_allclose(dyn.inverse_dynamics(qacc), check.qfrc_inverse, rtol=1e-9, atol=1e-9)
    assert np.abs(check.qfrc_inverse).max() > 1.0


def test_inverse_dynamics_with_contacts_inverts_the_forward_step():
    """A robot standing on the ground under its PID actuators and a random applied force: the
    force mj_forward's acceleration needs, by inverse dynamics through the contacts, is the
    actuators' plus the applied one (MuJoCo's soft contacts make the inverse exact)."""
    lab = Lab.create()
    sim = lab.sim
    sim.step(300)
    data = mujoco.MjData(sim.model)
    mujoco.mj_copyData(data, sim.model, sim.data)
    data.qfrc_applied[:] = np.random.default_rng(5).normal(scale=2.0, size=sim.model.nv)
    mujoco.mj_forward(sim.model, data)
    assert data.ncon > 0
    dyn = Dynamics(sim.model, data)
    tau = dyn.inverse_dynamics(data.qacc, contacts=True)
    expected = data.qfrc_applied + data.qfrc_actuator
    np.testing.assert_allclose(tau, expected, atol=1e-3 * np.abs(expected).max())
    assert not np.allclose(dyn.inverse_dynamics(data.qacc), expected, atol=1.0)  # contacts matter


def test_mex_one_com_is_the_mass_weighted_sum_of_the_links(mex):
    lab, model, data, dyn = mex
    bodies = list(lab.sim.compiled.bodies.values())
    masses = model.body_mass[bodies]
    np.testing.assert_allclose(dyn.mass(), masses.sum())
    np.testing.assert_allclose(dyn.com(), masses @ data.xipos[bodies] / masses.sum(), atol=1e-12)
    jac = np.zeros((3, model.nv))
    part = np.zeros((3, model.nv))
    for body, mass in zip(bodies, masses, strict=True):
        mujoco.mj_jacBodyCom(model, data, part, None, body)
        jac += mass * part
    np.testing.assert_allclose(dyn.com_jacobian(), jac / masses.sum(), atol=1e-12)


def test_mex_one_centroidal_momentum_is_the_sum_over_the_links(mex):
    lab, model, data, dyn = mex
    com = dyn.com()
    linear, angular = np.zeros(3), np.zeros(3)
    jp, jr = np.zeros((3, model.nv)), np.zeros((3, model.nv))
    for body in lab.sim.compiled.bodies.values():
        mujoco.mj_jacBodyCom(model, data, jp, jr, body)
        v, w = jp @ data.qvel, jr @ data.qvel
        rotation = data.ximat[body].reshape(3, 3)
        inertia = rotation @ np.diag(model.body_inertia[body]) @ rotation.T
        p = model.body_mass[body] * v
        linear += p
        angular += inertia @ w + np.cross(data.xipos[body] - com, p)
    np.testing.assert_allclose(dyn.centroidal_momentum(), np.r_[linear, angular], atol=1e-10)
    np.testing.assert_allclose(linear, dyn.mass() * dyn.com_jacobian() @ data.qvel, atol=1e-10)


def test_queries_never_write_the_callers_data_and_refresh_rereads_it(mex):
    _, model, data, _ = mex
    source = mujoco.MjData(model)
    mujoco.mj_copyData(source, model, data)
    before = {k: getattr(source, k).copy() for k in ("qpos", "qvel", "qacc", "M", "xpos", "cvel",
                                                     "qfrc_bias", "subtree_com")}
    dyn = Dynamics(model, source)
    for query in (dyn.mass_matrix, dyn.bias, dyn.gravity, dyn.com, dyn.com_jacobian,
                  dyn.centroidal_momentum, lambda: dyn.jacobian("l_forearm"),
                  lambda: dyn.jacobian_dot_qdot("l_forearm"),
                  lambda: dyn.inverse_dynamics(np.ones(model.nv), contacts=True)):
        query()
    for key, value in before.items():
        np.testing.assert_array_equal(getattr(source, key), value, err_msg=key)
    # the bias after gravity(), which zeroes the scratch velocity for a moment, is still h
    np.testing.assert_allclose(dyn.bias(), source.qfrc_bias, atol=1e-12)
    old = dyn.gravity()
    source.qpos[7:] += 0.2
    np.testing.assert_array_equal(dyn.gravity(), old)  # bound, computed once per refresh
    dyn.refresh()
    assert not np.allclose(dyn.gravity(), old)


def test_bad_names_and_vectors_are_one_line_errors_listing_what_exists(mex):
    _, model, _, dyn = mex
    with pytest.raises(InputError, match="no frame named 'l_hand'.*l_forearm.*sensor/imu"):
        dyn.jacobian("l_hand")
    with pytest.raises(InputError, match="no joint named 'knee'.*l_knee"):
        dyn.dofs(["l_elbow", "knee"])
    with pytest.raises(InputError, match="nv = 27"):
        dyn.inverse_dynamics(np.zeros(3))
    with pytest.raises(InputError, match="not finite"):
        dyn.inverse_dynamics(np.full(model.nv, np.nan))
    with pytest.raises(InputError, match="point"):
        dyn.jacobian("l_forearm", point=[1, 2])
    np.testing.assert_array_equal(dyn.dofs("pelvis_free"), np.arange(6))
    assert dyn.dofs(["l_elbow"])[0] == model.jnt_dofadr[model.joint("l_elbow").id]


def test_snapshot_goes_through_the_simulation_thread_while_a_loop_runs():
    lab = Lab.create()
    stop = threading.Event()
    loop = threading.Thread(target=lambda: lab.sim.run(float("inf"), until=stop.is_set))
    loop.start()
    try:
        from helpers import wait_until
        assert wait_until(lambda: lab.sim.steps > 10 and lab.sim.loop_thread == loop.ident)
        dyn = Dynamics.snapshot(lab)
        assert dyn.mass() == pytest.approx(15.0)
        assert dyn.q.shape == (lab.sim.model.nq,)
    finally:
        stop.set()
        loop.join()
    assert "l_forearm" in dyn.frames
    # the loop's thread has ended: nobody drains the work queue, the state is read directly
    assert not lab.sim.loop_elsewhere()
    after = Dynamics.snapshot(lab, timeout=0.5)
    np.testing.assert_array_equal(after.q, lab.sim.data.qpos)


def test_com_and_momentum_of_a_model_with_two_free_bodies():
    """Two roots (a plain model's default robot is every body): the sums by hand."""
    model = mujoco.MjModel.from_xml_string("""
    <mujoco><worldbody>
      <body name="a" pos="0 0 1"><freejoint/><inertial pos="0.1 0 0" mass="2" diaginertia="0.1 0.2 0.3"/></body>
      <body name="b" pos="1 0 0"><freejoint/><inertial pos="0 0.2 0" mass="3" diaginertia="0.3 0.1 0.2"/></body>
    </worldbody></mujoco>""")
    data = mujoco.MjData(model)
    data.qvel[:] = np.random.default_rng(2).normal(size=12)
    mujoco.mj_forward(model, data)
    dyn = Dynamics(model, data)
    masses = model.body_mass[1:]
    com = masses @ data.xipos[1:] / 5.0
    np.testing.assert_allclose(dyn.com(), com, atol=1e-12)
    linear, angular = np.zeros(3), np.zeros(3)
    jp, jr = np.zeros((3, 12)), np.zeros((3, 12))
    for body in (1, 2):
        mujoco.mj_jacBodyCom(model, data, jp, jr, body)
        rotation = data.ximat[body].reshape(3, 3)
        p = model.body_mass[body] * jp @ data.qvel
        linear += p
        angular += rotation @ np.diag(model.body_inertia[body]) @ rotation.T @ jr @ data.qvel
        angular += np.cross(data.xipos[body] - com, p)
    np.testing.assert_allclose(dyn.centroidal_momentum(), np.r_[linear, angular], atol=1e-12)
    np.testing.assert_allclose(dyn.com_jacobian() @ data.qvel * 5.0, linear, atol=1e-12)


def test_every_urdf_link_is_a_frame_at_its_urdf_pose():
    """Links joined by fixed joints (the Kinect's optical frames) are bodies of their own: each
    URDF link's frame is where the URDF's kinematics put it."""
    from mexone.description.kinematics import link_frames_at

    lab = Lab.create(controllers=False)
    dyn = Dynamics.live(lab.sim)
    robot = lab.sim.robot
    assert set(robot.links) - {"world"} <= set(dyn.frames)
    root_position, root_rotation = dyn.pose(robot.root)
    angles = dict(zip(lab.sim.joint_names, lab.sim.joint_positions(), strict=True))
    for name, frame in link_frames_at(robot, angles).items():  # in the root's frame
        position, rotation = dyn.pose(name)
        np.testing.assert_allclose(root_rotation.T @ (position - root_position), frame[:3, 3], atol=1e-9)
        np.testing.assert_allclose(root_rotation.T @ rotation, frame[:3, :3], atol=1e-9)
    before = dyn.com()
    lab.sim.step(50)
    np.testing.assert_array_equal(dyn.com(), before)  # bound, not followed until refreshed
    dyn.refresh()
    assert not np.allclose(dyn.com(), before)
