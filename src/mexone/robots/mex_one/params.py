"""Mex-One in one table: every dimension, mass, limit and gain the generator turns into files.

Published (DESIGN.md section 2): height 1.05 m, mass about 15 kg, a Kinect on the head.
Assumed (no CAD or joint list is public): the 21-DOF layout below, segment lengths in
proportion to a child-sized humanoid, masses by segment, servo-class torque limits.
Edit a number here and run ``python -m mexone.robots.mex_one.generate``; a test fails if the
committed files drift from this table.

Frames: x forward, y left, z up; the robot stands with its soles at z = 0 and every joint
at 0 is the home pose (arms hanging, legs straight). Left parts are given; right parts are
their mirror images in y (same axes, roll and yaw limits mirrored).
"""

from __future__ import annotations

from dataclasses import dataclass

ROBOT_NAME = "mex_rb"  # the seed's robot and ROS namespace name
PACKAGE = "mex_rb"  # package:// name of the mesh folder, as in the seed's Listing 3.5
HEIGHT = 1.05  # m, sole to top of the Kinect
PELVIS_HEIGHT = 0.60  # m, pelvis frame above the soles at home


Vec = tuple[float, float, float]  # x y z, m


@dataclass(frozen=True)
class Shape:
    """A primitive in its link's frame: kind 'box' (size = x y z) or 'cylinder' (radius, length,
    axis z). Visual meshes and collision primitives are both made from it."""

    kind: str
    size: tuple[float, ...]
    center: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Part:
    """A link's physics: its mass and the primitives that collide (and give its inertia)."""

    name: str
    mass: float  # kg, spread uniformly over the shapes' volume
    shapes: tuple[Shape, ...]
    mu: float = 0.9  # Coulomb friction with other surfaces (mu1 = mu2)


@dataclass(frozen=True)
class Hinge:
    name: str
    parent: str
    child: str
    xyz: tuple[float, float, float]  # joint origin in the parent's frame
    axis: tuple[float, float, float]
    lower: float  # rad
    upper: float
    effort: float  # N m, peak motor torque after the gearbox
    velocity: float  # rad/s
    damping: float  # N m s/rad, gearbox viscous loss
    friction: float  # N m, gearbox static friction
    p: float  # PID gains of its position controller (N m/rad, N m/(rad s), N m s/rad)
    i: float
    d: float


def _box(x: float, y: float, z: float, center: Vec = (0.0, 0.0, 0.0)) -> Shape:
    return Shape("box", (x, y, z), center)


def _cyl(r: float, length: float, center: Vec = (0.0, 0.0, 0.0)) -> Shape:
    return Shape("cylinder", (r, length), center)


# Total: 15.0 kg. Left limbs only; the right side is mirrored by `parts()`.
_CENTRE_PARTS = (
    Part("pelvis", 2.0, (_box(0.12, 0.18, 0.08),)),
    # electronics and battery sit a little forward: the COM is 1 cm ahead of the hips
    Part("torso", 3.6, (_box(0.12, 0.20, 0.24, (0.01, 0.0, 0.13)),)),
    Part("neck", 0.15, (_cyl(0.025, 0.04, (0.0, 0.0, 0.02)),)),
    # head with the Kinect on top, as on the real robot
    Part("head", 0.95, (_box(0.10, 0.12, 0.065, (0.0, 0.0, 0.0375)),
                        _box(0.065, 0.28, 0.04, (0.0, 0.0, 0.09)))),
)
_LEFT_PARTS = (
    Part("l_hip_rotor", 0.25, (_cyl(0.03, 0.03, (0.0, 0.0, -0.015)),)),
    Part("l_hip_bracket", 0.35, (_box(0.05, 0.05, 0.04),)),
    Part("l_thigh", 1.0, (_cyl(0.04, 0.17, (0.0, 0.0, -0.115)),)),
    Part("l_shank", 0.8, (_cyl(0.035, 0.17, (0.0, 0.0, -0.115)),)),
    Part("l_ankle", 0.2, (_box(0.04, 0.04, 0.03),)),
    Part("l_foot", 0.45, (_box(0.16, 0.08, 0.03, (0.02, 0.0, -0.045)),), mu=1.0),
    Part("l_shoulder", 0.2, (_box(0.05, 0.04, 0.05),)),
    Part("l_upper_arm", 0.5, (_cyl(0.03, 0.13, (0.0, 0.0, -0.095)),)),
    Part("l_forearm", 0.4, (_cyl(0.025, 0.15, (0.0, 0.0, -0.095)),)),
)

