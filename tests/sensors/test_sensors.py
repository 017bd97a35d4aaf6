"""Sensors against physics, not against mexone's own numbers: an IMU reads gravity and rates, the
ankle force-torque sensors carry the weight above them, the centre of pressure follows the COM
as statics says, the soles report their contacts, and the Kinect sees a box where it is."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from mexone.bus import msgs
from mexone.control import parse_control_config
from mexone.description.urdf import read_urdf
from mexone.lab import Lab
from mexone.physics import CompileOptions, Spawn
from mexone.robots.mex_one import params

G = 9.81


def collect(lab: Lab, topic: str, msg_type: type, seconds: float) -> list:
    box: list = []
    sub = lab.bus.subscribe(topic, msg_type, box.append)
    lab.sim.run(seconds)
    sub.unregister()
    return box


@pytest.fixture(scope="module")
def standing():
    """Mex-One standing on its controllers, settled."""
    lab = Lab.create()
    lab.sim.run(1.0)
    return lab


def test_imu_at_rest_reads_plus_g_up(standing):
    level = Lab.create(options=CompileOptions(fixed_base=True))  # pelvis held exactly level
    acc = np.array([[m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z]
                    for m in collect(level, "/mex_rb/imu", msgs.Imu, 0.5)])
    np.testing.assert_allclose(acc.mean(axis=0), [0.0, 0.0, G], atol=0.01)
    assert acc.std(axis=0) == pytest.approx([params.IMU_ACCEL_STDDEV] * 3, rel=0.3)  # the noise
    imus = collect(standing, "/mex_rb/imu", msgs.Imu, 0.5)  # standing: the pelvis leans a hair
    assert len(imus) == pytest.approx(0.5 * params.IMU_RATE, abs=1)
    acc = np.array([[m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z]
                    for m in imus])
    expected = [_rotation(m.orientation).T @ [0.0, 0.0, G] for m in imus]  # g, seen tilted
    np.testing.assert_allclose(acc.mean(axis=0), np.mean(expected, axis=0), atol=0.01)

    assert imus[-1].header.frame_id == "pelvis"
    assert imus[-1].linear_acceleration_covariance[0] == pytest.approx(params.IMU_ACCEL_STDDEV**2)
    q = imus[-1].orientation
    assert abs(q.w) == pytest.approx(1.0, abs=1e-3)  # upright, facing +x


def _rotation(q: msgs.Quaternion) -> np.ndarray:
    out = np.zeros(9)
    mujoco.mju_quat2Mat(out, np.array([q.w, q.x, q.y, q.z]))
    return out.reshape(3, 3)


@pytest.mark.parametrize("rpy", [(0.0, 0.3, 0.0), (0.2, 0.0, 0.7), (-0.25, 0.15, -1.0)])
def test_imu_on_a_tilted_robot_reads_gravity_rotated(rpy):
    lab = Lab.create(spawn=Spawn((0, 0, 0.3), rpy), options=CompileOptions(fixed_base=True))
    imus = collect(lab, "/mex_rb/imu", msgs.Imu, 0.3)[5:]
    acc = np.mean([[m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z]
                   for m in imus], axis=0)
    rot = lab.sim.data.xmat[lab.sim.compiled.root_body].reshape(3, 3)
    expected = rot.T @ np.array([0.0, 0.0, G])  # +g up, seen from the tilted pelvis
    angle = math.degrees(math.acos(np.dot(acc, expected) / np.linalg.norm(acc) / G))
    assert angle < 0.5
    q = imus[-1].orientation
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, rot.ravel())
    assert abs(np.dot([q.w, q.x, q.y, q.z], quat)) == pytest.approx(1.0, abs=1e-6)


SPINNER = """<robot name="spinner">
  <link name="world"/>
  <joint name="weld" type="fixed"><parent link="world"/><child link="base"/><origin xyz="0 0 0.5"/></joint>
  <link name="base"><inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <joint name="spin" type="continuous"><parent link="base"/><child link="disc"/><axis xyz="0 0 1"/>
    <limit effort="50" velocity="50"/></joint>
  <link name="disc"><inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.02"/></inertial>
    <collision><geometry><cylinder radius="0.1" length="0.02"/></geometry></collision></link>
  <joint name="ft_joint" type="revolute"><parent link="disc"/><child link="arm"/><origin xyz="0.05 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="5" velocity="5"/></joint>
  <link name="arm"><inertial><origin xyz="0.1 0 0"/><mass value="0.5"/>
    <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial></link>
  <transmission name="t"><type>transmission_interface/SimpleTransmission</type>
    <joint name="spin"><hardwareInterface>hardware_interface/VelocityJointInterface</hardwareInterface></joint>
    <actuator name="m"><mechanicalReduction>1</mechanicalReduction></actuator></transmission>
  <transmission name="t2"><type>transmission_interface/SimpleTransmission</type>
    <joint name="ft_joint"><hardwareInterface>hardware_interface/EffortJointInterface</hardwareInterface></joint>
    <actuator name="m2"><mechanicalReduction>1</mechanicalReduction></actuator></transmission>
  <gazebo reference="disc">
    <sensor name="disc_imu" type="imu">
      <update_rate>200</update_rate><pose>0.08 0 0 0 0 0</pose>
      <plugin name="imu" filename="libgazebo_ros_imu_sensor.so"><robotNamespace>spinner</robotNamespace>
        <topicName>disc/imu</topicName></plugin>
    </sensor>
  </gazebo>
  <gazebo reference="ft_joint">
    <sensor name="arm_ft" type="force_torque"><update_rate>100</update_rate>
      <force_torque><frame>child</frame><measure_direction>parent_to_child</measure_direction></force_torque>
    </sensor>
  </gazebo>
  <gazebo><plugin name="ft" filename="libgazebo_ros_ft_sensor.so"><jointName>ft_joint</jointName>
    <topicName>arm/wrench</topicName><updateRate>100</updateRate></plugin></gazebo>
