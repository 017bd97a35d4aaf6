"""Standing balance: keep Mex-One on its feet when pushed, from the pelvis IMU and the joint
states, with the ankles and (optionally) the hips.

    mexone run balance                      # stand and balance (push it from a routine or GUI)
    mexone run balance _ankle_rate:=0.1 _hip:=0.3

What fells Mex-One under joint PD alone is mostly not the push but the rebound: pushed forward
at the torso it rocks onto its toes, comes back, lands on its heels with that momentum and
falls backward (its heels are 6 cm behind the ankle, its toes 10 cm ahead). So the default law
damps the rocking with the ankles: each ankle is commanded against the tilt *rate* of the legs
in the world (`ankle_rate`, rad per rad/s), which absorbs the swing instead of bouncing it.

The legs' tilt is the pelvis IMU's tilt plus the hip angle (the IMU's own tilt would not do
for the hips: bending them moves the pelvis, and feeding that back bends them further).
`hip`, `rate` (Horak and Nashner's hip strategy: bend into the fall) and `ankle` (a tilt
term) are there to experiment with; none of the values tried helped, so they default to 0.
`lateral` is the share of every gain used sideways (hip and ankle roll).
Measured by benchmarks/push_recovery.py (README): forward 3.5 -> 6.5 N s, sideways no gain.
"""

import math

from mexone import rospy
from mexone.msgs import Float64, Imu, JointState

rospy.init_node("balance")
ns = rospy.get_param("~namespace", "mex_rb")
gain = rospy.get_param("~hip", 0.0)          # rad of hip per rad of leg tilt
rate_gain = rospy.get_param("~rate", 0.0)    # rad of hip per rad/s of leg tilt rate
ankle_gain = rospy.get_param("~ankle", 0.0)  # rad of ankle per rad of leg tilt
ankle_rate = rospy.get_param("~ankle_rate", 0.2)  # rad of ankle per rad/s of leg tilt rate
lateral = rospy.get_param("~lateral", 1.0)   # share of every gain used sideways (roll)
limit = rospy.get_param("~limit", 0.4)       # rad: the most a joint is bent
imu = {"pitch": 0.0, "roll": 0.0, "pitch_rate": 0.0, "roll_rate": 0.0}
hips = {"pitch": 0.0, "roll": 0.0, "pitch_rate": 0.0, "roll_rate": 0.0}


def on_imu(msg):
    q = msg.orientation
    imu["pitch"] = math.asin(max(-1.0, min(1.0, 2 * (q.w * q.y - q.z * q.x))))
    imu["roll"] = math.atan2(2 * (q.w * q.x + q.y * q.z), 1 - 2 * (q.x * q.x + q.y * q.y))
    imu["pitch_rate"] = msg.angular_velocity.y
    imu["roll_rate"] = msg.angular_velocity.x


def on_joints(msg):
    position = dict(zip(msg.name, msg.position, strict=True))
    velocity = dict(zip(msg.name, msg.velocity, strict=True))
    for axis in ("pitch", "roll"):
        names = (f"l_hip_{axis}", f"r_hip_{axis}")
        hips[axis] = sum(position[n] for n in names) / 2
        hips[f"{axis}_rate"] = sum(velocity[n] for n in names) / 2


def command(joint):
    return rospy.Publisher(f"/{ns}/{joint}_position_controller/command", Float64, queue_size=1)


def clamp(x):
    return max(-limit, min(limit, x))


rospy.Subscriber(f"/{ns}/imu", Imu, on_imu)
rospy.Subscriber(f"/{ns}/joint_states", JointState, on_joints)
pitch_joints = [command(f"{side}_hip_pitch") for side in "lr"]
roll_joints = [command(f"{side}_hip_roll") for side in "lr"]
ankle_pitch_joints = [command(f"{side}_ankle_pitch") for side in "lr"]
ankle_roll_joints = [command(f"{side}_ankle_roll") for side in "lr"]
rate = rospy.Rate(100)
while not rospy.is_shutdown():
    # the legs' tilt in the world: positive pitch leans them forward, positive roll right
    leg_pitch = imu["pitch"] + hips["pitch"]
    leg_pitch_rate = imu["pitch_rate"] + hips["pitch_rate"]
    leg_roll = imu["roll"] + hips["roll"]
    leg_roll_rate = imu["roll_rate"] + hips["roll_rate"]
    # legs tipping forward: flex the hips (negative hip pitch) -- the torso goes into the fall
    pitch = clamp(-(gain * leg_pitch + rate_gain * leg_pitch_rate))
    roll = clamp(-lateral * (gain * leg_roll + rate_gain * leg_roll_rate))
    # ankles: lean the legs against their tilt (positive ankle pitch tips the shank back)
    ankle_pitch = clamp(ankle_gain * leg_pitch + ankle_rate * leg_pitch_rate)
    ankle_roll = clamp(lateral * (ankle_gain * leg_roll + ankle_rate * leg_roll_rate))
    for pub in pitch_joints:
        pub.publish(Float64(pitch))
    for pub in roll_joints:
        pub.publish(Float64(roll))
    for pub in ankle_pitch_joints:
        pub.publish(Float64(ankle_pitch))
    for pub in ankle_roll_joints:
        pub.publish(Float64(ankle_roll))
    rate.sleep()
