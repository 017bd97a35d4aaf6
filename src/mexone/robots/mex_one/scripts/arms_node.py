#!/usr/bin/python3
"""The seed's Listing 4.2 as a real rospy node, fixed: 30 degrees (not 30 rad), ramped over
15 steps at 10 Hz out and back, on both shoulders, both elbows and the neck."""

import math

import rospy
from std_msgs.msg import Float64


def main() -> None:
    rospy.init_node("arms")
    ns = rospy.get_param("~namespace", "mex_rb")
    amplitude = math.radians(rospy.get_param("~degrees", 30.0))
    targets = {"l_shoulder_pitch": -1.0, "r_shoulder_pitch": -1.0, "l_elbow": -1.0,
               "r_elbow": -1.0, "neck_yaw": 1.0}
    pubs = {j: rospy.Publisher(f"/{ns}/{j}_position_controller/command", Float64, queue_size=1000)
            for j in targets}
    rate = rospy.Rate(10)
    while not rospy.is_shutdown():
        for t in range(0, 31):
            share = t / 15 if t <= 15 else (30 - t) / 15
            for joint, sign in targets.items():
                pubs[joint].publish(Float64(sign * amplitude * share))
            rate.sleep()


if __name__ == "__main__":
    try:  # noqa: SIM105 - the rospy idiom students know
        main()
    except rospy.ROSInterruptException:
        pass
