"""The joints' dry friction in the analysis (issue 38 item 1): what `linearize` leaves out.

MuJoCo's joint friction (URDF <dynamics friction>, `frictionloss`) is a soft constraint: each
step it asks for the force f = -(b v + a) / (A + R) that stops the joint (v its velocity, a its
acceleration without the friction, A the joint's inverse inertia, R = (1 - d) / d A0 the
constraint's softness: d its impedance solimp[0], A0 the inverse inertia at the model's
reference pose, dof_invweight0; b = 2 / (solimp[1] solref[0]) its reference damping) and clamps
it to the Coulomb level Fc. Slowly pushed, a joint creeps as through a damper of c = b / R:
below the stiction band v_s = Fc / c the friction is viscous, above it a constant Fc against
the motion. `FrictionModel` holds Fc, c and v_s per joint (Fc from the
model, or what `mexone identify` fitted: `with_identified`), and gives three views of it:

- `predict`: the linear closed loop with this friction in it, step by step (a Lur'e system):
  what the robot does, to a few per cent, where the linear model alone misses by tens;
- `describing_function(V)`: the equivalent viscous damping at a velocity amplitude V (c inside
  the band, falling as 4 Fc / (pi V) far above it);
- `bound`: the friction as a bounded disturbance, no larger than Fc: the largest difference it can make
  to each state (the l1 norm of the closed loop's response to it) and the dead band, the
  offset it can hold a joint at against the controller's stiffness.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, cast

import control
import mujoco
import numpy as np

from mexone.errors import InputError
from mexone.ranges import number_text

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from mexone.design.deploy import SystemDesign, _Deployed
    from mexone.lab import Lab

__all__ = ["FrictionModel", "friction_model"]


@dataclass(frozen=True)
class FrictionModel:
    """Per joint of a plant's inputs: `coulomb` (N m), `damping` c (N m s/rad, the creep),
    `band` v_s (rad/s), and MuJoCo's constraint parameters (`softness` R, `reference` b,
    `inverse_inertia` A at the point, per `step` s) the prediction uses."""

    joints: tuple[str, ...]
    coulomb: np.ndarray
    softness: np.ndarray
    reference: np.ndarray
    inverse_inertia: np.ndarray
    step: float
    source: str = "model"

    @property
    def damping(self) -> np.ndarray:
        """Viscous damping per joint (N m s/rad) the smoothed Coulomb friction acts as near zero speed."""
        return self.reference / self.softness

    @property
    def band(self) -> np.ndarray:
        """Speed per joint (rad/s) below which the friction acts as damping (Coulomb over damping)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.damping > 0, self.coulomb / self.damping, 0.0)

    def force(self, velocity: np.ndarray, acceleration: np.ndarray) -> np.ndarray:
        """The friction torque MuJoCo applies over a step from `velocity` with `acceleration`
        (what the joint would do without it)."""
        soft = -(self.reference * velocity + acceleration) / (self.inverse_inertia + self.softness)
        return np.clip(soft, -self.coulomb, self.coulomb)

    def describing_function(self, amplitude: float | np.ndarray) -> np.ndarray:
        """The equivalent viscous damping (N m s/rad) per joint at velocity amplitude V: the
        first harmonic of c v clamped to +-Fc."""
        v = np.broadcast_to(np.asarray(amplitude, dtype=float), self.coulomb.shape)
        c, band = self.damping, self.band
        ratio = np.clip(np.divide(band, v, out=np.ones_like(v), where=v > 0), 0.0, 1.0)
        return c * (2 / np.pi) * (np.arcsin(ratio) + ratio * np.sqrt(1 - ratio**2))

    def with_identified(self, path: str | Path) -> FrictionModel:
        """Fc from what `mexone identify` fitted (its identify.json, or the folder it wrote):
        `frictionloss` per joint; the others keep the model's."""
        path = Path(path)
        if path.is_dir():
            path = path / "identify.json"
        try:
            params = json.loads(path.read_text())["params"]
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise InputError(f"{path}: not an identify.json ({str(exc).splitlines()[0]})",
                             file=str(path), hint="give the folder `mexone identify -o` wrote") from None
        fitted = params.get("frictionloss") or {}
        if not isinstance(fitted, dict) or not fitted:
            raise InputError(f"{path}: no frictionloss was identified",
                             hint="mexone identify ... --params frictionloss")
        coulomb = self.coulomb.copy()
        for joint, value in fitted.items():
            if joint in self.joints:
                coulomb[self.joints.index(joint)] = float(value)
        return replace(self, coulomb=coulomb, source=str(path))

    # ----- with a closed loop ------------------------------------------------------------------
    def predict(self, controller: _Deployed, plant: control.StateSpace,
                deviation: Mapping[str, float] | ArrayLike | None = None, duration: float = 1.0,
                reference: Mapping[str, float] | ArrayLike | None = None) -> np.ndarray:
        """The linear closed loop of a deployed controller with this friction in it, from the
        point plus `deviation` (as compare takes it): len x nx of the plant's states."""
        from mexone.design.check import _vector, closed_loop

        sys = closed_loop(controller, plant)
        labels = list(plant.state_labels)
        dx0 = _vector(deviation, labels, "deviation")
        ref_labels = labels if sys.ninputs == plant.nstates \
            else list(cast("SystemDesign", controller.design).inputs)  # a gain's loop takes states
        r = _vector(reference, ref_labels, "reference")
        a, b = np.asarray(sys.A), np.asarray(sys.B) @ r
        cols, qrows, vrows = self._columns(plant)
        x = np.concatenate([dx0, np.zeros(sys.nstates - plant.nstates)])
        steps = max(2, round(duration / float(plant.dt)))
        out = np.zeros((steps, plant.nstates))
        h = float(plant.dt)
        for k in range(steps):
            out[k] = x[:plant.nstates]
            free = a @ x + b
            v = x[vrows]
            f = self.force(v, (free[vrows] - v) / h)
            x = free + cols @ f
        return out

    def bound(self, controller: _Deployed, plant: control.StateSpace
              ) -> tuple[np.ndarray, np.ndarray]:
        """(largest difference per plant state the friction can make, up to Fc on every joint
        at once: the sum over time of the impulse response's magnitude times Fc; the dead band
        per joint: Fc over the loop's static stiffness)."""
        from mexone.design.check import closed_loop

        sys = closed_loop(controller, plant)
        a = np.asarray(sys.A)
        cols, qrows, _ = self._columns(plant)
        cols = np.vstack([cols, np.zeros((sys.nstates - plant.nstates, cols.shape[1]))]) \
            if cols.shape[0] < sys.nstates else cols
        total = np.zeros(plant.nstates)
        response = cols * self.coulomb[None, :]
        for _ in range(20_000):
            total += np.abs(response[:plant.nstates]).sum(axis=1)
            response = a @ response
            if np.abs(response).max() < 1e-12 * max(1.0, total.max()):
                break
        static = control.dcgain(control.ss(a, cols, np.eye(a.shape[0])[qrows], 0, plant.dt))
        stiffness = 1.0 / np.abs(np.diag(np.atleast_2d(static)))
        return total, self.coulomb / stiffness

    def _columns(self, plant: control.StateSpace) -> tuple[np.ndarray, list[int], list[int]]:
        inputs = [label.rpartition(":")[0] for label in plant.input_labels]
        states = list(plant.state_labels)
        missing = [j for j in self.joints if j not in inputs]
        if missing:
            raise InputError(f"the friction model's joint {missing[0]!r} is not an input of the "
                             "plant", hint="friction_model(lab, plant) for this plant")
        cols = np.asarray(plant.B)[:, [inputs.index(j) for j in self.joints]]
        qrows = [states.index(f"{j}:q") for j in self.joints]
        vrows = [states.index(f"{j}:dq") for j in self.joints]
        return cols, qrows, vrows