X, Y, Z = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)
_LEG = dict(velocity=5.0, damping=0.5, friction=0.05)
_ARM = dict(velocity=5.0, damping=0.2, friction=0.02)
_HEAD = dict(velocity=5.0, damping=0.1, friction=0.01)

_CENTRE_JOINTS = (
    Hinge("waist_yaw", "pelvis", "torso", (0.0, 0.0, 0.04), Z, -1.0, 1.0, 15.0, p=150.0, i=0.0,
          d=1.5, **_LEG),
    Hinge("neck_yaw", "torso", "neck", (0.0, 0.0, 0.26), Z, -1.2, 1.2, 3.0, p=15.0, i=0.0, d=0.2,
          **_HEAD),
    Hinge("neck_pitch", "neck", "head", (0.0, 0.0, 0.04), Y, -0.5, 0.8, 3.0, p=15.0, i=0.0, d=0.2,
          **_HEAD),
)
# Left side; limits are for the left, mirrored for the right where the axis is x or z.
_LEFT_JOINTS = (
    Hinge("l_hip_yaw", "pelvis", "l_hip_rotor", (0.0, 0.06, -0.03), Z, -0.8, 0.8, 10.0, p=100.0,
          i=0.0, d=1.0, **_LEG),
    Hinge("l_hip_roll", "l_hip_rotor", "l_hip_bracket", (0.0, 0.0, -0.05), X, -0.4, 0.6, 20.0,
          p=300.0, i=0.0, d=3.0, **_LEG),
    Hinge("l_hip_pitch", "l_hip_bracket", "l_thigh", (0.0, 0.0, 0.0), Y, -1.8, 0.6, 25.0,
          p=300.0, i=0.0, d=3.0, **_LEG),
    Hinge("l_knee", "l_thigh", "l_shank", (0.0, 0.0, -0.23), Y, -0.1, 2.2, 25.0, p=300.0, i=0.0,
          d=3.0, **_LEG),
    Hinge("l_ankle_pitch", "l_shank", "l_ankle", (0.0, 0.0, -0.23), Y, -0.9, 0.9, 20.0, p=300.0,
          i=0.0, d=3.0, **_LEG),
    Hinge("l_ankle_roll", "l_ankle", "l_foot", (0.0, 0.0, 0.0), X, -0.5, 0.5, 15.0, p=300.0,
          i=0.0, d=3.0, **_LEG),
    Hinge("l_shoulder_pitch", "torso", "l_shoulder", (0.0, 0.14, 0.22), Y, -3.0, 3.0, 8.0,
          p=100.0, i=0.0, d=1.5, **_ARM),
    Hinge("l_shoulder_roll", "l_shoulder", "l_upper_arm", (0.0, 0.0, 0.0), X, -0.5, 2.5, 8.0,
          p=100.0, i=0.0, d=1.5, **_ARM),
    Hinge("l_elbow", "l_upper_arm", "l_forearm", (0.0, 0.0, -0.17), Y, -2.5, 0.1, 6.0, p=60.0,
          i=0.0, d=0.8, **_ARM),
)


def _mirror_name(name: str) -> str:
    return "r_" + name[2:] if name.startswith("l_") else name


def _mirror_shape(shape: Shape) -> Shape:
    x, y, z = shape.center
    return Shape(shape.kind, shape.size, (x, -y, z))


def parts() -> list[Part]:
    """Every link, in the order written to the URDF."""
    right = [Part(_mirror_name(p.name), p.mass, tuple(_mirror_shape(s) for s in p.shapes), p.mu)
             for p in _LEFT_PARTS]
    return [*_CENTRE_PARTS, *_LEFT_PARTS, *right]


def hinges() -> list[Hinge]:
    """Every joint, in the order written to the URDF."""
    right = []
    for h in _LEFT_JOINTS:
        lower, upper = (-h.upper, -h.lower) if h.axis != Y else (h.lower, h.upper)
        x, y, z = h.xyz
        right.append(Hinge(_mirror_name(h.name), _mirror_name(h.parent), _mirror_name(h.child),
                           (x, -y, z), h.axis, lower, upper, h.effort, h.velocity, h.damping,
                           h.friction, h.p, h.i, h.d))
    return [*_CENTRE_JOINTS, *_LEFT_JOINTS, *right]


