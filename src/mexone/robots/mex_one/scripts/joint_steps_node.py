#!/usr/bin/python3
"""The seed's Listing 3.18 as a real rospy node, fixed: one joint 0 -> -pi/2 in 20 steps of
0.078535 rad and back, at 10 Hz (the C++ never defined loop_rate, and went one step past)."""

import rospy
from std_msgs.msg import Float64


def main() -> None:
    rospy.init_node("joint_steps")
    joint = rospy.get_param("~joint", "l_shoulder_pitch")
    ns = rospy.get_param("~namespace", "mex_rb")
    pub = rospy.Publisher(f"/{ns}/{joint}_position_controller/command", Float64, queue_size=1000)
    rate = rospy.Rate(rospy.get_param("~rate", 10))
    steps = list(range(0, 21)) + list(range(20, -1, -1))
    while not rospy.is_shutdown():
        for count in steps:
            pub.publish(Float64(-0.078535 * count))
            rospy.loginfo("Publishing: %d", count)
            rate.sleep()


if __name__ == "__main__":
    try:  # noqa: SIM105 - the rospy idiom students know
        main()
    except rospy.ROSInterruptException:
        pass
