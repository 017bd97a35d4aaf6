"""Walk Mex-One over a course: from standing, 3 m forward, a quarter turn left in place, 1 m to
the right, then stand 5 s (the course and the gait's numbers are in walk.yaml next to this;
mexone/motion/walk.py holds the planner: footsteps, ZMP preview control of the centre of mass
(Kajita et al. 2003), swing-foot arcs and whole-body IK, sent to the joint position controllers).

    mexone run walk --json        # the report has distance_x, drift_y, yaw, speed and each leg's
    mexone run walk _course:="[[forward, 1.0]]" _gait:=my_gait.yaml

It sets its ~duration to the course's length, so `mexone run` runs it to its end.
"""

from mexone import rospy
from mexone.motion import walk, walk_seconds

STAND = 5.0  # s standing still at the end

rospy.init_node("walk")
course = rospy.get_param("~course", None)  # None: walk.yaml's
gait = rospy.get_param("~gait", None)       # None: the shipped walk.yaml
rospy.set_param("~duration", walk_seconds(course, gait) + STAND)
walk(course, gait)
rospy.loginfo("walked the course; standing %.0f s", STAND)
rospy.sleep(STAND)
