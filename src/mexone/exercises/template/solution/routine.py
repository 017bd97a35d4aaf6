"""The reference: both shoulders to -0.8 rad, held."""

from mexone import rospy
from mexone.msgs import Float64

rospy.init_node("arms_forward")
pubs = [rospy.Publisher(f"/mex_rb/{j}_position_controller/command", Float64, queue_size=1)
        for j in ("l_shoulder_pitch", "r_shoulder_pitch")]
rate = rospy.Rate(50)
while not rospy.is_shutdown():
    for pub in pubs:
        pub.publish(Float64(-0.8))
    rate.sleep()
