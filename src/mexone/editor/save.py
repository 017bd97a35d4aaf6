"""Saving what the editor built: URDF (with <gazebo> references and transmissions), SDF (what
Gazebo's Model Editor saved), the ros_control YAML, and a ROS package a student can roslaunch.
Every writer goes through mexone.files: nothing is replaced without force."""

from __future__ import annotations

import shutil
from dataclasses import replace
from pathlib import Path

import yaml

from mexone.control.autotune import POSITION_TYPE, STATE_RATE, STATE_TYPE, controller_name
from mexone.description.convert import merge_massless, rebase_meshes
from mexone.description.meshes import resolve_mesh
from mexone.description.model import Mesh, RobotModel
from mexone.description.sdf import write_sdf
from mexone.description.urdf import read_urdf, write_urdf
from mexone.editor.session import EditSession
from mexone.errors import InputError, OutputExistsError
from mexone.files import check_output, usable, write_text

__all__ = ["save_urdf", "save_sdf", "save_controllers", "save_package", "controllers_text"]

_COMMENT = "written by 'mexone edit'"


def _model(session: EditSession) -> RobotModel:
    """A private copy of the current model (the writers rebase meshes in place)."""
    return read_urdf(session.folder / "model.urdf")


def _placed(session: EditSession, out_dir: Path) -> RobotModel:
    """The model with mesh paths valid from `out_dir`, and the package:// or model:// URIs an
    opened model had written back as they were."""
    model = rebase_meshes(_model(session), out_dir)
    uris = session.extras.uris

    def back(geometry):
        if isinstance(geometry, Mesh) and geometry.filename in uris:
            return replace(geometry, filename=uris[geometry.filename])
        return geometry

    for link in model.links.values():
        link.visuals = [replace(v, geometry=back(v.geometry)) for v in link.visuals]
        link.collisions = [replace(c, geometry=back(c.geometry)) for c in link.collisions]
    return model


def save_urdf(session: EditSession, path: Path, force: bool = False) -> Path:
    check_output(path, force)
    write_text(path, write_urdf(_placed(session, path.parent)), force)
    return path


def save_sdf(session: EditSession, path: Path, force: bool = False) -> Path:
    """SDF 1.6 as `mexone convert` writes it (massless frames merged: SDF has none)."""
    check_output(path, force)
    model, _merged = merge_massless(_placed(session, path.parent))
    write_text(path, write_sdf(model), force)
    return path


def controllers_text(session: EditSession) -> str:
    """The ros_control YAML of the motors: a joint_state_controller and a position controller
    per motor with the gains set in the editor."""
    ns = session.namespace.strip("/")
    body: dict = {"joint_state_controller": {"type": STATE_TYPE, "publish_rate": STATE_RATE}}
    for joint, gains in session.extras.motors.items():
        pid = {"p": gains.p, "i": gains.i, "d": gains.d}
        if gains.i_clamp_min or gains.i_clamp_max:
            pid |= {"i_clamp_min": gains.i_clamp_min, "i_clamp_max": gains.i_clamp_max}
        body[controller_name(joint)] = {"type": POSITION_TYPE, "joint": joint, "pid": pid}
    return (f"# ros_control controllers for '{session.model.name}', {_COMMENT}\n"
            f"# (gains start at 'mexone controllers' auto gains). Load with: rosparam load <this file>\n"
            + yaml.safe_dump({ns: body}, sort_keys=False))


def save_controllers(session: EditSession, path: Path, force: bool = False) -> Path:
    if path.suffix.lower() not in (".yaml", ".yml"):
        raise InputError(f"'{path.name}' is not a .yaml file", hint="name it controllers.yaml")
    check_output(path, force)
    write_text(path, controllers_text(session), force)
    return path


_PACKAGE_XML = """<?xml version="1.0"?>
<package format="2">
  <name>{name}</name>
  <version>0.1.0</version>
  <description>{robot}, built in mexone's model editor.</description>
  <maintainer email="student@example.com">student</maintainer>
  <license>BSD</license>
  <buildtool_depend>catkin</buildtool_depend>
  <exec_depend>robot_state_publisher</exec_depend>
  <exec_depend>controller_manager</exec_depend>
  <exec_depend>gazebo_ros</exec_depend>
</package>
"""

_CMAKE = """cmake_minimum_required(VERSION 3.0.2)
project({name})
find_package(catkin REQUIRED)
catkin_package()
install(DIRECTORY config launch meshes urdf DESTINATION ${{CATKIN_PACKAGE_SHARE_DESTINATION}})
"""