</robot>"""
SPINNER_YAML = """spinner:
  spin_velocity: {type: velocity_controllers/JointVelocityController, joint: spin}
  arm_position: {type: effort_controllers/JointPositionController, joint: ft_joint, pid: {p: 50, d: 1}}
"""


@pytest.fixture
def spinner(tmp_path) -> Lab:
    """A foreign robot with an IMU and a force-torque joint declared the Gazebo way."""
    path = tmp_path / "spinner.urdf"
    path.write_text(SPINNER)
    return Lab.create(read_urdf(path), parse_control_config(SPINNER_YAML))


def test_a_known_angular_rate_is_read_within_one_percent(spinner):
    spinner.bus.publish("/spinner/spin_velocity/command", msgs.Float64(3.0))
    spinner.sim.run(0.5)
    imus = collect(spinner, "/spinner/disc/imu", msgs.Imu, 0.5)
    assert len(imus) == pytest.approx(100, abs=1)
    rate = np.mean([m.angular_velocity.z for m in imus])
    assert rate == pytest.approx(3.0, rel=0.01)
    # 8 cm from the axis: centripetal acceleration w^2 r towards the axis, plus g up
    acc = np.array([imus[-1].linear_acceleration.x, imus[-1].linear_acceleration.y,
                    imus[-1].linear_acceleration.z])
    assert np.hypot(acc[0], acc[1]) == pytest.approx(9.0 * 0.08, rel=0.02)
    assert acc[2] == pytest.approx(G, abs=0.02)


def test_force_torque_on_a_foreign_robot_follows_its_declared_convention(spinner):
    """parent_to_child in the child frame: the parent holds the 0.5 kg arm up (+4.9 N) and
    against its own weight's moment about the joint (0.5 kg at 0.1 m: +0.49 N m about y is
    what gravity does; the parent supplies the opposite)."""
    spinner.sim.run(1.0)
    wrenches = collect(spinner, "/arm/wrench", msgs.WrenchStamped, 0.2)
    force = np.mean([[w.wrench.force.x, w.wrench.force.y, w.wrench.force.z] for w in wrenches], axis=0)
    torque = np.mean([[w.wrench.torque.x, w.wrench.torque.y, w.wrench.torque.z] for w in wrenches], axis=0)
    np.testing.assert_allclose(force, [0.0, 0.0, 0.5 * G], atol=0.05)
    assert torque[1] == pytest.approx(-0.5 * G * 0.1, rel=0.05)
    assert wrenches[-1].header.frame_id == "arm"


def test_ankle_sensors_carry_the_weight_above_them(standing):
    """child_to_parent in the foot's frame: +M g up, M the robot less its feet."""
    total = 0.0
    for side in ("l", "r"):
        wrenches = collect(standing, f"/mex_rb/{side}_ankle_ft", msgs.WrenchStamped, 0.2)
        assert len(wrenches) == pytest.approx(0.2 * params.FT_RATE, abs=1)
        total += np.mean([w.wrench.force.z for w in wrenches])
    feet = sum(p.mass for p in params.parts() if p.name.endswith("_foot"))
    robot = sum(p.mass for p in params.parts())
    assert total == pytest.approx((robot - feet) * G, rel=0.02)


