"""Walk Mex-One where geometry_msgs/Twist on /<ns>/cmd_vel says: linear.x forward, linear.y
left (m/s), angular.z turn left (rad/s), each step clipped to walk.yaml's largest; no command
(or none for 0.5 s) stands. Send it from a routine, from ROS (rostopic pub, teleop_twist_keyboard)
or from the GUI's walk pad. A command takes effect when the footstep plan reaches it: after the
ZMP preview (walk.yaml's `preview`, 1.6 s).

    mexone run walk_cmd_vel --duration 30
    rostopic pub -r 10 /mex_rb/cmd_vel geometry_msgs/Twist '{linear: {x: 0.15}}'
"""

from mexone import rospy
from mexone.motion import walk_cmd_vel

rospy.init_node("walk_cmd_vel")
walk_cmd_vel(rospy.get_param("~gait", None))
