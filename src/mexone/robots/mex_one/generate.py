"""Write Mex-One's URDF, STL meshes and controller YAML from the parameter table.

    python -m mexone.robots.mex_one.generate [OUT_DIR]

With no OUT_DIR it rewrites the package data beside this file (the committed files).
Inertias come from the shapes and masses (uniform density), so they cannot disagree with the
geometry; meshes are written in millimetres, like a CAD export, and loaded with scale 0.001.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np
import yaml

from mexone.description.model import (
    Box,
    Collision,
    Cylinder,
    Dynamics,
    GazeboLink,
    Geometry,
    Inertial,
    Joint,
    Limit,
    Link,
    Mesh,
    Pose,
    RobotModel,
    Transmission,
    Visual,
)
from mexone.description.sensors import CameraSpec, Noise, SensorSpec
from mexone.description.urdf import write_urdf
from mexone.robots.mex_one import params

if TYPE_CHECKING:
    import trimesh

__all__ = ["build_model", "controllers_yaml", "visual_meshes", "mesh_file", "generate", "HERE"]

HERE = Path(__file__).resolve().parent
MM = 1000.0


def _volume(shape: params.Shape) -> float:
    if shape.kind == "box":
        return float(np.prod(shape.size))
    radius, length = shape.size
    return float(np.pi * radius**2 * length)


def _own_inertia(shape: params.Shape, mass: float) -> np.ndarray:
    """Inertia tensor of a uniform solid about its own centre."""
    if shape.kind == "box":
        x, y, z = shape.size
        return mass / 12 * np.diag([y * y + z * z, x * x + z * z, x * x + y * y])
    r, h = shape.size
    side = mass / 12 * (3 * r * r + h * h)
    return np.diag([side, side, mass * r * r / 2])


def inertial_for(part: params.Part) -> Inertial:
    """Mass spread by volume over the part's shapes; parallel-axis sum about the joint COM."""
    volumes = np.array([_volume(s) for s in part.shapes])
    masses = part.mass * volumes / volumes.sum()
    centres = np.array([s.center for s in part.shapes])
    com = masses @ centres / part.mass
    tensor = np.zeros((3, 3))
    for shape, m, c in zip(part.shapes, masses, centres, strict=True):
        d = c - com
        tensor += _own_inertia(shape, m) + m * (d @ d * np.eye(3) - np.outer(d, d))
    ixx, ixy, ixz, iyy, iyz, izz = (tensor[0, 0], tensor[0, 1], tensor[0, 2], tensor[1, 1],
                                    tensor[1, 2], tensor[2, 2])
    rounded = tuple(float(f"{v:.6g}") for v in (ixx, ixy, ixz, iyy, iyz, izz))
    return Inertial(part.mass, rounded, Pose(tuple(float(f"{v:.6g}") for v in com)))


def _primitive(shape: params.Shape) -> Geometry:
    return Box(shape.size) if shape.kind == "box" else Cylinder(*shape.size)


def _piece(piece: params.Piece) -> trimesh.Trimesh:
    """One visual solid in millimetres (convex hulls of spheres: rounded, closed, low-poly)."""
    import trimesh

    size = np.asarray(piece.size, dtype=float) * MM
    centre = np.asarray(piece.center) * MM
    if piece.kind == "rbox":
        *extent, r = size
        ball = trimesh.creation.uv_sphere(radius=r, count=list(params.CORNER_SEGMENTS)).vertices
        half = np.maximum(np.asarray(extent) / 2 - r, 0.0)
        corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * half
        mesh = trimesh.convex.convex_hull(np.vstack([ball + c for c in corners]))
    elif piece.kind == "limb":
        r_top, r_bottom, z_top, z_bottom, squash = piece.size
        points = []
        for r, z in ((r_top, z_top), (r_bottom, z_bottom)):
            sphere = trimesh.creation.uv_sphere(radius=r * MM, count=list(params.LIMB_SEGMENTS))
            points.append(sphere.vertices * (1.0, squash, 1.0) + (0.0, 0.0, z * MM))
        mesh = trimesh.convex.convex_hull(np.vstack(points))
        centre = centre * (1.0, 1.0, 0.0)  # the limb's heights are its own
    elif piece.kind == "horn":
        radius, length = size
        mesh = trimesh.creation.cylinder(radius=radius, height=length,
                                         sections=params.HORN_SECTIONS)
        rotation = trimesh.transformations.rotation_matrix  # untyped
        turn = {"x": rotation(np.pi / 2, (0, 1, 0)),  # type: ignore[no-untyped-call]
                "y": rotation(np.pi / 2, (1, 0, 0)),  # type: ignore[no-untyped-call]
                "z": np.eye(4)}[piece.axis]
        mesh.apply_transform(turn)
    else:
        raise ValueError(f"unknown piece kind {piece.kind!r}")
    mesh.apply_translation(centre)
    return mesh


