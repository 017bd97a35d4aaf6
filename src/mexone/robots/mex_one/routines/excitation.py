"""Excite every joint for system identification (`mexone identify`): a multisine per joint.

    mexone record excitation _base:=fixed -o hung.mcap --fixed-base -z 0.3 --duration 20  # stand
    mexone record excitation -o stand.mcap --duration 20                       # standing
    mexone record excitation _amplitude:=0.2 _seed:=1 ...   # smaller, other phases

What it sends: from the pose the robot is in, 2 s of cosine ramp to a working pose, then around
it a multisine per joint -- six log-spaced frequencies from _fmin to _fmax Hz (each joint its own,
shifted a few percent so no two joints move alike), Schroeder phases for a low peak, scaled so
position stays inside the joint's limits (45% of the room on either side), speed under half the
velocity limit and acceleration under _max_accel rad/s^2, faded in over 1 s. Six frequencies
over a decade separate what identification needs apart: Coulomb friction pushes the same at
any speed, viscous damping in proportion to speed, armature in proportion to acceleration
(frequency squared), and the speed passes through every value from 0 to its peak.

_base:=fixed (the robot hangs on a stand): every joint at once. The best data: no contacts,
the legs swing freely, so every joint's damping, friction and armature show. The working pose
spreads the legs and lifts the arms off the body so no link touches another.
_base:=standing (default): safe on its feet. The arms, head and waist as above; the legs only in
a symmetric squat (hip pitch -s, knee 2s, ankle pitch -s: the feet stay flat and the hips over
the ankles), which loads the knees and hips with the upper body's weight -- what identifies
link masses. Hip yaw and roll and ankle roll stay at 0: exciting them one at a time would tip
a standing robot over, so identify them on a stand.

Joint names, limits and controllers come from /robot_description and the controller parameters
(as on a real ROS master), so with `import rospy` this file runs as a node on the real robot.
Mex-One's working pose is built in; _pose:=joint=rad,joint=rad overrides it for other robots.
"""

import math
import xml.etree.ElementTree as ET

import numpy as np

from mexone import rospy
from mexone.msgs import Float64, JointState

rospy.init_node("excitation")
base = rospy.get_param("~base", "standing")
amplitude = float(rospy.get_param("~amplitude", 0.3))
fmin, fmax = float(rospy.get_param("~fmin", 0.2)), float(rospy.get_param("~fmax", 2.0))
max_accel = float(rospy.get_param("~max_accel", 20.0))
rate_hz = float(rospy.get_param("~rate", 100.0))
seed = int(rospy.get_param("~seed", 0))
if base not in ("standing", "fixed"):
    raise SystemExit(f"_base:={base}: say fixed (on a stand) or standing")
if not 0 < fmin < fmax:
    raise SystemExit("_fmin and _fmax: 0 < fmin < fmax (Hz)")

# Mex-One's working poses (rad): arms off the body, elbows bent; on a stand also legs apart.
POSE = {"l_shoulder_roll": 0.5, "r_shoulder_roll": -0.5, "l_elbow": -0.6, "r_elbow": -0.6}
POSE_FIXED = {"l_hip_roll": 0.15, "r_hip_roll": -0.15, "l_hip_pitch": -0.3, "r_hip_pitch": -0.3,
              "l_knee": 0.5, "r_knee": 0.5}
SQUAT = [("l_hip_pitch", "l_knee", "l_ankle_pitch"), ("r_hip_pitch", "r_knee", "r_ankle_pitch")]
SQUAT_DEPTH = 0.35  # rad of hip pitch at the deepest point
LEG_WORDS = ("hip", "knee", "ankle", "foot", "leg")


def limits_from_urdf(text):
    """joint -> (lower, upper, velocity) for revolute and prismatic joints."""
    out = {}
    for joint in ET.fromstring(text).iter("joint"):
        limit = joint.find("limit")
        if joint.get("type") in ("revolute", "prismatic") and limit is not None:
            out[joint.get("name")] = (float(limit.get("lower", 0)), float(limit.get("upper", 0)),
                                      float(limit.get("velocity", 0)) or math.inf)
    return out


def position_controllers():
    """joint -> (namespace, controller) of every single-joint position controller."""
    out = {}
    for ns, entries in rospy.get_param("/", {}).items():
        if not isinstance(entries, dict):
            continue
        for name, spec in entries.items():
            if isinstance(spec, dict) and str(spec.get("type", "")).endswith(
                    "/JointPositionController") and "joint" in spec:
                out[spec["joint"]] = (ns, name)
    return out


