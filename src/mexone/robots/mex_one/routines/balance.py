"""Standing balance: keep Mex-One on its feet when pushed, from its centre of mass (COM) and
pelvis IMU, with the ankles and, when they cannot do it, one step.

    mexone run balance                      # stand and balance (push it from a routine or GUI)
    mexone run balance _ankle:=1.5 _step_at:=0.08

The law is the capture point of the linear inverted pendulum (Pratt 2006, Englsberger 2011): a
COM at height z moving at v comes to rest over the point  cp = com + v / omega,
omega = sqrt(g / z).  While cp stays within the feet, the ankles alone can stop the robot:
each ankle is commanded against the capture point's error (leaning the legs back pushes the
centre of pressure ahead of the COM, which slows it) -- the ankle strategy. Once cp leaves
`step_at` of where the COM stood, no ankle torque can bring it back: the foot on the side of
the fall swings out and lands on the capture point as it is during the swing (a little
`beyond` it), and the robot balances, by its ankles again, over the wider stance -- the
stepping strategy. `hip` adds Horak and Nashner's hip strategy (bend into the fall), default
off: it did not help this robot.

COM and its height come from /<ns>/com (the sensors' balance topic, 50 Hz); its velocity by
differencing, lightly filtered (`filter`). The swing leg is straight (0.5 m), so a foot
placement is two angles in the world; the pelvis IMU's tilt turns them into hip angles, and
the ankle keeps the sole flat. Measured by benchmarks/push_recovery.py (benchmarks/RESULTS.md).
"""

import math

from mexone import rospy
from mexone.msgs import Float64, Imu, PointStamped

rospy.init_node("balance")
ns = rospy.get_param("~namespace", "mex_rb")
k_ankle = rospy.get_param("~ankle", 1.0)        # rad of ankle per m of capture-point error
k_hip = rospy.get_param("~hip", 0.0)            # rad of hip per m of capture-point error
lateral = rospy.get_param("~lateral", 1.0)      # share of the gains used sideways (roll)
limit = rospy.get_param("~limit", 0.4)          # rad: the most feedback bends a joint
smooth = rospy.get_param("~filter", 0.5)        # weight of the newest COM velocity sample
step_at = rospy.get_param("~step_at", 0.06)     # m of capture-point error that triggers a step
step_gain = rospy.get_param("~step_gain", 1.0)  # the foot lands this x (cp - com) from the COM
beyond = rospy.get_param("~beyond", 0.03)       # m: ...and this much further along the fall
beyond_y = rospy.get_param("~beyond_y", 0.06)   # m: ...and this much further out sideways
lift = rospy.get_param("~lift", 0.7)            # rad of knee flexion while the foot swings
swing = rospy.get_param("~swing", 0.09)         # s to lift the foot, and as long to put it down
LEG = 0.5  # m, hip to sole, leg straight
HIP = 0.06  # m, each hip out from the middle
REACH = 0.5  # rad from the vertical, the widest a leg swings: the ankle roll stops there
G = 9.81
com = {"now": None, "home": None, "velocity": (0.0, 0.0), "stamp": 0.0}
pelvis = {"pitch": 0.0, "roll": 0.0}
step = {}


def on_com(msg):
    p, stamp = msg.point, msg.header.stamp.to_sec()
    if com["now"] is None:
        com["home"] = (p.x, p.y)  # standing: balance about here
    elif stamp > com["stamp"]:
        dt = stamp - com["stamp"]
        com["velocity"] = tuple(smooth * (new - old) / dt + (1 - smooth) * v for new, old, v in
                                zip((p.x, p.y), com["now"][:2], com["velocity"], strict=True))
    com["now"], com["stamp"] = (p.x, p.y, p.z), stamp


def on_imu(msg):  # the pelvis tilt: positive pitch leans it forward, positive roll right
    q = msg.orientation
    pelvis["pitch"] = math.asin(max(-1.0, min(1.0, 2 * (q.w * q.y - q.z * q.x))))
    pelvis["roll"] = math.atan2(2 * (q.w * q.x + q.y * q.z), 1 - 2 * (q.x * q.x + q.y * q.y))


def command(joint):
    return rospy.Publisher(f"/{ns}/{joint}_position_controller/command", Float64, queue_size=1)


