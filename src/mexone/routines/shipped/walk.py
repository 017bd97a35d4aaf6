"""Walk Mex-One straight ahead: footsteps, ZMP preview control of the centre of mass (Kajita et
al. 2003), swing-foot arcs and whole-body IK, sent to the joint position controllers
(mexone/motion/walk.py holds the planner; the gait's numbers are in walk.yaml next to this).

    mexone run walk --duration 30 --json      # 3 m; the report has distance_x, drift_y, yaw, speed
    mexone run walk _distance:=1.0 _gait:=my_gait.yaml
"""

from mexone import rospy
from mexone.motion import walk

rospy.init_node("walk")
distance = rospy.get_param("~distance", 3.0)  # m
walk(distance, rospy.get_param("~gait", None))
rospy.loginfo("walked the plan for %.2f m; standing", distance)
rospy.spin()
