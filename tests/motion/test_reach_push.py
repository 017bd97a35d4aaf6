"""reach and push from routines, through the controllers, in the simulation: the hand gets
there, the feet stay, an unreachable target says so; a push that fells PD alone does not fell
the shipped balance routine, forward or sideways."""

from __future__ import annotations

import numpy as np
import pytest

from mexone.lab import Lab
from mexone.motion.recovery import PushTrial, survives
from mexone.routines.runner import RoutineRunner

ROUTINE = """
from mexone import rospy
from mexone.motion import reach
rospy.init_node("reacher")
reach({frame!r}, {xyz!r}, duration=1.0)
"""


def _reach(tmp_path, frame, xyz):
    lab = Lab.create()
    sim = lab.sim
    sim.run(0.3)
    feet0 = {f: sim.link_pose(f)[0] for f in ("l_foot", "r_foot")}
    moved = [0.0]

    def watch(s):
        moved[0] = max(moved[0], *(np.linalg.norm(s.link_pose(f)[0] - p) for f, p in feet0.items()))

    sim.add_periodic(0.01, watch)
    path = tmp_path / f"reach_{frame}.py"
    path.write_text(ROUTINE.format(frame=frame, xyz=list(xyz)))
    runner = RoutineRunner(lab, path)
    runner.run(9.0)
    assert runner.error is None
    forearm = {"l_hand": "l_forearm", "r_hand": "r_forearm"}[frame]
    position, quat = sim.link_pose(forearm)
    rot = np.zeros(9)
    import mujoco
    mujoco.mju_quat2Mat(rot, quat)
    hand = position + rot.reshape(3, 3) @ np.array([0.0, 0.0, -0.17])
    return hand, moved[0], runner.log_lines


@pytest.mark.parametrize("frame, xyz", [
    ("l_hand", (0.25, 0.2, 0.75)), ("r_hand", (0.3, -0.1, 0.7)),
    # low beside and behind the hip: the straight path stops 50-70 mm short in another local
    # minimum of the IK; reach then restarts the arm (WholeBodyIK.solve) and swings it there
    ("r_hand", (-0.055, -0.258, 0.676)), ("r_hand", (-0.038, -0.222, 0.721))])
def test_reachable_target_is_reached_in_sim_with_feet_planted(tmp_path, frame, xyz):
    hand, moved, log = _reach(tmp_path, frame, xyz)
    assert np.linalg.norm(hand - xyz) < 0.005
    assert moved < 0.005
    assert not [line for line in log if line[1] == "WARN"]


def test_unreachable_target_reports_the_remaining_error(tmp_path):
    xyz = (1.5, -0.2, 0.7)
    hand, moved, log = _reach(tmp_path, "r_hand", xyz)
    warnings = [text for _, level, text in log if level == "WARN"]
    assert len(warnings) == 1 and "\n" not in warnings[0]
    assert "out of reach" in warnings[0]
    reported = float(warnings[0].split("closest pose, ")[1].split(" mm")[0]) / 1000
    assert 0.7 < reported < 1.5  # the arm's length short of a target 1.5 m out
    assert np.linalg.norm(hand - xyz) > 0.7
    # straining for it, the whole body leans and twists: the feet stay on the ground (they
    # slide a few cm today: see the README's limits) and the robot stands
    assert moved < 0.1


@pytest.mark.parametrize("direction, impulse", [
    ((1.0, 0.0, 0.0), 6.0),  # N s at the torso: PD alone survives 3.5, the balance routine 9.0
    ((0.0, 1.0, 0.0), 8.0),  # PD alone 5.5, the balance routine 11.0 (both by stepping)
])
def test_balance_routine_survives_a_push_that_fells_pd_alone(direction, impulse):
    assert not survives(PushTrial(direction=direction), impulse)
    assert survives(PushTrial(direction=direction, routine="balance"), impulse)


def test_pd_alone_survives_a_small_push():  # the comparison is not with a broken robot
    assert survives(PushTrial(direction=(1.0, 0.0, 0.0)), 2.0)


GOAL = """
from mexone import rospy
from mexone.msgs import Header, Point, Pose, PoseStamped, Quaternion
rospy.init_node("goal")
pub = rospy.Publisher("/mex_rb/l_hand/goal", PoseStamped, queue_size=1)
rospy.sleep(0.5)
pub.publish(PoseStamped(Header(frame_id="world"),
                        Pose(Point(0.25, 0.2, 0.75), Quaternion(0.0, 0.0, 0.0, 0.0))))
pub.publish(PoseStamped(Header(frame_id="l_forearm"), Pose(Point(0.0, 0.0, 0.0))))
"""


def test_posestamped_goal_on_the_bus_moves_the_hand(tmp_path):
    lab = Lab.create()
    sim = lab.sim
    sim.run(0.3)
    path = tmp_path / "goal.py"
    path.write_text(GOAL)
    runner = RoutineRunner(lab, "reach_goals")
    runner.add(path)
    runner.run(9.0)
    assert runner.error is None
    position, quat = sim.link_pose("l_forearm")
    rot = np.zeros(9)
    import mujoco
    mujoco.mju_quat2Mat(rot, quat)
    hand = position + rot.reshape(3, 3) @ np.array([0.0, 0.0, -0.17])
    assert np.linalg.norm(hand - (0.25, 0.2, 0.75)) < 0.005
    # a goal in another frame is refused, in one line, and moves nothing
    warnings = [text for _, level, text in runner.log_lines if level == "WARN"]
    assert len(warnings) == 1 and "frame 'l_forearm' ignored" in warnings[0]


def test_gui_ik_handle_moves_the_hand():
    """The page's IK handles: a hand handle dropped 8 cm forward of the hand brings the hand
    there through the controllers (within PD's sag under gravity: no trimming, unlike reach)."""
    viser = pytest.importorskip("viser")
    from mexone.gui.handles import FRAMES, IkHandles

    lab = Lab.create()
    sim = lab.sim
    sim.run(0.3)
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    handles = None
    try:
        handles = IkHandles(server, lab, lambda action: action())
        handles.show(True)
        assert set(handles.handles) == {*FRAMES, "gaze"}
        position, rotation = handles.ik.pose("l_hand")
        target = position + np.array([0.08, 0.0, 0.05])
        quat = np.zeros(4)
        import mujoco
        mujoco.mju_mat2Quat(quat, rotation.ravel())
        joints, error = handles.solve(sim.data.qpos.copy(), "l_hand", target, quat)
        assert error.position < 0.002
        feet = {f: sim.link_pose(f)[0] for f in ("l_foot", "r_foot")}
        handles.send(joints, error)
        sim.run(2.0)
        forearm, q = sim.link_pose("l_forearm")
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, q)
        hand = forearm + rot.reshape(3, 3) @ np.array([0.0, 0.0, -0.17])
        assert np.linalg.norm(hand - target) < 0.02
        assert max(np.linalg.norm(sim.link_pose(f)[0] - p) for f, p in feet.items()) < 0.005
    finally:
        if handles is not None:
            handles.close()  # its worker thread ends with it
        server.stop()