def clamp(x):
    return max(-limit, min(limit, x))


def leg_angle(d):
    """The angle from the vertical of a straight leg whose foot is d m out from its hip."""
    return max(-REACH, min(REACH, math.asin(max(-1.0, min(1.0, d / LEG)))))


def legs_now(ex, ey, omega):
    """Each leg's hip pitch, hip roll and knee (and the ankles, while a foot swings)."""
    straight = [dict(pitch=0.0, roll=0.0, knee=0.0) for _ in "lr"]
    if not step and math.hypot(ex, ey) > step_at:
        step.update(side=0 if ey >= 0 else 1, start=rospy.get_time())  # left foot for a fall left
    if not step:
        return straight
    side, t = step["side"], rospy.get_time() - step["start"]
    if t < 2 * swing:  # foot up, out over the capture point as it is now, down
        vx, vy = com["velocity"]
        hip_y = HIP if side == 0 else -HIP
        dx = step_gain * vx / omega + beyond * vx / (math.hypot(vx, vy) or 1.0)
        dy = step_gain * vy / omega + math.copysign(beyond_y, hip_y) - hip_y
        if (side == 0) == (dy < 0):
            dy = 0.0  # a foot never steps across the other
        # the leg's angles in the world (positive pitch puts the foot behind, roll to the left)
        step["pitch"], step["roll"] = -leg_angle(dx), leg_angle(dy)
        step["foot"] = (com["now"][0] + dx, com["now"][1] + hip_y + dy)
        knee = lift if t < swing else 0.0
        straight[side] = dict(pitch=step["pitch"] - pelvis["pitch"] - knee / 2,
                              roll=step["roll"] - pelvis["roll"], knee=knee,
                              ankle_pitch=-step["pitch"] - knee / 2, ankle_roll=-step["roll"])
        return straight
    if "landed" not in step:  # from now on balance about the middle of the two feet
        step["landed"] = True
        stance = (com["home"][0], com["home"][1] + (-HIP if side == 0 else HIP))
        com["home"] = tuple((a + b) / 2 for a, b in zip(stance, step["foot"], strict=True))
    # both feet down: the split shared by the two legs, the pelvis level between them
    straight[side] = dict(pitch=step["pitch"] / 2, roll=step["roll"] / 2, knee=0.0)
    straight[1 - side] = dict(pitch=-step["pitch"] / 2, roll=-step["roll"] / 2, knee=0.0)
    return straight


rospy.Subscriber(f"/{ns}/com", PointStamped, on_com)
rospy.Subscriber(f"/{ns}/imu", Imu, on_imu)
joints = {j: [command(f"{side}_{j}") for side in "lr"]
          for j in ("hip_pitch", "hip_roll", "knee", "ankle_pitch", "ankle_roll")}
rate = rospy.Rate(100)
while not rospy.is_shutdown():
    if com["now"] is not None:
        x, y, z = com["now"]
        omega = math.sqrt(G / z)
        # capture point's error: where the COM would come to rest, less where it should
        ex = x + com["velocity"][0] / omega - com["home"][0]
        ey = y + com["velocity"][1] / omega - com["home"][1]
        for i, leg in enumerate(legs_now(ex, ey, omega)):
            on = 0.0 if "ankle_pitch" in leg else 1.0  # a foot in the air has nothing to push on
            # ankles: positive pitch tips the shank back, positive roll tips it left; on top of
            # what keeps the sole parallel to the pelvis
            sole_pitch = leg.get("ankle_pitch", -leg["pitch"] - leg["knee"])
            ankle_pitch = sole_pitch + on * clamp(k_ankle * ex)
            ankle_roll = leg.get("ankle_roll", -leg["roll"]) - on * clamp(lateral * k_ankle * ey)
            # hips: negative pitch flexes (torso forward), positive roll leans the torso left
            hip_pitch = leg["pitch"] - on * clamp(k_hip * ex)
            hip_roll = leg["roll"] + on * clamp(lateral * k_hip * ey)
            for joint, value in (("hip_pitch", hip_pitch), ("hip_roll", hip_roll),
                                 ("knee", leg["knee"]), ("ankle_pitch", ankle_pitch),
                                 ("ankle_roll", ankle_roll)):
                joints[joint][i].publish(Float64(value))
    rate.sleep()