# ----- Looks: the visual shells (issue 28). Drawing only: physics uses the Parts above. -------
# Three named URDF materials; every renderer (the page, videos, the MJCF and SDF exports) shows
# them. No <gazebo><material> is written: it would paint a link's servo and shell one colour.
MATERIALS = {
    "shell_white": (0.92, 0.92, 0.90, 1.0),  # painted covers
    "servo_dark": (0.26, 0.27, 0.30, 1.0),  # servo housings, horns, brackets, hands, soles
    "kinect_black": (0.04, 0.04, 0.05, 1.0),  # the Kinect's body
}
# Facets: round enough at a metre, ~20k triangles for the robot (the page keeps its shadow
# under gui.scene.SHADOW_TRIANGLES).
LIMB_SEGMENTS = (20, 12)  # around, pole to pole, of a limb's end spheres
CORNER_SEGMENTS = (8, 6)  # of a rounded box's corner spheres
HORN_SECTIONS = 20  # around a servo horn


@dataclass(frozen=True)
class Piece:
    """One visual solid in its link's frame, in metres.

    kind 'rbox': size = (x, y, z, corner radius); 'limb': size = (top radius, bottom radius,
    top z, bottom z, y/x squash), a rounded taper along z through `center`'s x and y;
    'horn': size = (radius, length), a cylinder along `axis` ('x', 'y' or 'z')."""

    kind: str
    size: tuple[float, ...]
    center: tuple[float, float, float] = (0.0, 0.0, 0.0)
    material: str = "shell_white"
    axis: str = "z"


def _rbox(x: float, y: float, z: float, r: float, center: Vec = (0.0, 0.0, 0.0),
          material: str = "shell_white") -> Piece:
    return Piece("rbox", (x, y, z, r), center, material)


def _limb(r_top: float, r_bottom: float, z_top: float, z_bottom: float, squash: float = 0.85,
          center: Vec = (0.0, 0.0, 0.0)) -> Piece:
    return Piece("limb", (r_top, r_bottom, z_top, z_bottom, squash), center)


def _horn(r: float, length: float, axis: str, center: Vec = (0.0, 0.0, 0.0),
          material: str = "servo_dark") -> Piece:
    return Piece("horn", (r, length), center, material, axis)


def _servo(x: float, y: float, z: float, center: Vec = (0.0, 0.0, 0.0)) -> Piece:
    return _rbox(x, y, z, 0.006, center, "servo_dark")