def test_contacts_name_both_soles_and_clear_when_a_foot_lifts():
    lab = Lab.create(options=CompileOptions(fixed_base=True))  # held at standing height
    lab.sim.run(0.3)
    for side in ("l", "r"):
        states = collect(lab, f"/mex_rb/{side}_foot_contact", msgs.ContactsState, 0.1)[-1].states
        assert states and states[0].collision1_name.startswith(f"mex_rb::{side}_foot::")
        assert states[0].collision2_name == "ground_plane::link::collision"
        assert sum(w.force.z for w in states[0].wrenches) > 0  # the ground pushes up on the sole
    lab.bus.publish("/mex_rb/l_knee_position_controller/command", msgs.Float64(1.0))
    lab.bus.publish("/mex_rb/l_hip_pitch_position_controller/command", msgs.Float64(-0.5))
    lab.sim.run(1.0)
    assert collect(lab, "/mex_rb/l_foot_contact", msgs.ContactsState, 0.1)[-1].states == []
    assert collect(lab, "/mex_rb/r_foot_contact", msgs.ContactsState, 0.1)[-1].states != []


def test_sole_contact_forces_carry_the_whole_weight():
    """Standing free and still, the ground's forces on the two soles (as the bumpers report
    them, point by point and in total) hold up the whole robot: m g up, nothing sideways."""
    lab = Lab.create()
    lab.sim.run(1.0)
    weight = float(lab.sim.model.body_subtreemass[lab.sim.compiled.root_body]) * 9.81
    total, points = np.zeros(3), np.zeros(3)
    for side in ("l", "r"):
        for state in collect(lab, f"/mex_rb/{side}_foot_contact", msgs.ContactsState, 0.1)[-1].states:
            f = state.total_wrench.force
            total += (f.x, f.y, f.z)
            points += np.sum([(w.force.x, w.force.y, w.force.z) for w in state.wrenches], axis=0)
            assert all(n.z > 0.99 for n in state.contact_normals)  # the floor's normal, up
    np.testing.assert_allclose(total, points, atol=1e-9)  # the total is the sum of its points
    assert total[2] == pytest.approx(weight, rel=0.02)
    assert np.hypot(total[0], total[1]) < 0.02 * weight


