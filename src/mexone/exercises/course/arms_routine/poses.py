"""The poses of the arms routine (rad) and when each must be held: shared by the grader, the
statement's table and the tests. Joint order: l_shoulder_pitch, r_shoulder_pitch, l_elbow,
r_elbow."""

JOINTS = ("l_shoulder_pitch", "r_shoulder_pitch", "l_elbow", "r_elbow")
POSES = (  # (from s, to s): the window where the arms must be at the pose
    ((1.5, 2.0), (-0.6, -0.6, -0.5, -0.5)),   # arms forward, elbows a little bent
    ((3.0, 3.5), (-1.2, 0.0, -1.2, 0.0)),     # left arm up, right arm down
    ((4.5, 5.0), (0.0, -1.2, 0.0, -1.2)),     # the other way round
    ((6.0, 6.5), (-0.3, -0.3, -1.0, -1.0)),   # elbows bent
)
DURATION = 6.5