# Centre and left links; the right side is mirrored by `looks()`. Each link's pieces are drawn
# as one <visual> per material (meshes/<link>.stl for the first material, <link>_<material>.stl).
_LOOKS: dict[str, tuple[Piece, ...]] = {
    "pelvis": (
        _rbox(0.12, 0.18, 0.08, 0.025),
        _horn(0.045, 0.012, "z", (0.0, 0.0, 0.042)),  # waist yaw bearing
        _servo(0.05, 0.04, 0.02, (0.0, 0.06, -0.03)),  # hip yaw servos' feet
        _servo(0.05, 0.04, 0.02, (0.0, -0.06, -0.03)),
    ),
    "torso": (
        # chest wider than the waist, like a child's torso
        _rbox(0.10, 0.16, 0.11, 0.02, (0.005, 0.0, 0.065)),
        _rbox(0.12, 0.20, 0.14, 0.03, (0.01, 0.0, 0.175)),
        _rbox(0.006, 0.09, 0.07, 0.003, (0.07, 0.0, 0.16), "servo_dark"),  # chest vent
        _rbox(0.03, 0.13, 0.13, 0.01, (-0.052, 0.0, 0.15), "servo_dark"),  # battery pack
        _horn(0.022, 0.24, "y", (0.0, 0.0, 0.22)),  # shoulder servos' shafts
        _horn(0.02, 0.03, "z", (0.0, 0.0, 0.25)),  # neck yaw bearing
    ),
    "neck": (_horn(0.022, 0.04, "z", (0.0, 0.0, 0.02)),
             _horn(0.012, 0.07, "y", (0.0, 0.0, 0.04))),
    "head": (
        _rbox(0.10, 0.12, 0.065, 0.025, (0.0, 0.0, 0.0375)),
        _rbox(0.012, 0.09, 0.03, 0.006, (0.045, 0.0, 0.04), "servo_dark"),  # visor
        _horn(0.018, 0.128, "y", (0.0, 0.0, 0.035)),  # ears: the neck pitch servo
        # the Kinect: a black bar on a stub, three windows on its front face
        _rbox(0.03, 0.05, 0.012, 0.004, (-0.005, 0.0, 0.074), "kinect_black"),
        _rbox(0.062, 0.28, 0.034, 0.012, (-0.001, 0.0, 0.093), "kinect_black"),
        _horn(0.0075, 0.004, "x", (0.0305, 0.026, 0.093)),  # IR projector
        _horn(0.0065, 0.004, "x", (0.0305, 0.0, 0.093)),  # RGB camera
        _horn(0.0075, 0.004, "x", (0.0305, -0.026, 0.093)),  # IR camera
    ),
    "l_hip_rotor": (_horn(0.028, 0.03, "z", (0.0, 0.0, -0.015)),
                    _servo(0.045, 0.03, 0.02, (0.0, 0.0, -0.04))),
    "l_hip_bracket": (_servo(0.05, 0.05, 0.04),
                      _horn(0.016, 0.056, "x"), _horn(0.02, 0.064, "y")),
    "l_thigh": (
        _limb(0.042, 0.034, -0.055, -0.18),
        _servo(0.05, 0.058, 0.05, (0.0, 0.0, -0.213)),  # knee servo
        _horn(0.02, 0.074, "y", (0.0, 0.0, -0.23)),
    ),
    "l_shank": (
        _limb(0.036, 0.028, -0.06, -0.185),
        _servo(0.045, 0.054, 0.045, (0.0, 0.0, -0.207)),  # ankle pitch servo
        _horn(0.018, 0.066, "y", (0.0, 0.0, -0.23)),
    ),
    "l_ankle": (_servo(0.04, 0.04, 0.03), _horn(0.013, 0.05, "x")),
    "l_foot": (
        _rbox(0.16, 0.08, 0.022, 0.009, (0.02, 0.0, -0.041)),
        _rbox(0.16, 0.08, 0.01, 0.004, (0.02, 0.0, -0.055), "servo_dark"),  # sole
    ),
    "l_shoulder": (_rbox(0.056, 0.046, 0.056, 0.02, (0.0, 0.006, 0.004)),  # shoulder cap
                   _horn(0.017, 0.064, "x")),
    "l_upper_arm": (
        _limb(0.03, 0.026, -0.045, -0.14, 0.9),
        _servo(0.04, 0.05, 0.045, (0.0, 0.0, -0.163)),  # elbow servo
        _horn(0.017, 0.062, "y", (0.0, 0.0, -0.17)),
    ),
    "l_forearm": (
        _limb(0.025, 0.021, -0.035, -0.145, 0.9),
        _servo(0.032, 0.03, 0.02, (0.0, 0.0, -0.16)),  # wrist
        _rbox(0.04, 0.02, 0.045, 0.008, (0.0, 0.0, -0.19), "servo_dark"),  # hand
        _rbox(0.012, 0.012, 0.028, 0.005, (0.022, 0.0, -0.178), "servo_dark"),  # thumb
    ),
}


def looks() -> dict[str, tuple[Piece, ...]]:
    """Every link's visual pieces; right links are the left ones mirrored in y."""
    out = {name: pieces for name, pieces in _LOOKS.items()}
    for name, pieces in _LOOKS.items():
        if name.startswith("l_"):
            out[_mirror_name(name)] = tuple(
                Piece(p.kind, p.size, (p.center[0], -p.center[1], p.center[2]), p.material, p.axis)
                for p in pieces)
    return out


# Contact: Gazebo's ODE contact stiffness kp (N/m) and damping kd (N s/m) for every link
CONTACT_KP = 1.0e6
CONTACT_KD = 100.0
JOINT_STATE_RATE = 50.0  # Hz, as the seed's Listing 3.17

# Sensors, declared in the URDF the Gazebo way (see generate.py). Noise values are assumed: a
# consumer-grade MEMS IMU; Gazebo tutorials' orders of magnitude.
IMU_LINK = "pelvis"
IMU_RATE = 100.0  # Hz
IMU_GYRO_STDDEV = 2.0e-4  # rad/s
IMU_ACCEL_STDDEV = 1.0e-2  # m/s^2
FT_JOINTS = ("l_ankle_roll", "r_ankle_roll")  # six-axis sensors between ankle and foot
FT_RATE = 100.0
CONTACT_LINKS = ("l_foot", "r_foot")  # the soles
CONTACT_RATE = 50.0
# Kinect v1 (published: 640 x 480 RGB and depth at 30 Hz, 57 x 43 degree field of view, depth
# 0.5-4.5 m), in front of the bar on top of the head
KINECT_XYZ = (0.034, 0.0, 0.09)  # in the head's frame: just ahead of the bar's front face
KINECT_WIDTH, KINECT_HEIGHT = 640, 480
KINECT_HFOV_DEG = 57.0
KINECT_RANGE = (0.5, 4.5)  # m
KINECT_RATE = 30.0