def test_state_interfaces_agree_with_statics_and_with_the_messages(standing):
    """What a controller reads (`state.sensors[name]`) against statics, and against what the
    broadcasters publish at the same instant: the IMU's proper acceleration is g up in its
    frame, the ankle FT states carry the weight above the ankles, the soles' contact states
    carry the whole robot, and a camera has no state interfaces (one-line KeyError)."""
    states = standing.sensors.states
    assert set(states) == {"imu", "l_ankle_ft", "r_ankle_ft", "l_foot_contact", "r_foot_contact"}
    imu = states["imu"]
    x, y, z, w = imu.orientation
    rot = _rotation(msgs.Quaternion(x, y, z, w))
    np.testing.assert_allclose(imu.linear_acceleration, rot.T @ [0.0, 0.0, G], atol=0.05)  # noisy
    feet = sum(p.mass for p in params.parts() if p.name.endswith("_foot"))
    robot = sum(p.mass for p in params.parts())
    ankles = states["l_ankle_ft"].force[2] + states["r_ankle_ft"].force[2]
    assert ankles == pytest.approx((robot - feet) * G, rel=0.03)
    soles = states["l_foot_contact"].force + states["r_foot_contact"].force
    assert states["l_foot_contact"].in_contact and states["r_foot_contact"].in_contact
    assert soles[2] == pytest.approx(robot * G, rel=0.03)
    # the broadcaster's message at an instant carries that instant's state
    box: list = []
    sub = standing.bus.subscribe("/mex_rb/l_ankle_ft", msgs.WrenchStamped, box.append)
    standing.sim.run(0.02)
    sub.unregister()
    force = states["l_ankle_ft"].force  # the same instant as the last message (100 Hz)
    last = box[-1].wrench.force
    np.testing.assert_allclose([last.x, last.y, last.z], force, rtol=1e-12)
    with pytest.raises(KeyError, match="no sensor named 'kinect' with state interfaces"):
        states["kinect"]


def test_centre_of_pressure_follows_the_com_as_statics_predicts():
    """Standing, the ZMP measured by the ankle sensors is the COM's ground projection (on
    average: the robot sways on its ankles); leaning on the ankles moves both forward alike."""
    lab = Lab.create()
    lab.sim.run(1.0)
    before = _balance(lab)
    for k in range(1, 51):  # lean over a second: the foot flat, the legs tilt forward
        for side in ("l", "r"):
            lab.bus.publish(f"/mex_rb/{side}_ankle_pitch_position_controller/command",
                            msgs.Float64(-0.05 * k / 50))
        lab.sim.run(0.02)
    lab.sim.run(1.0)
    after = _balance(lab)
    for com, zmp in (before, after):
        assert np.linalg.norm(zmp[:2] - com[:2]) < 0.005  # statics: the ZMP under the COM
    moved = after[0][0] - before[0][0]
    assert moved > 0.02  # leaning forward moved the COM forward...
    assert after[1][0] - before[1][0] == pytest.approx(moved, abs=0.005)  # ...and the ZMP with it


def _balance(lab: Lab) -> tuple[np.ndarray, np.ndarray]:
    """Mean COM and ZMP over two seconds (50 Hz), and the support polygon holds the COM."""
    coms, zmps, polygons = [], [], []
    subs = [lab.bus.subscribe("/mex_rb/com", msgs.PointStamped, coms.append),
            lab.bus.subscribe("/mex_rb/zmp", msgs.PointStamped, zmps.append),
            lab.bus.subscribe("/mex_rb/support_polygon", msgs.PolygonStamped, polygons.append)]
    lab.sim.run(2.0)
    for sub in subs:
        sub.unregister()
    assert len(coms) == len(zmps) == len(polygons) == pytest.approx(100, abs=1)
    assert len(polygons[-1].polygon.points) >= 4  # both soles flat on the ground
    assert lab.sensors.balance.state().statically_stable
    return (np.mean([[c.point.x, c.point.y, c.point.z] for c in coms], axis=0),
            np.mean([[z.point.x, z.point.y, z.point.z] for z in zmps], axis=0))


def test_sensors_nobody_reads_cost_no_timer():
    lab = Lab.create()
    assert lab.sim.periodic == []  # joint_states and every sensor wait for a listener
    sub = lab.bus.subscribe("/mex_rb/imu", msgs.Imu, lambda m: None)
    assert len(lab.sim.periodic) == 1
    sub.unregister()
    assert lab.sim.periodic == []