limits = limits_from_urdf(rospy.get_param("/robot_description"))
controllers = {j: c for j, c in position_controllers().items() if j in limits}
if not controllers:
    raise SystemExit("no position controllers with joint limits to excite")
pose = dict(POSE)
if base == "fixed":
    pose.update(POSE_FIXED)
for item in filter(None, str(rospy.get_param("~pose", "")).split(",")):
    name, _, value = item.partition("=")
    pose[name.strip()] = float(value)

squat = [chain for chain in SQUAT if all(j in controllers for j in chain)] if base == "standing" \
    else []
in_squat = {j for chain in squat for j in chain}
if base == "fixed":
    free = list(controllers)
else:
    free = [j for j in controllers if j not in in_squat and not any(w in j for w in LEG_WORDS)]

# one period of every joint's multisine, sampled finely, to scale peaks, speeds and accelerations
rng = np.random.default_rng(seed)
grid = np.arange(0.0, 60.0, 0.005)
k = np.arange(6)
phases = -math.pi * k * (k + 1) / len(k)  # Schroeder


def multisine(index, t):
    freqs = np.geomspace(fmin, fmax, len(k)) * (1 + 0.1 * index / max(1, len(controllers)))
    shift = rng_phase[index]
    return sum(np.sin(2 * math.pi * f * t + p + shift) for f, p in zip(freqs, phases, strict=True))


rng_phase = rng.uniform(0, 2 * math.pi, len(controllers) + 1)
names = list(controllers)
plan = {}  # joint -> (centre, amplitude, signal index)
for index, joint in enumerate(names):
    lo, hi, vmax = limits[joint]
    centre = min(max(pose.get(joint, 0.0), lo + 0.1 * (hi - lo)), hi - 0.1 * (hi - lo))
    pose[joint] = centre
    if joint not in free:
        continue
    signal = multisine(index, grid)
    peak = np.max(np.abs(signal))
    speed = np.max(np.abs(np.gradient(signal, grid))) / peak
    accel = np.max(np.abs(np.gradient(np.gradient(signal, grid), grid))) / peak
    room = 0.45 * min(centre - lo, hi - centre)
    a = min(amplitude, room, 0.5 * vmax / speed, max_accel / accel)
    plan[joint] = (centre, a / peak, index)
squat_signal = multisine(len(controllers), grid)
squat_peak = np.max(np.abs(squat_signal))
squat_scale = SQUAT_DEPTH / 2 / squat_peak * min(
    1.0, max_accel / (np.max(np.abs(np.gradient(np.gradient(squat_signal, grid), grid)))
                      * SQUAT_DEPTH / squat_peak))
for hip, knee, ankle in squat:
    for joint, sign in ((hip, -1.0), (knee, 2.0), (ankle, -1.0)):
        pose[joint] = sign * SQUAT_DEPTH / 2

pubs = {j: rospy.Publisher(f"/{ns}/{name}/command", Float64, queue_size=10)
        for j, (ns, name) in controllers.items()}
start_pose = {}
try:
    state = rospy.wait_for_message(f"/{next(iter(controllers.values()))[0]}/joint_states",
                                   JointState, timeout=1.0)
    start_pose = dict(zip(state.name, state.position, strict=False))
except rospy.ROSException:
    pass
rospy.loginfo("exciting %d joints (%s base)%s", len(plan), base,
              f" and squatting {len(squat)} legs" if squat else "")

RAMP, HOLD, FADE = 2.0, 0.5, 1.0  # s: to the working pose, still there, excitation fading in
rate = rospy.Rate(rate_hz)
t0 = rospy.get_time()
while not rospy.is_shutdown():
    t = rospy.get_time() - t0
    blend = 0.5 - 0.5 * math.cos(math.pi * min(t / RAMP, 1.0))
    fade = min(max((t - RAMP - HOLD) / FADE, 0.0), 1.0)
    te = max(t - RAMP - HOLD, 0.0)
    s = squat_scale * float(multisine(len(controllers), np.array([te]))[0]) * fade
    for joint, pub in pubs.items():
        target = pose[joint]
        if joint in plan:
            centre, gain, index = plan[joint]
            target = centre + fade * gain * float(multisine(index, np.array([te]))[0])
        for hip, knee, ankle in squat:
            target += {hip: -s, knee: 2 * s, ankle: -s}.get(joint, 0.0)
        begin = start_pose.get(joint, 0.0)
        pub.publish(Float64(begin + blend * (target - begin)))
    rate.sleep()
