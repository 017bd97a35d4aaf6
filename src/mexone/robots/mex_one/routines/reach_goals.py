"""Move Mex-One's hands, feet and head to geometry_msgs/PoseStamped goals on
/<ns>/<frame>/goal (l_hand, r_hand, l_foot, r_foot, head), whole-body IK through the position
controllers, the other feet planted. Goals are in the world frame (frame_id '' or 'world'); a
zero quaternion (rospy's default) leaves the orientation free.

    mexone run reach_goals --duration 60
    rostopic pub -1 /mex_rb/l_hand/goal geometry_msgs/PoseStamped \\
        '{header: {frame_id: world}, pose: {position: {x: 0.25, y: 0.2, z: 0.75}}}'
"""

from mexone import rospy
from mexone.motion import follow_goals

rospy.init_node("reach_goals")
follow_goals(duration=rospy.get_param("~duration_each", 1.0))
