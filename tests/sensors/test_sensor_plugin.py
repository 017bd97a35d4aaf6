"""A new sensor type is one module: a joint torque sensor written here (its MjSpec edit, state,
message, plot signal, page view) is declared in a URDF's <gazebo> block and picked up by the
reader, the model builder, the state interfaces, the broadcaster, the plots and the writers --
checked against statics (a horizontal pendulum's holding torque is m g l)."""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np
import pytest

from mexone.bus.msgs import Header
from mexone.control import parse_control_config
from mexone.description import sensors as declared
from mexone.description.sdf import read_sdf, write_sdf
from mexone.description.urdf import parse_urdf, read_urdf, write_urdf
from mexone.description.xmlio import XmlReader
from mexone.lab import Lab
from mexone.sensors import SENSOR_CLASSES, Sensor, register_sensor

G = 9.81
MASS, ARM = 1.0, 0.2  # kg at m from the hinge


# ----- the whole sensor type: one module's worth --------------------------------------------------
@dataclass
class JointEffort:
    """Its message (a new one: a header and the measured torque)."""

    header: Header = field(default_factory=Header)
    effort: float = 0.0


@dataclass
class JointTorqueState:
    effort: np.ndarray = field(default_factory=lambda: np.zeros(1))
    """N m the actuator applies to the joint"""


def joint_torque_type():
    class JointTorqueSensor(Sensor):
        state_type = JointTorqueState
        message_type = JointEffort
        plot = {"effort": "N m"}
        linear = True

        @classmethod
        def build(cls, spec, body, sensor, robot) -> None:  # the MjSpec edit
            spec.add_sensor(name=f"{sensor.name}/effort", type=mujoco.mjtSensor.mjSENS_JOINTACTFRC,
                            objtype=mujoco.mjtObj.mjOBJ_JOINT, objname=sensor.joint)

        def setup(self) -> None:  # the state: sensordata row -> effort, in the shared pass
            model = self.sim.model
            row = int(model.sensor_adr[model.sensor(f"{self.spec.name}/effort").id])
            self.measure.linear([row], [[1.0]], self.bind(effort=slice(0, 1)))

        def read(self, state: JointTorqueState) -> None:
            """Linear: nothing left to do."""

        def message(self, state: JointTorqueState) -> JointEffort:
            return JointEffort(self.header(), float(state.effort[0]))

        def view(self) -> str:
            return f"`{self.spec.joint}` {float(self.state().effort[0]):+.2f} N m"

    return JointTorqueSensor


@pytest.fixture(scope="module")
def joint_torque():
    cls = register_sensor("joint_torque")(joint_torque_type())
    yield cls
    del SENSOR_CLASSES["joint_torque"]  # leave the registry as other tests expect it


PENDULUM = f"""<robot name="pendulum">
  <link name="world"/>
  <joint name="weld" type="fixed"><parent link="world"/><child link="base"/><origin xyz="0 0 1"/></joint>
  <link name="base"><inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <joint name="hinge" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="20" velocity="5"/></joint>
  <link name="arm"><inertial><origin xyz="{ARM} 0 0"/><mass value="{MASS}"/>
    <inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4"/></inertial></link>
  <transmission name="t"><type>transmission_interface/SimpleTransmission</type>
    <joint name="hinge"><hardwareInterface>hardware_interface/EffortJointInterface</hardwareInterface></joint>
    <actuator name="m"><mechanicalReduction>1</mechanicalReduction></actuator></transmission>
  <gazebo reference="hinge">
    <sensor name="hinge_torque" type="joint_torque"><update_rate>50</update_rate></sensor>
  </gazebo>
</robot>"""
PENDULUM_YAML = """pendulum:
  hold: {type: effort_controllers/JointPositionController, joint: hinge, pid: {p: 400, d: 10, i: 200, i_clamp: 5}}
"""


@pytest.fixture(scope="module")
def pendulum(joint_torque, tmp_path_factory) -> Lab:
    path = tmp_path_factory.mktemp("pendulum") / "pendulum.urdf"
    path.write_text(PENDULUM)
    lab = Lab.create(read_urdf(path), parse_control_config(PENDULUM_YAML))
    lab.sim.run(1.0)  # settled, held horizontal
    return lab


def test_without_the_plugin_the_type_is_read_and_refused_where_it_is_built(tmp_path):
    """What a file parses to never depends on what was imported: the reader keeps any type; the
    model builder and `mexone check` refuse one no plug-in simulates, at its line."""
    robot = parse_urdf(XmlReader("pendulum.urdf", PENDULUM.replace("joint_torque", "torque_x").encode()))
    assert [(s.name, s.type, s.line) for s in robot.sensors] == [("hinge_torque", "torque_x", 13)]
    assert declared.SENSOR_TYPES == ("imu", "force_torque", "contact", "camera", "depth")
    path = tmp_path / "pendulum.urdf"
    path.write_text(PENDULUM.replace("joint_torque", "torque_x"))
    with pytest.raises(Exception, match=r"pendulum.urdf:13: sensor 'hinge_torque': mexone does not "
                                        r"simulate sensor type 'torque_x' \(types: camera, contact, depth"):
        Lab.create(read_urdf(path), parse_control_config(PENDULUM_YAML))
    from mexone.cli import main

    assert main(["check", str(path)]) == 1