# ----- a foreign camera, declared as gazebo_ros's tutorials declare it ----------------------------
CAMSTAND = """<?xml version="1.0"?>
<robot name="camstand">
  <link name="base"><inertial><mass value="2"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><geometry><box size="0.1 0.1 0.1"/></geometry></collision></link>
  <link name="camera_link"><inertial><mass value="0.1"/><inertia ixx="0.001" iyy="0.001" izz="0.001" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="cam_joint" type="fixed"><parent link="base"/><child link="camera_link"/><origin xyz="0 0 0.5"/></joint>
  <gazebo reference="camera_link">
    <sensor type="camera" name="camera1">
      <update_rate>20.0</update_rate>
      <camera name="head"><horizontal_fov>1.3962634</horizontal_fov>
        <image><width>160</width><height>120</height><format>R8G8B8</format></image>
        <clip><near>0.02</near><far>300</far></clip></camera>
      <plugin name="camera_controller" filename="libgazebo_ros_camera.so">
        <alwaysOn>true</alwaysOn><updateRate>0.0</updateRate>
        <cameraName>rrbot/camera1</cameraName>
        <imageTopicName>image_raw</imageTopicName>
        <cameraInfoTopicName>camera_info</cameraInfoTopicName>
        <frameName>camera_link_optical</frameName>
      </plugin>
    </sensor>
  </gazebo>
</robot>"""


@pytest.mark.parametrize("namespace, prefix", [(None, ""), ("/cell2", "/cell2")])
def test_a_foreign_camera_publishes_where_gazebo_ros_would(tmp_path, namespace, prefix):
    """cameraName prefixes the topics; with no robotNamespace the plugin publishes from the root
    (rrbot's /rrbot/camera1/image_raw), and spawn_model's -robot_namespace moves it all."""
    path = tmp_path / "camstand.urdf"
    path.write_text(CAMSTAND)
    lab = Lab.create(read_urdf(path), False, namespace=namespace)
    images = collect(lab, f"{prefix}/rrbot/camera1/image_raw", msgs.Image, 0.2)
    infos = collect(lab, f"{prefix}/rrbot/camera1/camera_info", msgs.CameraInfo, 0.1)
    assert len(images) == pytest.approx(4, abs=1)  # 20 Hz of sim time
    assert (images[-1].width, images[-1].height, images[-1].encoding) == (160, 120, "rgb8")
    assert images[-1].header.frame_id == infos[-1].header.frame_id == "camera_link_optical"
    fx = 80 / math.tan(1.3962634 / 2)
    np.testing.assert_allclose(infos[-1].K, [fx, 0, 79.5, 0, fx, 59.5, 0, 0, 1], rtol=1e-6)
    rgb = np.frombuffer(images[-1].data, dtype=np.uint8).reshape(120, 160, 3)
    assert rgb[:60].mean() != pytest.approx(rgb[60:].mean(), abs=5)  # sky above, floor below


# ----- the Kinect ---------------------------------------------------------------------------------
BOX_HALF = 0.2  # m: a 40 cm cube...
BOX_DISTANCE = 1.5  # ...whose front face is this far ahead of the Kinect


@pytest.fixture(scope="module")
def kinect_view():
    """Mex-One held on a stand (its head steady) looking at a cube; one frame of every output."""
    probe = Lab.create(options=CompileOptions(fixed_base=True), controllers=False)
    cam = probe.sim.model.camera("sensor/kinect").id
    eye = probe.sim.data.cam_xpos[cam].copy()
    centre = eye + np.array([BOX_DISTANCE + BOX_HALF, 0.0, 0.0])

    def cube(spec, robot) -> None:
        geom = spec.worldbody.add_geom(name="cube", type=mujoco.mjtGeom.mjGEOM_BOX,
                                       size=[BOX_HALF] * 3, pos=centre, rgba=(0.9, 0.2, 0.1, 1))
        geom.contype = geom.conaffinity = 0

    lab = Lab.create(options=CompileOptions(fixed_base=True), edits=[cube])
    lab.sim.run(0.2)
    topics = {"depth": ("/mex_rb/kinect/depth/image_raw", msgs.Image),
              "info": ("/mex_rb/kinect/depth/camera_info", msgs.CameraInfo),
              "points": ("/mex_rb/kinect/depth/points", msgs.PointCloud2),
              "rgb": ("/mex_rb/kinect/rgb/image_raw", msgs.Image)}
    got: dict[str, list] = {k: [] for k in topics}
    subs = [lab.bus.subscribe(t, c, got[k].append) for k, (t, c) in topics.items()]
    lab.sim.run(0.1)
    for sub in subs:
        sub.unregister()
    assert all(len(v) == 3 for v in got.values())  # 30 Hz
    return lab, eye, {k: v[-1] for k, v in got.items()}


