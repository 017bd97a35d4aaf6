"""Arms routine, the reference: ramp smoothly from pose to pose (1 s each), then hold it until
its window ends, so the robot keeps its balance."""

from itertools import pairwise

from mexone import rospy
from mexone.msgs import Float64

rospy.init_node("arms_routine")
ns = "mex_rb"
JOINTS = ("l_shoulder_pitch", "r_shoulder_pitch", "l_elbow", "r_elbow")
RAMP = 0.7  # s to move from one pose to the next, starting when the last one's window ends
# (when the move to the pose starts, pose): each reached 0.3 s before its window opens
PLAN = ((0.0, (0.0, 0.0, 0.0, 0.0)), (0.5, (-0.6, -0.6, -0.5, -0.5)),
        (2.0, (-1.2, 0.0, -1.2, 0.0)), (3.5, (0.0, -1.2, 0.0, -1.2)),
        (5.0, (-0.3, -0.3, -1.0, -1.0)))
pubs = {j: rospy.Publisher(f"/{ns}/{j}_position_controller/command", Float64, queue_size=10)
        for j in JOINTS}
rate = rospy.Rate(100)


def command(t):
    for (_, p0), (t1, p1) in pairwise(PLAN):
        if t < t1 + RAMP:
            share = min(max((t - t1) / RAMP, 0.0), 1.0)
            share = share * share * (3 - 2 * share)  # smooth start and stop
            return [a + (b - a) * share for a, b in zip(p0, p1, strict=True)]
    return list(PLAN[-1][1])


while not rospy.is_shutdown():
    for joint, value in zip(JOINTS, command(rospy.get_time()), strict=True):
        pubs[joint].publish(Float64(value))
    rate.sleep()
