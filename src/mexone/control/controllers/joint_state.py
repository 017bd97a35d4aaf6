"""joint_state_controller: every actuated joint, alphabetical, stamped with sim time, on
/<ns>/joint_states, published when last + 1/publish_rate <= t (50 Hz by default)."""

from __future__ import annotations

import numpy as np

from mexone.bus.msgs import Header, JointState, Time
from mexone.control.controllers.base import ControllerContext, ControllerInterface, register
from mexone.control.spec import ControllerSpec
from mexone.physics.simulation import Periodic, Simulation

__all__ = ["JointStateController", "DEFAULT_RATE"]

DEFAULT_RATE = 50.0


@register("joint_state_controller/JointStateController", "")
class JointStateController(ControllerInterface):
    kind = "state"
    sliders = False
    drives_joints = False

    def __init__(self, spec: ControllerSpec, ctx: ControllerContext) -> None:
        super().__init__(spec, ctx)
        hw = ctx.hw
        self.names = sorted(hw.joints)
        order = np.array([hw.index[j] for j in self.names], dtype=int)
        self._qpos, self._dofs = hw.qpos_adr[order], hw.dof_adr[order]
        self.period = 1.0 / (spec.publish_rate or DEFAULT_RATE)
        self.topic = f"{ctx.namespace}/joint_states"
        self.seq = 0
        self.timer: Periodic | None = None
        self._watching = False
        ctx.bus.advertise(self.topic, JointState)

    def starting(self, t: float) -> None:
        self.running = True
        if not self._watching:  # publish only while someone listens (a timer costs a pause)
            self._watching = True
            self.ctx.bus.on_subscribers(self.topic, lambda _n: self._listeners_changed())
        self._listeners_changed()

    def stopping(self) -> None:
        self.running = False
        self._listeners_changed()

    def _listeners_changed(self) -> None:
        wanted = self.running and self.ctx.bus.wanted(self.topic)
        if wanted and self.timer is None:
            self.timer = self.ctx.sim.add_periodic(self.period, self.publish)
        elif not wanted and self.timer is not None:
            self.ctx.sim.remove_periodic(self.timer)
            self.timer = None

    def publish(self, sim: Simulation) -> None:
        bus = self.ctx.bus
        if not bus.wanted(self.topic):
            return
        self.seq += 1
        data = sim.data
        msg = JointState(Header(self.seq, Time.from_nsec(sim.time_ns), ""), list(self.names),
                         data.qpos[self._qpos].tolist(), data.qvel[self._dofs].tolist(),
                         data.qfrc_actuator[self._dofs].tolist())
        bus.publish(self.topic, msg)