def test_depth_of_a_known_box_and_its_edges_where_camera_info_puts_them(kinect_view):
    lab, eye, frame = kinect_view
    info, image = frame["info"], frame["depth"]
    assert (image.width, image.height, image.encoding) == (640, 480, "32FC1")
    assert info.header.frame_id == "kinect_depth_optical_frame"
    depth = np.frombuffer(image.data, dtype=np.float32).reshape(image.height, image.width)
    fx, cx, cy = info.K[0], info.K[2], info.K[5]
    assert info.K[4] == fx and fx == pytest.approx(320 / math.tan(math.radians(57 / 2)))
    row, col = int(round(cy)), int(round(cx))
    assert depth[row, col] == pytest.approx(BOX_DISTANCE, abs=0.01)
    # the cube's side edges, 0.2 m either side of the optical axis at the face's depth
    edge = fx * BOX_HALF / BOX_DISTANCE
    inside = np.flatnonzero(np.isfinite(depth[row]))
    assert inside[0] - (cx - edge) == pytest.approx(0.5, abs=1.0)  # the first pixel centre in
    assert (cx + edge) - inside[-1] == pytest.approx(0.5, abs=1.0)
    column = np.flatnonzero(np.abs(depth[:, col] - BOX_DISTANCE) < 0.01)
    assert column[0] - (cy - edge) == pytest.approx(0.5, abs=1.0)  # top edge (image y is down)
    assert (cy + edge) - column[-1] == pytest.approx(0.5, abs=1.0)
    rgb = np.frombuffer(frame["rgb"].data, dtype=np.uint8).reshape(480, 640, 3)
    assert rgb[row, col, 0] > 1.5 * rgb[row, col, 1]  # the red cube, seen by the RGB camera too