def friction_model(lab: Lab, plant: control.StateSpace, joints: Sequence[str] | None = None) -> FrictionModel:
    """The dry friction of the plant's input joints (or `joints`), from the lab's model: Fc
    (frictionloss), MuJoCo's constraint parameters, and the joints' inverse inertia per step
    from the plant's own B (its velocity row, so the model's inertia and implicit damping)."""
    model = lab.sim.model
    inputs = [label.rpartition(":")[0] for label in plant.input_labels]
    joints = tuple(inputs if joints is None else joints)
    states = list(plant.state_labels)
    step = float(plant.dt)
    coulomb, imp, ref, inv = [], [], [], []
    b = np.asarray(plant.B)
    for joint in joints:
        if joint not in inputs:
            raise InputError(f"{joint!r} is not an input of the plant",
                             hint="inputs: " + ", ".join(inputs))
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, joint)
        dof = int(model.jnt_dofadr[jid])
        solref, solimp = model.dof_solref[dof], model.dof_solimp[dof]
        timeconst = max(float(solref[0]), 2 * model.opt.timestep) if solref[0] > 0 else 0.02
        coulomb.append(float(model.dof_frictionloss[dof]))
        d = min(max(float(solimp[0]), 1e-4), 0.9999)
        imp.append((1 - d) / d * float(model.dof_invweight0[dof]))
        ref.append(2.0 / (float(solimp[1]) * timeconst))
        inv.append(b[states.index(f"{joint}:dq"), inputs.index(joint)] / step)
    if step > model.opt.timestep * 1.5:
        raise InputError(f"the plant's period {number_text(step)} s is longer than the physics "
                         f"step {number_text(model.opt.timestep)} s: friction acts every step",
                         hint="linearize at period=None (the time step) for the friction model")
    return FrictionModel(joints, np.array(coulomb), np.array(imp), np.array(ref), np.array(inv),
                         step)

