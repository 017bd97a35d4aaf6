"""SimHardware: the hardware interface between controllers and the simulated joints.

Every actuated joint has a MuJoCo actuator whose force is affine in the joint state,
    torque = u + kq * q + kv * qdot            (joint space; the gear is folded in here)
so a PD law (kq = -p, kv = -d, u = p * setpoint) runs inside MuJoCo's step, with its damping
integrated implicitly and the URDF effort limit enforced by the actuator's force range.
Controllers only write u (and kq, kv when they start); Python runs per step only for what MuJoCo
cannot do (integral terms, finite-difference derivatives, trajectories, ideal servos).
"""

from __future__ import annotations

import numpy as np

from mexone.errors import InputError
from mexone.physics.simulation import Simulation

__all__ = ["SimHardware"]


class SimHardware:
    def __init__(self, sim: Simulation):
        self.sim = sim
        self.joints = list(sim.compiled.actuated)  # actuator order
        self.index = {name: i for i, name in enumerate(self.joints)}
        sim_index = {name: i for i, name in enumerate(sim.joint_names)}
        self.sim_rows = np.array([sim_index[j] for j in self.joints], dtype=int)
        self.qpos_adr = sim.compiled.qpos_adr[self.sim_rows]
        self.dof_adr = sim.compiled.dof_adr[self.sim_rows]
        self.gear = sim.compiled.gear.copy()
        joints = [sim.robot.joints[j] for j in self.joints]
        self.lower = np.array([j.limit.lower if j.type in ("revolute", "prismatic") else -np.inf
                               for j in joints])
        self.upper = np.array([j.limit.upper if j.type in ("revolute", "prismatic") else np.inf
                               for j in joints])
        self.effort_limit = np.array([j.limit.effort if j.limit and j.limit.effort > 0 else np.inf
                                      for j in joints])
        self.continuous = np.array([j.type == "continuous" for j in joints])
        self.u = np.zeros(len(self.joints))

    def rows(self, names) -> np.ndarray:
        missing = [n for n in names if n not in self.index]
        if missing:
            raise InputError(f"joint {', '.join(missing)} has no transmission, so no controller "
                             "can drive it", hint="add a <transmission> for it to the URDF")
        return np.array([self.index[n] for n in names], dtype=int)

    # ----- state ----------------------------------------------------------------------------
    def position(self, rows: np.ndarray) -> np.ndarray:
        return self.sim.data.qpos[self.qpos_adr[rows]]

    def velocity(self, rows: np.ndarray) -> np.ndarray:
        return self.sim.data.qvel[self.dof_adr[rows]]

    def effort(self, rows: np.ndarray) -> np.ndarray:
        """Joint torque the motors applied in the last step."""
        return self.sim.data.actuator_force[rows] * self.gear[rows]

    # ----- commands -------------------------------------------------------------------------
    def set_feedback(self, rows: np.ndarray, kq: np.ndarray, kv: np.ndarray) -> None:
        """State feedback the actuator applies by itself (joint space)."""
        g2 = self.gear[rows] ** 2
        self.sim.model.actuator_biasprm[rows, 1] = kq / g2
        self.sim.model.actuator_biasprm[rows, 2] = kv / g2

    def set_u(self, rows: np.ndarray, u: np.ndarray) -> None:
        self.u[rows] = u
        self.sim.data.ctrl[rows] = u / self.gear[rows]

    def release(self, rows: np.ndarray) -> None:
        """No controller: the motor applies nothing."""
        self.set_feedback(rows, np.zeros(len(rows)), np.zeros(len(rows)))
        self.set_u(rows, np.zeros(len(rows)))

    def teleport(self, rows: np.ndarray, position: np.ndarray | None, velocity: np.ndarray) -> None:
        """Ideal servo (Gazebo's SetPosition/SetVelocity): write the state, no force."""
        if position is not None:
            self.sim.data.qpos[self.qpos_adr[rows]] = position
        self.sim.data.qvel[self.dof_adr[rows]] = velocity
