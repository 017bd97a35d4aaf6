"""IK drag handles: viser transform controls on the hands (position), the feet (pose) and a gaze
target; moving one solves whole-body IK (mexone.motion: the other feet held, the COM over them) from the
robot's measured pose and sends the joint positions to the position controllers, as the
Joints sliders do. The IK runs in a worker thread on its own model copy; only the simulation
thread reads the state (a snapshot) and publishes the commands.
"""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING

import mujoco
import numpy as np
import viser

from mexone.gui.panels import Panel, register_panel
from mexone.lab import Lab

if TYPE_CHECKING:  # mink and its QP solvers only when a student turns the handles on
    from mexone.motion.ik import WholeBodyIK

__all__ = ["IkHandles", "IkHandlesPanel", "FRAMES", "POSED", "GAZE"]

FRAMES = ("l_hand", "r_hand", "l_foot", "r_foot")
POSED = ("l_foot", "r_foot")  # handles that turn too; a hand's orientation is left to the IK
GAZE = "gaze"  # a point the head's camera looks at
SOLVE_ITERATIONS = 150  # IK steps per drop (converge stops earlier when it settles)
ANSWER_SECONDS = 10.0  # a simulation thread silent this long has stopped: the worker ends


class IkHandles:
    def __init__(self, server: viser.ViserServer, lab: Lab, do):
        self.server, self.lab, self.do = server, lab, do
        self.ik: WholeBodyIK | None = None
        self.lock = threading.Lock()  # the IK's own data: the worker's and show()'s
        self.handles: dict[str, object] = {}
        self.latest: tuple[str, np.ndarray, np.ndarray] | None = None
        self.wake = threading.Event()
        self.closing = threading.Event()
        self._answered = threading.Event()  # the simulation thread handed over its pose
        with server.gui.add_folder("IK handles", expand_by_default=False):
            box = server.gui.add_checkbox("Show handles", False,
                                          hint="drag a hand, a foot or the gaze target: "
                                               "whole-body IK moves the robot there")
            box.on_update(lambda e: self.do(lambda: self.show(bool(e.target.value))))
            self.status = server.gui.add_markdown("")
        self.thread = threading.Thread(target=self._work, daemon=True, name="ik handles")
        self.thread.start()

    def close(self, join: float = 5.0) -> None:
        """Stop the worker (the page stops, or Load replaces the robot): it ends after the solve
        in progress, if any, without sending it. From the simulation thread pass join=0: the
        worker may be waiting for that thread."""
        self.closing.set()
        self._answered.set()
        self.wake.set()
        if join > 0 and threading.current_thread() is not self.thread:
            self.thread.join(timeout=join)

    def show(self, on: bool) -> None:
        """Add (at the frames' present poses) or remove the handles (simulation thread)."""
        for handle in self.handles.values():
            handle.remove()
        self.handles.clear()
        if not on or self.lab.manager is None:
            return
        with self.lock:
            if self.ik is None:
                from mexone.motion.ik import WholeBodyIK

                self.ik = WholeBodyIK.for_sim(self.lab.sim)
            self.ik.reset(self.lab.sim.data.qpos.copy())
            poses = {frame: self.ik.pose(frame) for frame in FRAMES}
        for frame, (position, rotation) in poses.items():
            quat = np.zeros(4)
            mujoco.mju_mat2Quat(quat, rotation.ravel())
            self._add(frame, position, quat, rotations=frame in POSED)
        self._add(GAZE, np.array([1.0, 0.0, 0.3]), np.array([1.0, 0.0, 0.0, 0.0]), rotations=False)

    def _add(self, name: str, position, wxyz, rotations: bool) -> None:
        handle = self.server.scene.add_transform_controls(
            f"/ik_handles/{name}", scale=0.12, position=tuple(position), wxyz=tuple(wxyz),
            disable_rotations=not rotations)
        handle.on_update(lambda e, n=name: self.drag(n, e.target.position, e.target.wxyz))
        self.handles[name] = handle

    def drag(self, frame: str, position, wxyz) -> None:
        """A handle moved (viser's thread): solve for the latest pose, dropping stale ones."""
        self.latest = (frame, np.asarray(position, dtype=float), np.asarray(wxyz, dtype=float))
        self.wake.set()

    def _work(self) -> None:
        while True:
            self.wake.wait()
            self.wake.clear()
            if self.closing.is_set():
                return
            job, self.latest = self.latest, None
            if job is None or self.ik is None:
                continue
            qpos = self._measured()
            if qpos is None:
                return
            joints, error = self.solve(qpos, *job)
            if self.closing.is_set():
                return
            self.do(lambda j=joints, e=error: self.send(j, e))

    def _measured(self) -> np.ndarray | None:
        """The robot's pose from the simulation thread, or None once closing (a stopped
        simulation thread never answers: close() wakes this wait)."""
        sim, box = self.lab.sim, []
        answered = self._answered
        answered.clear()
        if self.closing.is_set():  # close() set it before the clear above
            return None

        def snapshot() -> None:
            box.append(sim.data.qpos.copy())
            answered.set()
        sim.work.put(snapshot)
        answered.wait(timeout=ANSWER_SECONDS)
        return None if self.closing.is_set() or not box else box[0]

    def solve(self, qpos: np.ndarray, frame: str, position: np.ndarray, wxyz: np.ndarray):
        """Joint positions putting `frame` at the pose (or the camera looking at `position`)."""
        with self.lock:
            self.ik.reset(qpos)
            if frame == GAZE:
                self.ik.look_at(position)
            elif frame in POSED:
                rotation = np.zeros(9)
                mujoco.mju_quat2Mat(rotation, wxyz / np.linalg.norm(wxyz))
                self.ik.set_target(frame, position, rotation.reshape(3, 3))
            else:  # the arms have too few joints for every orientation at every position
                self.ik.set_target(frame, position)
            self.ik.converge(iterations=SOLVE_ITERATIONS)
            error = None if frame == GAZE else self.ik.error(frame)
            return self.ik.joint_positions(), error

    def send(self, joints: dict[str, float], error=None) -> None:
        """Command every position controller's joints (simulation thread)."""
        manager = self.lab.manager
        for ctrl in manager.controllers.values():
            if ctrl.holds_position:
                command = {j: joints[j] for j in ctrl.joints if j in joints}
                if command:
                    manager.command(ctrl.name, command)
        self.status.content = "" if error is None else f"IK: {error} from the handle"


@register_panel
class IkHandlesPanel(Panel):
    """The IK handles folder: an IkHandles (and its worker thread) per robot loaded."""

    name = "ik_handles"
    order = 92
    handles: IkHandles | None = None

    def build(self) -> None:
        self.handles = IkHandles(self.server, self.lab, self.do)

    def unload(self) -> None:
        if self.handles is not None:
            self.handles.close(join=0)  # the simulation thread, which its worker may await

    def stop(self) -> None:
        if self.handles is not None:
            self.handles.close()
