"""The walk's plan, published for drawing: footsteps as geometry_msgs/PoseArray and the planned
ZMP and COM as nav_msgs/Path on /<ns>/walk/*. Open loop (no sensing) the published plan is the
footstep planner's own, and the COM path predicted at a lift-off is the one preview control
then gives; walked by the shipped routine, the footsteps are the planner's from the stance it
started in, once per step, and the last ones are where the feet stand."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from mexone.lab import Lab
from mexone.motion.ik import WholeBodyIK
from mexone.motion.walk import FootstepPlanner, Gait, course_steps, walk_ticks
from mexone.msgs import Path, PoseArray
from mexone.robots.mex_one import END_EFFECTORS
from mexone.routines.runner import RoutineRunner

SHORT = [("forward", 0.12)]  # two steps, then two closing ones


def _targets(gait, feet, course):
    """Every footstep the planner plans, open loop, in order."""
    out, seen = [], []  # the swings themselves kept: an id() is reused once its object is freed
    for tick in FootstepPlanner(gait, feet, course_steps(gait, course)):
        if tick.swing is not None and not any(tick.swing is s for s in seen):
            seen.append(tick.swing)
            out.append(tick.swing.target.copy())
    return out


def test_the_open_loop_plan_is_the_planners_and_the_com_path_comes_true():
    lab = Lab.create(controllers=False)
    ik = WholeBodyIK.for_sim(lab.sim)
    gait = Gait()
    plans, coms = [], []
    for _ in walk_ticks(ik, lab.sim.data.qpos.copy(), gait, course_steps(gait, SHORT),
                        on_plan=lambda tick, com: coms.append(com),
                        on_replan=lambda plan: plans.append((len(coms), plan))):
        pass
    # at the start and at each of the 4 lift-offs
    assert len(plans) == 5
    first = plans[0][1]
    feet = [np.array(f) for f in first.footsteps[:2]]
    targets = _targets(gait, feet, SHORT)
    assert len(targets) == 4
    # each plan: the steps walked and those planned (1.6 s ahead), the planner's exactly (open
    # loop nothing moves a landing); the last one shows all 6 footsteps
    every = [*feet, *targets]
    for _, plan in plans:
        assert 2 < len(plan.footsteps) <= 6
        assert np.allclose(plan.footsteps, every[:len(plan.footsteps)], atol=1e-12)
    assert len(plans[-1][1].footsteps) == 6
    assert first.zmp[0] == pytest.approx((feet[0][:2] + feet[1][:2]) / 2)
    for at, plan in plans[1:]:
        # now and the 1.6 s preview ahead at least (or the rest of the walk, all planned)
        assert len(plan.zmp) == len(plan.com) >= 1 + min(161, len(coms) - at)
        predicted = plan.com[1:]
        actual = np.array(coms[at:at + len(predicted)])
        n = len(actual)
        # the next period exactly; then as far as the plan reached, within 1 mm (the plan
        # planned later adds to the preview's far end, whose gains are small)
        assert predicted[0] == pytest.approx(actual[0], abs=1e-12)
        assert np.abs(predicted[:n] - actual).max() < 1e-3
    # the COM sways towards each stance foot and ends between the feet
    assert coms[-1] == pytest.approx(plans[-1][1].zmp[-1], abs=2e-3)


@pytest.fixture(scope="module")
def walked():
    """The shipped walk routine over SHORT, every plan message kept; the GUI's overlay built
    on the same bus before the walk, as a page would be."""
    viser = pytest.importorskip("viser")
    from helpers import built_panel
    from mexone.gui.walkplan import WalkPlanView

    lab = Lab.create()
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    view = built_panel(WalkPlanView, server, lab)
    got = {"footsteps": [], "zmp_plan": [], "com_plan": []}
    for key, kind in (("footsteps", PoseArray), ("zmp_plan", Path), ("com_plan", Path)):
        lab.bus.subscribe(f"/mex_rb/walk/{key}", kind, got[key].append)
    runner = RoutineRunner(lab, "walk", {"_course": [list(leg) for leg in SHORT]})
    runner.run(None)  # the course's length, as the routine declares it
    assert runner.error is None
    yield lab, got, view
    server.stop()


def test_the_walk_routine_publishes_its_plan_once_a_step(walked):
    lab, got, _ = walked
    assert lab.bus.topics["/mex_rb/walk/footsteps"].ros_type == "geometry_msgs/PoseArray"
    assert lab.bus.topics["/mex_rb/walk/com_plan"].ros_type == "nav_msgs/Path"
    # published when the plan changes: at the start and at each of the 4 lift-offs, not a tick
    assert [len(v) for v in got.values()] == [5, 5, 5]
    first, last = got["footsteps"][0].poses, got["footsteps"][-1].poses
    assert got["footsteps"][0].header.frame_id == "world"
    assert len(first) == 4 and len(last) == 6  # standing feet and steps planned 1.6 s ahead
    feet = [np.array([p.position.x, p.position.y, 2 * math.atan2(p.orientation.z, p.orientation.w)])
            for p in first]
    targets = _targets(Gait.load(), feet[:2], SHORT)
    for got_foot, want in zip(feet[2:], targets, strict=False):
        assert got_foot == pytest.approx(want, abs=1e-9)
    # the standing feet are Mex-One's (0.12 m apart, on the ground); the plan ends 12 cm ahead
    assert abs(feet[0][1] - feet[1][1]) == pytest.approx(0.12, abs=0.02)
    assert abs(first[0].position.z) < 0.01 and type(first[0].position.z) is float
    assert targets[-1][0] - feet[0][0] == pytest.approx(0.12, abs=1e-9)
    # the last plan's final footsteps are where the soles stand now: 2.8 and 3.1 cm ahead of
    # them measured (the feet slip forward, README's limits: 3.3 m walked for 3 planned), and
    # the one relative to the other within 1 cm
    soles = []
    for side in "lr":
        link, offset = END_EFFECTORS[f"{side}_foot"]
        position, quat = lab.sim.link_pose(link)
        turned = np.zeros(3)
        mujoco.mju_rotVecQuat(turned, np.asarray(offset, dtype=float), np.asarray(quat))
        soles.append((np.asarray(position) + turned)[:2])
    planned = {round(p.position.y > 0): np.array([p.position.x, p.position.y]) for p in last[-2:]}
    assert set(planned) == {0, 1}  # one left, one right
    left, right = planned[1], planned[0]
    assert np.linalg.norm(left - soles[0]) < 0.045 and np.linalg.norm(right - soles[1]) < 0.045
    assert np.linalg.norm((left - right) - (soles[0] - soles[1])) < 0.01
    # the ZMP path starts on the ground where the COM path starts above it, a period apart
    zmp, com = got["zmp_plan"][1], got["com_plan"][1]
    assert len(zmp.poses) == len(com.poses) > 150
    assert com.poses[0].pose.position.z > 0.4 and abs(zmp.poses[0].pose.position.z) < 0.01
    step = com.poses[1].header.stamp.to_sec() - com.poses[0].header.stamp.to_sec()
    assert step == pytest.approx(0.01, abs=1e-9)


def test_the_gui_overlay_draws_the_plan_and_the_measured_zmp(walked):
    from mexone.gui.walkplan import MIN_SEGMENT, PATH_STRIDE

    lab, got, view = walked
    nodes = view.nodes
    # hidden, it only kept the latest messages: nothing drawn, /zmp not asked for
    assert not any(n.visible for n in nodes.values())
    assert view.latest["footsteps"] is got["footsteps"][-1]
    assert len(nodes["footsteps"].points) == 1
    assert not lab.bus.wanted("/mex_rb/zmp") or lab.bus.taps
    view.show(True)  # the View menu's toggle (simulation thread)
    assert all(nodes[k].visible for k in ("footsteps", "zmp_plan", "com_plan"))
    assert not nodes["zmp"].visible  # nothing measured yet: hidden, not a zero-length line
    steps = got["footsteps"][-1].poses
    outlines = nodes["footsteps"].points
    assert outlines.shape == (4 * len(steps), 2, 3)
    for i, pose in enumerate(steps):  # each sole's outline is centred on its footstep
        centre = outlines[4 * i:4 * i + 4, 0].mean(axis=0)
        assert centre[:2] == pytest.approx((pose.position.x, pose.position.y), abs=1e-6)
        side = np.linalg.norm(outlines[4 * i, 1] - outlines[4 * i, 0])
        assert side == pytest.approx(0.08, abs=1e-6) or side == pytest.approx(0.16, abs=1e-6)
    com = got["com_plan"][-1].poses
    drawn = nodes["com_plan"].points
    # every 4th point (and the last) joined, repeated points left out: no
    # segment of zero length, which a browser draws across the whole view
    for node in (nodes["com_plan"], nodes["zmp_plan"], nodes["footsteps"]):
        assert np.linalg.norm(node.points[:, 1] - node.points[:, 0], axis=1).min() > MIN_SEGMENT
    assert len(drawn) <= len(com) // PATH_STRIDE + 1
    assert drawn[0, 0] == pytest.approx((com[0].pose.position.x, com[0].pose.position.y,
                                         com[0].pose.position.z), abs=1e-6)
    ends = np.array([[p.pose.position.x, p.pose.position.y] for p in com[::PATH_STRIDE] + com[-1:]])
    assert np.linalg.norm(ends - drawn[-1, 1, :2], axis=1).min() < 1e-6
    zmp_plan = np.array([[p.pose.position.x, p.pose.position.y] for p in got["zmp_plan"][-1].poses])
    for point in nodes["zmp_plan"].points[:, 0, :2]:  # drawn through the planned points
        assert np.linalg.norm(zmp_plan - point, axis=1).min() < 1e-6
    # the measured ZMP: asked for while shown (50 Hz, as the balance topics), between the feet
    assert lab.bus.wanted("/mex_rb/zmp")
    lab.sim.run(0.5)
    view.update()
    trail = nodes["zmp"].points
    assert nodes["zmp"].visible and 2 <= len(trail) + 1 <= 26  # 50 Hz, repeats left out
    assert all(n.thickness_units == "screen" for n in nodes.values())  # pixels, not metres
    middle = np.mean([[p.position.x, p.position.y] for p in steps[-2:]], axis=0)
    assert np.abs(trail[:, 0, :2] - middle).max() < 0.04
    view.show(False)
    assert not any(n.visible for n in nodes.values()) and not lab.bus.wanted("/mex_rb/zmp")


def test_a_listener_who_comes_while_the_robot_stands_gets_the_plan():
    """rviz opened after `walk_cmd_vel` started, before any command: the plan made at the start
    (nobody listened then, so it was not sent) arrives at the next tick; one message, not one a
    tick: the plan has not changed."""
    lab = Lab.create()
    runner = RoutineRunner(lab, "walk_cmd_vel")
    got: list[PoseArray] = []

    def late(sim) -> None:
        if sim.time >= 2.0 and not got and not late.subscribed:
            late.subscribed = True
            lab.bus.subscribe("/mex_rb/walk/footsteps", PoseArray, got.append)
    late.subscribed = False
    runner.run(3.0, on_tick=late)
    assert runner.error is None
    assert len(got) == 1
    # standing: the two soles, where they stand
    soles = sorted(p.position.y for p in got[0].poses)
    l_sole = lab.sim.link_pose(END_EFFECTORS["l_foot"][0])[0]
    assert len(soles) >= 2 and soles[-1] == pytest.approx(l_sole[1], abs=0.03)