def visual_meshes(link: str) -> dict[str, trimesh.Trimesh]:
    """The link's visual meshes in millimetres, in the link frame (as a CAD export would be),
    one per material in the order the link's pieces name them."""
    import trimesh

    by_material: dict[str, list[trimesh.Trimesh]] = {}
    for piece in params.looks()[link]:
        by_material.setdefault(piece.material, []).append(_piece(piece))
    return {material: cast("trimesh.Trimesh", trimesh.util.concatenate(pieces))
            for material, pieces in by_material.items()}


def mesh_file(link: str, material: str, first: bool) -> str:
    """meshes/<link>.stl for a link's first material (its main shell), <link>_<material>.stl
    for the others."""
    return f"{link}.stl" if first else f"{link}_{material}.stl"


def _visuals(link: str) -> list[Visual]:
    visuals = []
    for i, material in enumerate(visual_meshes(link)):
        name = mesh_file(link, material, i == 0)
        mesh = Mesh(f"package://{params.PACKAGE}/meshes/{name}", (0.001, 0.001, 0.001))
        visuals.append(Visual(mesh, name=f"{name[:-4]}_visual", material=material,
                              rgba=params.MATERIALS[material]))
    return visuals


def build_model() -> RobotModel:
    model = RobotModel(name=params.ROBOT_NAME, links={}, joints={},
                       ros_namespace=f"/{params.ROBOT_NAME}")
    for part in params.parts():
        model.links[part.name] = Link(
            part.name,
            inertial_for(part),
            _visuals(part.name),
            [Collision(_primitive(s), Pose(s.center), f"{part.name}_collision_{i}")
             for i, s in enumerate(part.shapes)],
        )
        model.gazebo_links[part.name] = GazeboLink(
            self_collide=True, mu1=part.mu, mu2=part.mu, kp=params.CONTACT_KP,
            kd=params.CONTACT_KD)
    for h in params.hinges():
        dynamics = Dynamics(h.damping, h.friction)
        model.joints[h.name] = Joint(h.name, "revolute", h.parent, h.child, Pose(h.xyz), h.axis,
                                     Limit(h.lower, h.upper, h.effort, h.velocity), dynamics)
        model.gazebo_joints[h.name] = dynamics  # the seed's Listing 3.11, from the same numbers
        model.transmissions.append(Transmission(
            f"{h.name}_transmission", h.name,
            hardware_interface="hardware_interface/EffortJointInterface",
            actuator=f"{h.name}_motor", mechanical_reduction=1.0))
    _add_sensors(model)
    return model


