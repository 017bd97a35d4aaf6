"""Arms routine: move the arms through the poses of the statement (README.md), in time.

Run it: mexone run routine.py --duration 6.5     Check it: python3 check.py
"""

from mexone import rospy
from mexone.msgs import Float64

rospy.init_node("arms_routine")
ns = "mex_rb"
JOINTS = ("l_shoulder_pitch", "r_shoulder_pitch", "l_elbow", "r_elbow")
pubs = {j: rospy.Publisher(f"/{ns}/{j}_position_controller/command", Float64, queue_size=10)
        for j in JOINTS}
rate = rospy.Rate(50)

# TODO: publish each pose in time (rospy.get_time() is sim time), moving smoothly between them
while not rospy.is_shutdown():
    rate.sleep()
