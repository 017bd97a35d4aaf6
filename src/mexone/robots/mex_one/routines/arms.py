"""The seed's Listing 4.2, fixed and ported: arms (and head) out and back, slowly.

The C++ published `30` to a position controller: meant as degrees, it was 30 rad. It also
jumped straight to the target; the seed's text asks for slow movements so the robot keeps its
balance, so each half-cycle here ramps over 15 steps at 10 Hz (1.5 s), as its loop counted.
"""

import math

from mexone import rospy
from mexone.msgs import Float64

rospy.init_node("arms")
ns = rospy.get_param("~namespace", "mex_rb")
amplitude = math.radians(rospy.get_param("~degrees", 30.0))
targets = {  # joint: direction of the motion
    "l_shoulder_pitch": -1.0, "r_shoulder_pitch": -1.0,  # arms forward
    "l_elbow": -1.0, "r_elbow": -1.0,                    # elbows bent
    "neck_yaw": 1.0,                                     # head turns
}
pubs = {j: rospy.Publisher(f"/{ns}/{j}_position_controller/command", Float64, queue_size=1000)
        for j in targets}
rate = rospy.Rate(10)

while not rospy.is_shutdown():
    for t in range(0, 31):
        share = t / 15 if t <= 15 else (30 - t) / 15  # up for 15 steps, down for 15
        for joint, sign in targets.items():
            pubs[joint].publish(Float64(sign * amplitude * share))
        if t in (0, 15):
            rospy.loginfo("arms at %.0f degrees", math.degrees(amplitude * share))
        rate.sleep()
