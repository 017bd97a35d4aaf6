"""The Move tool (Gazebo's translate/rotate modes): drag the floating base to a new pose.

A viser transform gizmo sits on the robot's root link. The page's drags arrive in viser's
threads; each is handed to the simulation thread, which places the base there with
`Simulation.set_free_body` (zero velocity, joints untouched). While a drag lasts the base is
held at the gizmo's pose every frame, paused or running, as a hand would hold it; let go and
physics takes over. Between drags the gizmo follows the robot.
"""

from __future__ import annotations

import mujoco
import numpy as np
import viser

from mexone.errors import InputError
from mexone.lab import Lab

__all__ = ["MoveTool"]


class MoveTool:
    def __init__(self, server: viser.ViserServer, lab: Lab, do):
        self.server, self.lab, self.do = server, lab, do
        self.holding: tuple[np.ndarray, np.ndarray] | None = None  # the pose a drag holds
        gui = server.gui
        self.enabled = gui.add_checkbox("Move the robot", False,
                                        hint="a gizmo on the floating base: drag to place it "
                                             "(paused or running)")
        self.enabled.on_update(lambda e: self.do(lambda: self.enable(bool(e.target.value))))
        self.gizmo = server.scene.add_transform_controls("/tools/move", scale=0.35, depth_test=False,
                                                        visible=False)  # seen through links
        self.gizmo.on_update(self._dragged)

    @property
    def base(self) -> str:
        return self.lab.sim.robot.base_link

    def enable(self, on: bool) -> None:
        """Simulation thread: a robot welded to the world cannot be moved (said, not hidden)."""
        if on:
            sim = self.lab.sim
            body = sim.compiled.bodies.get(self.base)
            if body is None or sim.model.body_jntadr[body] < 0 or \
                    sim.model.jnt_type[sim.model.body_jntadr[body]] != mujoco.mjtJoint.mjJNT_FREE:
                self.enabled.value = False
                raise InputError(f"Move: '{self.base}' is fixed to the world, so it cannot be moved",
                                 hint="only a floating robot can be dragged")
        self.gizmo.visible = on
        self.holding = None
        self.follow()

    async def _dragged(self, event) -> None:
        """async: viser keeps a drag's start/update/end in order only for async callbacks
        (an update handled after the end would hold the robot for ever); it only queues."""
        if event.client is None:
            return
        pose = (np.asarray(event.target.position, dtype=float),
                np.asarray(event.target.wxyz, dtype=float))
        phase = getattr(event, "phase", "update")
        self.do(lambda: self.place(*pose, hold=phase != "end"))

    def place(self, position, wxyz, hold: bool = True) -> None:
        """Simulation thread: the base to this pose (world, w x y z), at rest."""
        if not self.enabled.value:
            return
        self.lab.sim.set_free_body(self.base, position, wxyz)
        self.holding = (np.asarray(position, dtype=float), np.asarray(wxyz, dtype=float)) \
            if hold else None

    def update(self) -> None:
        """Once a frame: hold the base while dragged, else keep the gizmo on the robot."""
        if not self.enabled.value:
            return
        if self.holding is not None:
            self.lab.sim.set_free_body(self.base, *self.holding)
        else:
            self.follow()

    def follow(self) -> None:
        sim = self.lab.sim
        body = sim.compiled.bodies.get(self.base)
        if body is None:
            return
        position, wxyz = sim.data.xpos[body], sim.data.xquat[body]
        if np.allclose(self.gizmo.position, position, atol=1e-4) and \
                np.allclose(self.gizmo.wxyz, wxyz, atol=1e-4):
            return  # a resting robot sends the page nothing
        with self.server.atomic():
            self.gizmo.position = tuple(position)
            self.gizmo.wxyz = tuple(wxyz)
