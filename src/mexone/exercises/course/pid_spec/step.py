"""The grader's step (not the student's): l_elbow from 0 to -1 rad at t = 0.5 s, held."""

from mexone import rospy
from mexone.msgs import Float64

rospy.init_node("step")
pub = rospy.Publisher("/mex_rb/l_elbow_position_controller/command", Float64, queue_size=10)
rate = rospy.Rate(100)
while not rospy.is_shutdown():
    pub.publish(Float64(-1.0 if rospy.get_time() >= 0.5 else 0.0))
    rate.sleep()
