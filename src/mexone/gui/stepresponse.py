"""The step-response helper: pick a position-controlled joint and a step, press, read the
rise time, overshoot, settling time and steady error next to the plot.

The numbers come from `mexone.control.metrics`, sampled the way `mexone run` samples them
(TrackingRecorder at 200 Hz of sim time), so the page and the command line agree.
"""

from __future__ import annotations

import numpy as np

from mexone.control.metrics import TrackingRecorder, rise_time
from mexone.errors import InputError
from mexone.gui.panels import Panel, register_panel
from mexone.gui.plots import first_joint
from mexone.ranges import STEP_SIZE

__all__ = ["StepResponse", "STEP_WINDOW"]

STEP_WINDOW = 2.0  # s of sim time measured after the step
_STEADY = 0.2  # s at the end of the window averaged for the steady error


@register_panel
class StepResponse(Panel):
    """The Step response folder (see the module's doc); pane 1 of the Plots panel shows the
    stepped joint."""

    name = "step_response"
    order = 5
    period = 1

    def build(self) -> None:
        self.size = 0.5
        self.running: tuple | None = None  # (joint, recorder, t0, start, target)
        self.result: dict | None = None
        self.started = 0.0
        manager = self.lab.manager
        joints = tuple(j for j, c in manager.by_joint().items() if c.holds_position) \
            if manager else ()
        gui = self.server.gui
        with gui.add_folder("Step response", expand_by_default=False):
            if not joints:
                gui.add_markdown("No position controllers.")
                return
            default = first_joint(self.lab)
            self.joint = gui.add_dropdown("Joint", joints,
                                          initial_value=default if default in joints else joints[0])
            self.host.fields.add("Step (rad)", self.size, STEP_SIZE,
                                 lambda v: setattr(self, "size", v))
            gui.add_button("Apply step").on_click(lambda _: self.do(
                lambda: self.start(self.joint.value, self.size)))
            self.view = gui.add_markdown("")

    def start(self, joint: str, size: float) -> None:
        """Simulation thread: command the step now and measure for STEP_WINDOW s."""
        manager = self.lab.manager
        ctrl = manager.by_joint().get(joint) if manager else None
        if ctrl is None or not ctrl.holds_position:
            raise InputError(f"Step response: '{joint}' has no running position controller")
        if self.running:
            self.lab.sim.remove_periodic(self.running[1].timer)
        sim = self.lab.sim
        start = float(ctrl.setpoint[ctrl.joints.index(joint)])
        target = start + size
        lo, hi = ctrl.command_range(ctrl.joints.index(joint))
        if not lo <= target <= hi:
            raise InputError(f"Step response: {joint} to {target:.3g} rad is outside "
                             f"{lo:g} to {hi:g}", hint="a smaller step, or the other sign")
        recorder = TrackingRecorder(sim, manager, history=STEP_WINDOW + 1.0)
        recorder.sample(sim)  # the setpoint before the step
        manager.command(ctrl.name, {joint: target})
        self.started = sim.time
        self.running = (joint, recorder, sim.time, start, target)
        self.result = None
        self.view.content = f"*stepping {joint} by {size:g} rad…*"
        plots = self.host.panel("plots")
        if plots is not None:
            plots.show_joint(joint)

    def update(self) -> None:
        """Once a frame (simulation thread): report when the window is over."""
        if not self.running:
            return
        joint, recorder, t0, start, target = self.running
        sim = self.lab.sim
        if sim.time < t0:  # a reset
            sim.remove_periodic(recorder.timer)
            self.running = None
            self.view.content = "*step interrupted by a reset*"
            return
        if sim.time < t0 + STEP_WINDOW:
            return
        sim.remove_periodic(recorder.timer)
        self.running = None
        m = recorder.metrics()[joint]
        rows = recorder.history(joint)
        t, q = rows[:, 0] - t0, rows[:, 2]
        steady = float(np.mean(np.abs(target - q[t >= t[-1] - _STEADY])))
        rise = rise_time(t, q, start, target)
        self.result = {"joint": joint, "rise_time": rise, "overshoot": m.overshoot,
                       "settling_time": m.settling_time, "steady_error": steady}
        settle = "never (in 2 s)" if m.settling_time is None else f"{m.settling_time:.3f} s"
        self.view.content = (f"**{joint}** {start:.3g} → {target:.3g} rad: rise time (10-90%) "
                             f"{'—' if rise is None else f'{rise:.3f} s'}, overshoot "
                             f"{100 * m.overshoot:.1f}%, settling (2%) {settle}, "
                             f"steady error {steady:.2g} rad")
