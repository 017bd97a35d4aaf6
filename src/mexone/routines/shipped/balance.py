"""Standing balance: keep Mex-One on its feet when pushed, from its IMU, with the hips and ankles.

    mexone run balance                      # stand and balance (try the GUI's push tool)
    mexone run balance _hip:=1.2 _ankle:=0.3

A push at the torso tips the whole robot about the edge of its feet; joint PD alone holds the
body rigid, so it falls once the push carries its centre of mass past that edge. Two of the
strategies people use (Horak and Nashner's ankle and hip strategies) fix that from the pelvis
IMU alone, at 100 Hz:

- hip strategy: bend at the hips against the tipping rate (`hip` s). Throwing the torso into
  the fall swings the legs, and the ground's reaction on the feet, back the other way: the
  body's angular momentum goes into the torso instead of into tipping about the toes.
- ankle strategy: press the toes (or heels, or the outer soles) down in proportion to the tilt
  (`ankle`), which moves the centre of pressure toward the edge the robot tips over.

The same two can act in the frontal plane with hip roll and ankle roll (`lateral`: the share
of both gains used there). They are off by default: no sign or share tried so far beat joint PD
alone sideways. Gains are in rad per rad (tilt) and rad per rad/s (tilt rate).

STATUS: unfinished. These gains came from a grid search scored by bisection, which survival
does not allow (it is not monotonic in the impulse); scanned properly they do NOT yet beat
joint PD alone (benchmarks/push_recovery.py). Tuning them, or replacing the law with whole-body
IK and a COM task (mexone.motion.ik), is open work.
"""

import math

from mexone import rospy
from mexone.msgs import Float64, Imu

rospy.init_node("balance")
ns = rospy.get_param("~namespace", "mex_rb")
hip_rate = rospy.get_param("~hip", 0.05)        # rad of hip per rad/s of tipping
ankle_tilt = rospy.get_param("~ankle", 0.5)     # rad of ankle per rad of tilt
lateral = rospy.get_param("~lateral", 0.0)      # share of both gains used in the frontal plane
limit = rospy.get_param("~limit", 0.4)          # rad: the most either strategy bends a joint
state = {"pitch": 0.0, "roll": 0.0, "pitch_rate": 0.0, "roll_rate": 0.0}


def on_imu(msg):
    q = msg.orientation
    state["pitch"] = math.asin(max(-1.0, min(1.0, 2 * (q.w * q.y - q.z * q.x))))
    state["roll"] = math.atan2(2 * (q.w * q.x + q.y * q.z), 1 - 2 * (q.x * q.x + q.y * q.y))
    state["pitch_rate"] = msg.angular_velocity.y
    state["roll_rate"] = msg.angular_velocity.x


def command(joint):
    return rospy.Publisher(f"/{ns}/{joint}_position_controller/command", Float64, queue_size=1)


def clamp(x):
    return max(-limit, min(limit, x))


rospy.Subscriber(f"/{ns}/imu", Imu, on_imu)
joints = {j: command(j) for side in "lr" for j in (f"{side}_hip_pitch", f"{side}_ankle_pitch",
                                                   f"{side}_hip_roll", f"{side}_ankle_roll")}
rate = rospy.Rate(100)
while not rospy.is_shutdown():
    # sagittal: tipping forward (pitch > 0) flexes the hips (negative hip pitch) and presses
    # the toes down (positive ankle pitch lifts the shank over the foot)
    hip = clamp(-hip_rate * state["pitch_rate"])
    ankle = clamp(ankle_tilt * state["pitch"])
    # frontal: tipping to the left (roll < 0)...
    hip_roll = clamp(-lateral * hip_rate * state["roll_rate"])
    ankle_roll = clamp(lateral * ankle_tilt * state["roll"])
    for side in "lr":
        joints[f"{side}_hip_pitch"].publish(Float64(hip))
        joints[f"{side}_ankle_pitch"].publish(Float64(ankle))
        joints[f"{side}_hip_roll"].publish(Float64(hip_roll))
        joints[f"{side}_ankle_roll"].publish(Float64(ankle_roll))
    rate.sleep()