def test_point_cloud_put_into_the_world_by_real_tf2_lies_on_the_box(kinect_view):
    """The frame-convention test: the cloud in the optical frame (z forward, x right, y down),
    moved into `world` by Debian's tf2 with mexone's TF tree, puts the cube's face where it is."""
    from mexone.ros1.bridge import import_rospy

    import_rospy()
    import rospy
    import tf2_ros
    from geometry_msgs.msg import TransformStamped
    from sensor_msgs import point_cloud2
    from sensor_msgs.msg import PointCloud2, PointField
    from tf2_sensor_msgs.tf2_sensor_msgs import do_transform_cloud

    lab, eye, frame = kinect_view
    cloud = frame["points"]
    buffer = tf2_ros.Buffer(debug=False)  # no ROS graph needed: the library alone
    for tf in lab.transforms():
        ros_tf = TransformStamped()
        ros_tf.header.frame_id, ros_tf.child_frame_id = tf.header.frame_id, tf.child_frame_id
        ros_tf.header.stamp = rospy.Time(tf.header.stamp.secs, tf.header.stamp.nsecs)
        t, q = ros_tf.transform.translation, ros_tf.transform.rotation
        t.x, t.y, t.z = tf.translation
        q.w, q.x, q.y, q.z = tf.rotation
        buffer.set_transform(ros_tf, "mexone")
    ros_cloud = PointCloud2(height=cloud.height, width=cloud.width, is_bigendian=False,
                            point_step=cloud.point_step, row_step=cloud.row_step,
                            data=cloud.data, is_dense=cloud.is_dense,
                            fields=[PointField(f.name, f.offset, f.datatype, f.count)
                                    for f in cloud.fields])
    ros_cloud.header.frame_id = cloud.header.frame_id
    stamp = rospy.Time(cloud.header.stamp.secs, cloud.header.stamp.nsecs)
    ros_cloud.header.stamp = stamp
    moved = do_transform_cloud(ros_cloud, buffer.lookup_transform("world", cloud.header.frame_id,
                                                                 stamp))
    points = np.array(list(point_cloud2.read_points(moved, skip_nans=True)))
    on_face = np.abs(points[:, 0] - (eye[0] + BOX_DISTANCE)) < 0.05
    face, rest = points[on_face], points[~on_face]
    edge = 320 / math.tan(math.radians(57 / 2)) * BOX_HALF / BOX_DISTANCE
    assert len(face) == pytest.approx((2 * edge) ** 2, rel=0.05)  # the cube's face, every pixel
    np.testing.assert_allclose(face[:, 0], eye[0] + BOX_DISTANCE, atol=0.01)  # where it is
    np.testing.assert_allclose(rest[:, 2], 0.0, atol=0.01)  # and the rest is the floor
    assert face[:, 1].min() == pytest.approx(-BOX_HALF, abs=0.01)
    assert face[:, 1].max() == pytest.approx(BOX_HALF, abs=0.01)
    assert face[:, 2].min() == pytest.approx(eye[2] - BOX_HALF, abs=0.01)
    assert face[:, 2].max() == pytest.approx(eye[2] + BOX_HALF, abs=0.01)


def test_a_camera_rendered_in_one_thread_closes_cleanly_from_another(kinect_view):
    """The GUI renders in the simulation thread and Python may collect the renderer anywhere:
    EGL refused with EGL_BAD_ACCESS while the context stayed bound to the rendering thread."""
    import threading

    lab, _, _ = kinect_view
    camera = lab.sensors.sensors["kinect"]
    errors: list[BaseException] = []

    def render() -> None:
        try:
            camera.render(depth=False)
        except BaseException as error:  # noqa: BLE001 - reported below
            errors.append(error)

    thread = threading.Thread(target=render)
    thread.start()
    thread.join()
    camera.close()  # this thread
    assert not errors and camera.renderer is None
    assert camera.render(depth=True).shape == (480, 640)  # and a new renderer works here
    camera.close()


def test_the_kinect_sees_a_model_spawned_into_the_running_world(tmp_path):
    """gazebo_ros' spawn_urdf_model recompiles the world: the camera must render the new one
    (its renderer was built on the old model and kept drawing the world without the box)."""
    lab = Lab.create(options=CompileOptions(fixed_base=True), controllers=False)
    eye = lab.sim.data.cam_xpos[lab.sim.model.camera("sensor/kinect").id].copy()
    before = collect(lab, "/mex_rb/kinect/depth/image_raw", msgs.Image, 0.05)[-1]
    box = tmp_path / "box.urdf"
    box.write_text('<robot name="box"><link name="box"><inertial><mass value="5"/><inertia ixx="1" '
                   'iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/></inertial><collision><geometry>'
                   '<box size="0.4 0.4 3"/></geometry></collision><visual><geometry><box size="0.4 0.4 3"/>'
                   '</geometry></visual></link></robot>')
    lab.sim.add_model(box, "box", Spawn(xyz=(eye[0] + 1.7, eye[1], 1.5), on_ground=False))
    after = collect(lab, "/mex_rb/kinect/depth/image_raw", msgs.Image, 0.05)[-1]
    centre = (240, 320)
    depth_before = np.frombuffer(before.data, dtype=np.float32).reshape(480, 640)[centre]
    depth_after = np.frombuffer(after.data, dtype=np.float32).reshape(480, 640)[centre]
    assert not depth_before < 1.6  # nothing in front before (floor far away, or NaN)
    assert depth_after == pytest.approx(1.5, abs=0.01)  # the box's face, 0.2 m before its centre
