"""Standing balance: keep Mex-One on its feet when pushed, from its centre of mass (COM), with
the ankles and, when they cannot do it, a step.

    mexone run balance                      # stand and balance (push it from a routine or GUI)
    mexone run balance _ankle:=1.5 _step_at:=0.1

The law is the capture point of the linear inverted pendulum (Pratt 2006, Englsberger 2011): a
COM at height z moving at v comes to rest over the point  cp = com + v / omega,
omega = sqrt(g / z).  While cp stays within the feet, the ankles alone can stop the robot:
each ankle is commanded against the capture point's error (leaning the legs back pushes the
centre of pressure ahead of the COM, which slows it) -- the ankle strategy. Once cp leaves the
feet (`step_at` from where the COM stood) no ankle torque can bring it back: the foot on the
side of the fall is lifted and put down under it (`step_gain` x the error, at most `step_max`),
and the robot then balances, still by its ankles, over the wider stance -- the stepping
strategy. `hip` adds Horak and Nashner's hip strategy (bend into the fall), default off: it
did not help this robot.

COM and its height come from /<ns>/com (the sensors' balance topic, 50 Hz); its velocity by
differencing, lightly filtered (`filter`). The legs are straight and 0.5 m long, so the step is
two angles (hip pitch and roll) with the sole kept parallel to the pelvis by the ankle.
Measured by benchmarks/push_recovery.py (benchmarks/RESULTS.md).
"""

import math

from mexone import rospy
from mexone.msgs import Float64, PointStamped

rospy.init_node("balance")
ns = rospy.get_param("~namespace", "mex_rb")
k_ankle = rospy.get_param("~ankle", 1.0)        # rad of ankle per m of capture-point error
k_hip = rospy.get_param("~hip", 0.0)            # rad of hip per m of capture-point error
lateral = rospy.get_param("~lateral", 1.0)      # share of the gains used sideways (roll)
limit = rospy.get_param("~limit", 0.4)          # rad: the most feedback bends a joint
smooth = rospy.get_param("~filter", 0.5)        # weight of the newest COM velocity sample
step_at = rospy.get_param("~step_at", 0.08)     # m of capture-point error that triggers a step
step_gain = rospy.get_param("~step_gain", 1.5)  # step length per m of capture-point error
step_max = rospy.get_param("~step_max", 0.25)   # m, the longest step
lift = rospy.get_param("~lift", 0.7)            # rad of knee flexion while the foot swings
swing = rospy.get_param("~swing", 0.1)          # s to lift the foot, and as long to put it down
LEG = 0.5  # m, hip to sole
REACH = 0.45  # rad: the widest a leg swings (the ankle roll, keeping the sole flat, stops at 0.5)
G = 9.81
com = {"now": None, "home": None, "velocity": (0.0, 0.0), "stamp": 0.0}
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


def command(joint):
    return rospy.Publisher(f"/{ns}/{joint}_position_controller/command", Float64, queue_size=1)


def clamp(x):
    return max(-limit, min(limit, x))


def swing_angle(d):
    """The hip angle that moves a straight leg's foot d m (within REACH)."""
    return max(-REACH, min(REACH, math.asin(max(-1.0, min(1.0, d / LEG)))))


def legs_now(ex, ey):
    """Each leg's hip pitch, hip roll and knee: straight, or the capture step's."""
    straight = [dict(pitch=0.0, roll=0.0, knee=0.0) for _ in "lr"]
    if not step and math.hypot(ex, ey) > step_at:
        scale = min(step_gain, step_max / math.hypot(ex, ey))
        side = 0 if ey >= 0 else 1  # the left leg for a fall to the left (or straight ahead)
        dx, dy = scale * ex, scale * ey
        if (side == 0) == (dy < 0):
            dy = 0.0  # a foot never steps across the other
        step.update(side=side, start=rospy.get_time(),
                    pitch=-swing_angle(dx), roll=swing_angle(dy))
        # the stance to come is centred between the feet: balance about there from now on
        com["home"] = (com["home"][0] + dx / 2, com["home"][1] + dy / 2)
    if not step:
        return straight
    side, t = step["side"], rospy.get_time() - step["start"]
    if t < 2 * swing:  # foot up (knee bent, thigh lifted), out, then down
        knee = lift if t < swing else 0.0
        straight[side] = dict(pitch=step["pitch"] - knee / 2, roll=step["roll"], knee=knee)
        return straight
    # both feet down: the split shared by the two legs, the pelvis level between them
    straight[side] = dict(pitch=step["pitch"] / 2, roll=step["roll"] / 2, knee=0.0)
    straight[1 - side] = dict(pitch=-step["pitch"] / 2, roll=-step["roll"] / 2, knee=0.0)
    return straight


rospy.Subscriber(f"/{ns}/com", PointStamped, on_com)
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
        legs = legs_now(ex, ey)
        for i, leg in enumerate(legs):
            swinging = step and i == step["side"] and rospy.get_time() - step["start"] < 2 * swing
            on = 0.0 if swinging else 1.0  # a foot in the air has nothing to push on
            # ankles: positive pitch tips the shank back, positive roll tips it left; on top of
            # what keeps the sole parallel to the pelvis
            ankle_pitch = -leg["pitch"] - leg["knee"] + on * clamp(k_ankle * ex)
            ankle_roll = -leg["roll"] - on * clamp(lateral * k_ankle * ey)
            # hips: negative pitch flexes (torso forward), positive roll leans the torso left
            hip_pitch = leg["pitch"] - on * clamp(k_hip * ex)
            hip_roll = leg["roll"] + on * clamp(lateral * k_hip * ey)
            for joint, value in (("hip_pitch", hip_pitch), ("hip_roll", hip_roll),
                                 ("knee", leg["knee"]), ("ankle_pitch", ankle_pitch),
                                 ("ankle_roll", ankle_roll)):
                joints[joint][i].publish(Float64(value))
    rate.sleep()