def test_a_packages_sensor_type_is_found_through_its_entry_point(tmp_path):
    """A package that declares `[project.entry-points."mexone.sensors"]` is picked up without
    being imported by anyone: the URDF naming its type runs in a fresh interpreter."""
    import inspect
    import subprocess
    import sys
    import textwrap

    package = tmp_path / "torque_pkg"
    package.mkdir()
    source = inspect.getsource(JointEffort) + inspect.getsource(JointTorqueState) + \
        textwrap.dedent(inspect.getsource(joint_torque_type)) + \
        'register_sensor("joint_torque")(joint_torque_type())\n'
    (package / "__init__.py").write_text("")
    (package / "joint_torque.py").write_text(
        "from dataclasses import dataclass, field\nimport mujoco\nimport numpy as np\n"
        "from mexone.bus.msgs import Header\nfrom mexone.sensors import Sensor, register_sensor\n"
        + source)
    info = tmp_path / "torque_pkg-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: torque-pkg\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[mexone.sensors]\njoint_torque = torque_pkg.joint_torque\n")
    (tmp_path / "pendulum.urdf").write_text(PENDULUM)
    code = ("import sys; from mexone.lab import Lab; from mexone.control import parse_control_config;"
            f"lab = Lab.create(sys.argv[1], parse_control_config({PENDULUM_YAML!r})); lab.sim.run(0.5);"
            "print(type(lab.sensors.sensors['hinge_torque']).__module__, "
            "float(lab.sensors.states['hinge_torque'].effort[0]))")
    env = {**__import__("os").environ}
    env["PYTHONPATH"] = f"{tmp_path}:{env.get('PYTHONPATH', '')}"
    out = subprocess.run([sys.executable, "-c", code, str(tmp_path / "pendulum.urdf")],
                         capture_output=True, text=True, env=env, timeout=60)
    assert out.returncode == 0, out.stderr
    module, effort = out.stdout.split()
    assert module == "torque_pkg.joint_torque" and float(effort) == pytest.approx(-MASS * G * ARM, rel=0.05)


def test_a_new_sensor_type_is_declared_built_and_read(pendulum, joint_torque):
    sensor = pendulum.sensors.sensors["hinge_torque"]
    assert type(sensor) is joint_torque and sensor.link == "arm"  # the joint's child
    assert pendulum.sim.model.sensor("hinge_torque/effort") is not None  # its MjSpec edit ran
    # its state: the holding torque, m g l, against gravity's moment about +y
    effort = pendulum.sensors.states["hinge_torque"].effort
    assert effort[0] == pytest.approx(-MASS * G * ARM, rel=0.01)
    assert pendulum.sensors.states.kinds()["hinge_torque"] == "joint_torque"


def test_a_new_sensor_type_broadcasts_only_while_someone_listens(pendulum):
    sensor = pendulum.sensors.sensors["hinge_torque"]
    topic = sensor.outputs[0].topic
    assert topic == f"{pendulum.namespace}/hinge_torque" and topic in pendulum.sensors.light_topics
    assert "hinge_torque" not in pendulum.sensors.broadcasting()
    box: list = []
    sub = pendulum.bus.subscribe(topic, JointEffort, box.append)
    assert "hinge_torque" in pendulum.sensors.broadcasting()
    pendulum.sim.run(0.2)
    sub.unregister()
    assert "hinge_torque" not in pendulum.sensors.broadcasting()
    assert len(box) == pytest.approx(0.2 * 50, abs=1)  # its update rate
    assert np.mean([m.effort for m in box]) == pytest.approx(-MASS * G * ARM, rel=0.01)
    assert box[-1].header.frame_id == "arm"


def test_a_new_sensor_type_has_its_plot_signal_and_page_view(pendulum):
    from mexone.gui.plots import SignalLog

    log = SignalLog(pendulum)
    assert "hinge_torque/effort" in log.index
    assert sensor_unit(log, "hinge_torque/effort") == "N m"
    assert pendulum.sensors.readings()["hinge_torque"][0] == pytest.approx(-MASS * G * ARM, rel=0.01)
    assert "`hinge` -1.9" in pendulum.sensors.sensors["hinge_torque"].view()


def sensor_unit(log, name: str) -> str:
    return next(s.unit for s in log.signals if s.name == name)


@pytest.mark.parametrize("fmt", ["urdf", "sdf"])
def test_a_new_sensor_type_survives_the_writers(pendulum, tmp_path, fmt):
    write, read = (write_urdf, read_urdf) if fmt == "urdf" else (write_sdf, read_sdf)
    path = tmp_path / f"again.{fmt}"
    path.write_text(write(pendulum.sim.robot))
    spec = next(s for s in read(path).sensors if s.name == "hinge_torque")
    assert (spec.type, spec.joint, spec.update_rate) == ("joint_torque", "hinge", 50.0)


def test_mexone_check_lists_the_sensors_and_their_state_interfaces(capsys):
    import json

    from mexone.cli import main

    assert main(["check"]) == 0
    lines = capsys.readouterr().out.splitlines()
    imu = next(line for line in lines if line.strip().startswith("imu "))
    assert "on pelvis" in imu and imu.endswith("orientation, angular_velocity, linear_acceleration")
    contact = next(line for line in lines if line.strip().startswith("l_foot_contact "))
    assert "in_contact, force" in contact
    assert "(topics only)" in next(line for line in lines if line.strip().startswith("kinect "))
    assert main(["check", "--json"]) == 0
    rows = {r["name"]: r for r in json.loads(capsys.readouterr().out)["sensors"]}
    assert rows["l_ankle_ft"] == {"name": "l_ankle_ft", "type": "force_torque", "on": "l_ankle_roll",
                                  "rate_hz": 100.0, "state": ["force", "torque"]}