_DISPLAY = """<?xml version="1.0"?>
<!-- The robot's description and its TF tree: roslaunch {name} display.launch -->
<launch>
  <param name="robot_description" textfile="$(find {name})/urdf/{robot}.urdf"/>
  <node name="robot_state_publisher" pkg="robot_state_publisher" type="robot_state_publisher"/>
</launch>
"""

_CONTROL = """<?xml version="1.0"?>
<!-- The seed's control.launch for this robot: its controllers onto the parameter server, loaded
     and started by ros_control's spawner in whatever simulates it (Gazebo with
     gazebo_ros_control, or mexone sim with its ROS bridge): roslaunch {name} control.launch -->
<launch>
  <param name="robot_description" textfile="$(find {name})/urdf/{robot}.urdf"/>
  <rosparam file="$(find {name})/config/controllers.yaml" command="load"/>
  <node name="controller_spawner" pkg="controller_manager" type="spawner" respawn="false"
        output="screen" ns="{ns}" args="{controllers}"/>
  <node name="robot_state_publisher" pkg="robot_state_publisher" type="robot_state_publisher">
    <remap from="/joint_states" to="{ns}/joint_states"/>
  </node>
</launch>
"""

_GAZEBO = """<?xml version="1.0"?>
<!-- The seed's model.launch for this robot: Gazebo's empty world with the robot spawned, then
     control.launch (needs gazebo_ros): roslaunch {name} gazebo.launch -->
<launch>
  <include file="$(find gazebo_ros)/launch/empty_world.launch"/>
  <include file="$(find {name})/launch/control.launch"/>
  <node name="spawn_model" pkg="gazebo_ros" type="spawn_model" output="screen"
        args="-urdf -param robot_description -model {robot}"/>
</launch>
"""


def save_package(session: EditSession, folder: Path, force: bool = False) -> Path:
    """A catkin package named after the folder: package.xml, CMakeLists.txt, meshes/ (copies),
    urdf/ (meshes as package:// URIs), config/controllers.yaml, launch/. An existing folder
    is refused unless force (then only the files written here are replaced)."""
    folder = usable(Path(folder))
    name = folder.name
    if not name.replace("_", "").isalnum() or not name[0].isalpha() or name.lower() != name:
        raise InputError(f"'{name}' is not a ROS package name", file=folder,
                         hint="lower-case letters, digits and _, starting with a letter")
    if folder.exists() and not force:
        raise OutputExistsError("already exists; nothing was written", file=folder,
                                hint="pass --force (or tick Overwrite) to replace its files")
    if not folder.parent.is_dir():
        raise InputError("output folder does not exist", file=folder,
                         hint=f"create it first: mkdir -p {folder.parent}")
    model = _model(session)
    for sub in ("meshes", "urdf", "config", "launch"):
        (folder / sub).mkdir(parents=True, exist_ok=True)
    copied: dict[Path, str] = {}

    def packaged(geometry):
        if not isinstance(geometry, Mesh):
            return geometry
        source = resolve_mesh(geometry.filename, model.base_dir).resolve()
        if source not in copied:
            target, n = source.name, 2
            while target in copied.values():
                target, n = f"{source.stem}_{n}{source.suffix}", n + 1
            shutil.copyfile(source, folder / "meshes" / target)
            copied[source] = target
        return replace(geometry, filename=f"package://{name}/meshes/{copied[source]}")

    for link in model.links.values():
        link.visuals = [replace(v, geometry=packaged(v.geometry)) for v in link.visuals]
        link.collisions = [replace(c, geometry=packaged(c.geometry)) for c in link.collisions]
    robot = model.name
    ns = session.namespace
    controllers = " ".join(["joint_state_controller", *(controller_name(j) for j in session.extras.motors)])
    files = {
        "package.xml": _PACKAGE_XML.format(name=name, robot=robot),
        "CMakeLists.txt": _CMAKE.format(name=name),
        f"urdf/{robot}.urdf": write_urdf(model, comment=_COMMENT),
        "config/controllers.yaml": controllers_text(session),
        "launch/display.launch": _DISPLAY.format(name=name, robot=robot),
        "launch/control.launch": _CONTROL.format(name=name, robot=robot, ns=ns, controllers=controllers),
        "launch/gazebo.launch": _GAZEBO.format(name=name, robot=robot),
    }
    for rel, text in files.items():
        write_text(folder / rel, text, True)
    return folder
