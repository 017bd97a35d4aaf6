"""The View menu's Walk plan overlay: what the walk routines plan and what the feet measure, as
rviz would draw the same topics. The footsteps (/<ns>/walk/footsteps, geometry_msgs/PoseArray)
as sole outlines, the planned ZMP (/<ns>/walk/zmp_plan, on the ground) and COM
(/<ns>/walk/com_plan, at its height; both nav_msgs/Path) as lines, and the measured ZMP
(/<ns>/zmp, the Balance view's, from the foot force-torque sensors) as a trail of its last
seconds. The subscribers only keep the latest message (they run in the publisher's thread);
the lines are drawn in the simulation thread, between frames. /<ns>/zmp is subscribed only while
the overlay shows: its publisher computes it for subscribers only.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from mexone.bus.msgs import Path, PointStamped, PoseArray
from mexone.gui.panels import Panel, register_panel
from mexone.sensors.balance import RATE as BALANCE_RATE

__all__ = ["WalkPlanView", "WALK_PLAN", "SOLE", "TRAIL", "PATH_STRIDE", "polyline"]

WALK_PLAN = "Walk plan"  # the View menu's entry
SOLE = (0.16, 0.08)  # m, Mex-One's sole (length, width): a footstep's outline
TRAIL = round(5.0 * BALANCE_RATE)  # measured ZMP points kept: its last 5 s
MIN_SEGMENT = 1e-5  # m: shorter segments (a point repeated) are not drawn
PATH_STRIDE = 4  # a path's points drawn: every 4th (40 ms apart; a browser without a GPU
# draws thick lines slowly, and the paths are smooth at that scale)
_LIFT = 0.003  # m above the ground, so the lines are not hidden in the grid
_FOOT_RGB, _ZMP_RGB, _COM_RGB, _MEASURED_RGB = (40, 90, 220), (230, 140, 20), (40, 170, 70), (220, 30, 30)
_EMPTY = np.zeros((1, 2, 3), np.float32)


def sole_outlines(poses) -> np.ndarray:
    """Line segments (4 per footstep) outlining a sole at each pose (x, y, z, yaw)."""
    half = np.array(SOLE) / 2
    corners = np.array([[1, 1], [-1, 1], [-1, -1], [1, -1]]) * half
    out = []
    for x, y, z, yaw in poses:
        c, s = math.cos(yaw), math.sin(yaw)
        ring = corners @ np.array([[c, s], [-s, c]]) + (x, y)
        ring = np.c_[ring, np.full(4, z + _LIFT)]
        out.extend(zip(ring, np.roll(ring, -1, axis=0), strict=True))
    return np.array(out, np.float32) if out else None


def polyline(points: np.ndarray) -> np.ndarray:
    """Consecutive points as line segments, repeated points left out: the browser draws a
    zero-length thick segment as a quad across the whole view (the planned ZMP stands still on
    each stance foot), which also takes a GPU-less browser seconds a frame."""
    points = np.asarray(points, np.float32).reshape(-1, 3)
    if len(points):
        moved = np.r_[True, np.linalg.norm(np.diff(points, axis=0), axis=1) > MIN_SEGMENT]
        points = points[moved]
    if len(points) < 2:
        return None
    return np.stack([points[:-1], points[1:]], axis=1)


@register_panel
class WalkPlanView(Panel):
    """The Walk plan overlay (no folder: View > Walk plan shows it; see the module's doc)."""

    name = "walk_plan"
    order = 93
    period = 1

    def build(self) -> None:
        lab = self.lab
        ns = lab.namespace
        self.topics = {"footsteps": f"{ns}/walk/footsteps", "zmp_plan": f"{ns}/walk/zmp_plan",
                       "com_plan": f"{ns}/walk/com_plan", "zmp": f"{ns}/zmp"}
        self.latest: dict[str, object] = {}  # topic key -> its newest message (any thread)
        self.drawn: dict[str, object] = {}  # key -> the message drawn
        self.trail: deque[tuple[float, float, float]] = deque(maxlen=TRAIL)
        self._trail_drawn = -1  # measured ZMP points received when the trail was last drawn
        self._received = 0
        self._subs = [lab.bus.subscribe(self.topics[k], kind, lambda m, k=k: self._keep(k, m),
                                        latched=True, node="gui")
                      for k, kind in (("footsteps", PoseArray), ("zmp_plan", Path),
                                      ("com_plan", Path))]
        self._zmp_sub = None
        scene = self.server.scene
        self.nodes = {
            "footsteps": scene.add_line_segments("/walk_plan/footsteps", _EMPTY, _FOOT_RGB,
                                                 thickness=3.0, thickness_units="screen", visible=False),
            "zmp_plan": scene.add_line_segments("/walk_plan/zmp_plan", _EMPTY, _ZMP_RGB,
                                                thickness=3.0, thickness_units="screen", visible=False),
            "com_plan": scene.add_line_segments("/walk_plan/com_plan", _EMPTY, _COM_RGB,
                                                thickness=3.0, thickness_units="screen", visible=False),
            "zmp": scene.add_line_segments("/walk_plan/zmp_measured", _EMPTY, _MEASURED_RGB,
                                           thickness=2.0, thickness_units="screen", visible=False),
        }
        self.visible = False
        self.filled: set[str] = set()  # nodes with something to draw (an empty one is hidden)

    def _draw(self, key: str, points: np.ndarray | None) -> None:
        """Points to a node, or hide it: a placeholder segment of zero length would show as a
        quad across the view."""
        node = self.nodes[key]
        if points is None:
            self.filled.discard(key)
            node.visible = False
            return
        node.points = points
        self.filled.add(key)
        node.visible = self.visible

    def _keep(self, key: str, msg) -> None:
        self.latest[key] = msg  # one assignment: drawn later, in the simulation thread

    def _measured(self, msg: PointStamped) -> None:
        self.trail.append((msg.point.x, msg.point.y, msg.point.z))
        self._received += 1

    def show(self, on: bool) -> None:
        """Simulation thread: show or hide; the measured ZMP is listened to while shown."""
        self.visible = on
        if on and self._zmp_sub is None:
            self.trail.clear()
            self.filled.discard("zmp")
            self._zmp_sub = self.lab.bus.subscribe(self.topics["zmp"], PointStamped,
                                                   self._measured, node="gui")
        elif not on and self._zmp_sub is not None:
            self._zmp_sub.unregister()
            self._zmp_sub = None
        for key, node in self.nodes.items():
            node.visible = on and key in self.filled
        if on:
            self.drawn.clear()
            self._trail_drawn = -1
            self.update()

    def unload(self) -> None:
        """The subscriptions end with the robot (Load)."""
        for sub in [*self._subs, self._zmp_sub]:
            if sub is not None:
                sub.unregister()
        self._subs, self._zmp_sub = [], None

    def update(self) -> None:
        """Simulation thread, each frame: redraw what changed."""
        if not self.visible:
            return
        for key in ("footsteps", "zmp_plan", "com_plan"):
            msg = self.latest.get(key)
            if msg is None or msg is self.drawn.get(key):
                continue
            self.drawn[key] = msg
            if key == "footsteps":
                points = sole_outlines([(p.position.x, p.position.y, p.position.z,
                                         2 * math.atan2(p.orientation.z, p.orientation.w))
                                        for p in msg.poses])
            else:
                lift = _LIFT if key == "zmp_plan" else 0.0
                poses = msg.poses[::PATH_STRIDE] + msg.poses[-1:]  # the end point kept
                points = polyline([(p.pose.position.x, p.pose.position.y,
                                    p.pose.position.z + lift) for p in poses])
            self._draw(key, points)
        if self.trail and self._received != self._trail_drawn:
            self._trail_drawn = self._received
            self._draw("zmp", polyline([(x, y, z + _LIFT) for x, y, z in list(self.trail)]))
