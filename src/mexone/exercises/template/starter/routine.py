"""Raise both arms forward and hold them (see README.md)."""

from mexone import rospy
from mexone.msgs import Float64  # noqa: F401 - for your commands

rospy.init_node("arms_forward")
rate = rospy.Rate(50)
# TODO: publish the target to /mex_rb/<joint>_position_controller/command
while not rospy.is_shutdown():
    rate.sleep()
