"""The seed's Listing 3.18, fixed and ported: one joint from 0 to -pi/2 in 20 steps of
0.078535 rad and back, for ever. (The C++ used an undefined loop_rate: here 10 Hz.)

    mexone run joint_steps                      # the left shoulder (arm raised forward)
    mexone run joint_steps _joint:=r_elbow _rate:=20
"""

from mexone import rospy
from mexone.msgs import Float64

rospy.init_node("joint_steps")
joint = rospy.get_param("~joint", "l_shoulder_pitch")
namespace = rospy.get_param("~namespace", "mex_rb")
pub = rospy.Publisher(f"/{namespace}/{joint}_position_controller/command", Float64, queue_size=1000)
rate = rospy.Rate(rospy.get_param("~rate", 10))

count = 0
while not rospy.is_shutdown():
    while count <= 20 and not rospy.is_shutdown():
        pub.publish(Float64(-0.078535 * count))
        rospy.loginfo("Publishing: %d", count)
        rate.sleep()
        count += 1
    count = 20  # the C++ left count at 21 and published -1.649 rad: one step past -pi/2
    while count >= 0 and not rospy.is_shutdown():
        pub.publish(Float64(-0.078535 * count))
        rospy.loginfo("Publishing: %d", count)
        rate.sleep()
        count -= 1
    count = 0
