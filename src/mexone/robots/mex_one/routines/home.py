"""The seed's 4.3.1: every joint to 0 (home) and hold."""

from mexone import rospy
from mexone.msgs import Float64

rospy.init_node("home")
ns = rospy.get_param("~namespace", "mex_rb")
controllers = [name for name in rospy.get_param(f"/{ns}", {}) if name.endswith("_position_controller")]
pubs = [rospy.Publisher(f"/{ns}/{name}/command", Float64, queue_size=1) for name in controllers]
for pub in pubs:
    pub.publish(Float64(0.0))
rospy.loginfo("sent %d joints home", len(pubs))
rospy.spin()