def _add_sensors(model: RobotModel) -> None:
    """IMU in the pelvis, force-torque at both ankles, contact on both soles, the Kinect on the
    head with its link and optical frames (so robot_state_publisher draws them in TF)."""
    ns = f"/{params.ROBOT_NAME}"
    model.links["kinect_link"] = Link("kinect_link")
    model.joints["kinect_joint"] = Joint("kinect_joint", "fixed", "head", "kinect_link",
                                         Pose(params.KINECT_XYZ))
    for frame in ("kinect_rgb_optical_frame", "kinect_depth_optical_frame"):
        model.links[frame] = Link(frame)  # REP-103 optical: z forward, x right, y down
        model.joints[f"{frame}_joint"] = Joint(f"{frame}_joint", "fixed", "kinect_link", frame,
                                               Pose(rpy=(-math.pi / 2, 0.0, -math.pi / 2)))
    gyro = Noise("gaussian", stddev=params.IMU_GYRO_STDDEV)
    accel = Noise("gaussian", stddev=params.IMU_ACCEL_STDDEV)
    model.sensors.append(SensorSpec(
        "imu", "imu", link=params.IMU_LINK, update_rate=params.IMU_RATE,
        plugin="libgazebo_ros_imu_sensor.so", namespace=ns, topic="imu", frame=params.IMU_LINK,
        noise={f"{g}/{a}": (gyro if g == "angular_velocity" else accel)
               for g in ("angular_velocity", "linear_acceleration") for a in "xyz"}))
    for joint in params.FT_JOINTS:
        name = joint.replace("_roll", "_ft")
        model.sensors.append(SensorSpec(
            name, "force_torque", joint=joint, update_rate=params.FT_RATE,
            plugin="libgazebo_ros_ft_sensor.so", namespace=ns, topic=name,
            ft_frame="child", measure_direction="child_to_parent"))
    for link in params.CONTACT_LINKS:
        model.sensors.append(SensorSpec(
            f"{link}_contact", "contact", link=link, update_rate=params.CONTACT_RATE,
            plugin="libgazebo_ros_bumper.so", namespace=ns, topic=f"{link}_contact",
            frame="world", collisions=(f"{link}_collision_0",)))
    low, high = params.KINECT_RANGE
    model.sensors.append(SensorSpec(
        "kinect", "depth", link="kinect_link", update_rate=params.KINECT_RATE,
        plugin="libgazebo_ros_openni_kinect.so", namespace=ns,
        topics={"image": "kinect/rgb/image_raw", "camera_info": "kinect/rgb/camera_info",
                "depth": "kinect/depth/image_raw", "depth_camera_info": "kinect/depth/camera_info",
                "points": "kinect/depth/points"},
        frame="kinect_depth_optical_frame", range=(low, high),
        camera=CameraSpec(params.KINECT_WIDTH, params.KINECT_HEIGHT,
                          math.radians(params.KINECT_HFOV_DEG), 0.05, 8.0)))


def controllers_yaml() -> str:
    controllers: dict[str, Any] = {
        "joint_state_controller": {"type": "joint_state_controller/JointStateController",
                                   "publish_rate": params.JOINT_STATE_RATE},
    }
    for h in params.hinges():
        controllers[f"{h.name}_position_controller"] = {
            "type": "effort_controllers/JointPositionController",
            "joint": h.name,
            "pid": {"p": h.p, "i": h.i, "d": h.d, "i_clamp_min": 0.0, "i_clamp_max": 0.0},
        }
    header = ("# Mex-One controllers in the ros_control schema of the seed's Listing 3.17.\n"
              "# Generated by `python -m mexone.robots.mex_one.generate` from params.py.\n"
              "# Effort-interface position controllers: the PID output is the joint torque, which\n"
              "# is what the seed's position_controllers/JointPositionController meant to do.\n")
    return header + yaml.safe_dump({params.ROBOT_NAME: controllers}, sort_keys=False)


URDF_COMMENT = (" Mex-One (Cinvestav Guadalajara), reconstructed at its published scale: 1.05 m, "
                "15 kg, 21 DOF. Generated from mexone/robots/mex_one/params.py; do not edit by "
                "hand. ")


def generate(out: Path = HERE) -> list[Path]:
    """Write every generated file below `out`; returns the paths written."""
    written = []
    for sub in ("urdf", "meshes", "config"):
        (out / sub).mkdir(parents=True, exist_ok=True)
    urdf = out / "urdf" / f"{params.ROBOT_NAME}.urdf"
    urdf.write_text(write_urdf(build_model(), URDF_COMMENT))
    written.append(urdf)
    for part in params.parts():
        for i, (material, mesh) in enumerate(visual_meshes(part.name).items()):
            path = out / "meshes" / mesh_file(part.name, material, i == 0)
            mesh.export(path, file_type="stl")
            written.append(path)
    yaml_path = out / "config" / "controllers.yaml"
    yaml_path.write_text(controllers_yaml())
    written.append(yaml_path)
    return written


if __name__ == "__main__":
    target = Path(sys.argv[1]) if len(sys.argv) > 1 else HERE
    for path in generate(target):
        print(path)
