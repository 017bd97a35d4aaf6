'''`mexone controllers new NAME --part PART`: a student's own walking part, runnable as written.

Each kind is a short, complete implementation of one part's interface (a different method from
the shipped one, so there is something to compare), and the YAML is Mex-One's walking stack
(robots/mex_one/config/walking.yaml) with that one part's `type:` replaced by it: the robot
walks with it from the start, and the student improves it from there.
'''

from __future__ import annotations

import re

from mexone.control.skeleton import class_name
from mexone.errors import InputError, warn_renamed
from mexone.robots import mex_one

__all__ = ["PARTS", "walking_skeleton_files"]

_HEADER = '''"""{cls}: my own {what} for Mex-One's walking stack (docs/walking-stack.md).

It replaces the `{part}` controller of walking.yaml; the other parts read what it exports.
Edit, save, press Reload on the page (or rerun): no other part needs touching.
"""

import math

import numpy as np

from mexone.control import Param, PythonController
from mexone.walking.body import FEET, SOLE_OFFSET, matrix_to_quat, quat_to_matrix, yaw_of
from mexone.walking.footsteps import Steps
'''

_FOOTSTEPS = '''

class {cls}(PythonController):
    """Straight ahead at a fixed rhythm: step k (right foot first) lifts at start + k period and
    lands `step_length` ahead of the other foot. Exports `steps` (mexone.walking.footsteps.Steps:
    the feet on the ground, then the next Steps.K steps as rows of foot, x, y, z, yaw, pitch,
    roll, t_lift, t_land)."""

    exports = {{"steps": Steps.LENGTH}}
    step_length = Param(0.06, low=0.0, high=0.2, doc="forward per step", unit="m")
    period = Param(0.4, low=0.2, high=2.0, doc="s from one lift to the next", unit="s")
    single_support = Param(0.3, low=0.1, high=2.0, doc="s a foot is in the air", unit="s")
    start = Param(1.0, low=0.0, high=60.0, doc="s after activation the first step lifts", unit="s")

    def activate(self, state):
        self.start_feet = []
        for name in FEET:
            p, r = self.dynamics.pose(name)
            sole = p + r @ SOLE_OFFSET
            self.start_feet.append(np.array([sole[0], sole[1], 0.0, yaw_of(r)]))
        self.t0 = state.time + self.start

    def step(self, k):
        """Step k's row: foot, x, y, z, yaw, pitch, roll, t_lift, t_land."""
        foot = 1 if k % 2 == 0 else 0
        x = self.start_feet[foot][0] + (k + 1) * self.step_length
        lift = self.t0 + k * self.period
        return np.array([foot, x, self.start_feet[foot][1], 0.0, 0.0, 0.0, 0.0, lift,
                         lift + self.single_support])

    def update(self, state, t, dt):
        done = max(0, math.floor((t - self.t0) / self.period) + 1)  # steps lifted so far
        ground = [f.copy() for f in self.start_feet]
        for k in range(done):
            row = self.step(k)
            if row[8] <= t:  # landed: that foot stands there now
                ground[int(row[0])][:2] = row[1:3]
        rows = [self.step(k) for k in range(max(0, done - 1), done + Steps.K)
                if self.step(k)[8] > t]
        self.exports["steps"][:] = Steps.pack(np.array(ground), rows)
'''

_COM = '''

class {cls}(PythonController):
    """The divergent component of motion (Englsberger et al. 2015): xi = c + dc / omega must end
    each step on the next foothold, so its reference runs backwards from the last planned step,
    xi_ref(t) = p + exp(omega (t - t_land)) (xi_end - p) about the standing foot p; the ZMP
    command, kept inside the standing sole, gives the COM's acceleration omega^2 (c - zmp).
    As written the ZMP follows the plan only (p_ref): the DCM's feedback, which steers xi back
    to xi_ref, is yours to add (course exercise 11); without it the robot falls at its first
    steps. Reads `steps`; exports `com` (9: position, velocity, acceleration) and `landing`
    (5; NaN: the steps as planned)."""

    inputs = {{"steps": Steps.LENGTH}}
    exports = {{"com": 9, "landing": 5}}
    height = Param(0.54, low=0.2, high=1.0, doc="COM above the soles", unit="m")
    half_length = Param(0.06, low=0.0, high=0.1, doc="ZMP limit along the sole", unit="m")
    half_width = Param(0.025, low=0.0, high=0.05, doc="ZMP limit across the sole", unit="m")

    def update(self, state, t, dt):
        steps = state.inputs["steps"]
        out = self.exports
        out["landing"][:] = np.nan
        dyn = self.dynamics
        c, v = dyn.com(), dyn.com_jacobian() @ state.all_dq
        omega = math.sqrt(9.81 / self.height)
        xi = c[:2] + v[:2] / omega
        feet, rows = Steps.feet(steps), Steps.rows(steps)
        ahead = [row for row in rows if row[8] > t]
        if not ahead:  # standing: the DCM over the feet's middle
            p_ref = xi_ref = (feet[0, :2] + feet[1, :2]) / 2
        else:
            # backwards from the last step: xi at each landing, about the foot standing then
            stands = [feet[1 - int(ahead[0][0]), :2]] + [row[1:3] for row in ahead]
            xi_end = (stands[-1] + stands[-2]) / 2
            for i in range(len(ahead) - 1, 0, -1):
                span = ahead[i][8] - ahead[i - 1][8]
                xi_end = stands[i] + math.exp(-omega * span) * (xi_end - stands[i])
            p_ref = stands[0]
            xi_ref = p_ref + math.exp(omega * (t - ahead[0][8])) * (xi_end - p_ref)
        # yours to add: the DCM's feedback. xi (measured) drifts off xi_ref exponentially; a
        # ZMP command that leads the plan by the DCM's error brings it back
        zmp = p_ref
        # the ZMP stays on the ground's support: the standing sole, or both soles' box
        swing = Steps.swing_now(steps, t)
        down = [f for f in range(2) if swing is None or int(swing[0]) != f]
        size = np.array([self.half_length, self.half_width])
        low = np.min([feet[f, :2] for f in down], axis=0) - size
        high = np.max([feet[f, :2] for f in down], axis=0) + size
        zmp = np.clip(zmp, low, high)
        acc = omega**2 * (c[:2] - zmp)
        ground = (feet[0, 2] + feet[1, 2]) / 2
        out["com"][:] = [c[0], c[1], ground + self.height, v[0], v[1], 0.0, acc[0], acc[1], 0.0]
'''

_ESTIMATOR = '''

class {cls}(PythonController):
    """Leg odometry without a filter: the attitude from the IMU, the base's velocity from the
    standing feet (a foot on the ground does not move: v = -J_foot dq with the base's linear
    columns left out), its position from where the standing foot touched down. Exports `base`
    (13: position, quaternion w x y z, velocity (world), angular velocity (base frame)) and
    `contact` (2)."""

    exports = {{"base": 13, "contact": 2}}
    contact_force = Param(20.0, low=0.0, high=1e4, doc="normal force that counts as contact", unit="N")

    def activate(self, state):
        self.position = np.array(state.all_q[:3], dtype=float)
        self.touched = [None, None]

    def update(self, state, t, dt):
        imu = state.sensors["imu"]  # on the pelvis, its axes the pelvis's
        x, y, z, w = imu.orientation
        rotation = quat_to_matrix(np.array([w, x, y, z]))
        omega = np.array(imu.angular_velocity)
        dyn = self.dynamics  # the encoders' kinematics; only the feet relative to the base are used
        base_true, base_rot = dyn.pose("pelvis")
        velocities, positions, contact = [], [], np.zeros(2)
        for f, name in enumerate(FEET):
            if state.sensors[name + "_contact"].force[2] < self.contact_force:
                self.touched[f] = None
                continue
            contact[f] = 1.0
            # the foot relative to the base, in the base's frame, turned by the IMU's attitude
            p_foot, _ = dyn.pose(name)
            offset = rotation @ base_rot.T @ (p_foot - base_true)
            if self.touched[f] is None:
                self.touched[f] = self.position + offset
            positions.append(self.touched[f] - offset)
            jac = dyn.jacobian(name)[:3]
            dq = np.array(state.all_dq)
            dq[:3] = 0.0
            dq[3:6] = omega
            velocities.append(-(rotation @ base_rot.T @ (jac @ dq)))
        velocity = np.mean(velocities, axis=0) if velocities else np.zeros(3)
        self.position = np.mean(positions, axis=0) if positions else self.position + velocity * dt
        out = self.exports["base"]
        out[:3], out[3:7], out[7:10], out[10:] = self.position, matrix_to_quat(rotation), velocity, omega
        self.exports["contact"][:] = contact
'''

_WHOLE_BODY = '''
from mexone.walking.footsteps import swing_point
from mexone.walking.wbc import Foot, Task, WholeBodyQP, sole_corners


class {cls}(PythonController):
    """Weighted whole-body control with mexone's QP (mexone.walking.wbc.WholeBodyQP: the
    floating base's equations, friction pyramids, torque limits) and my own tasks: the COM's
    acceleration from `com`, the swing foot on a minimum-jerk arc to its landing (`landing` when
    the COM planner moved it), a level pelvis and a posture. Torques through the effort
    interface."""

    inputs = {{"steps": Steps.LENGTH, "com": 9, "landing": 5, "base": 13}}
    optional_inputs = ("landing", "base")
    exports = {{"status": 2}}
    w_com = Param(100.0, low=0.0, high=1e6, doc="COM task weight")
    w_foot = Param(10.0, low=0.0, high=1e6, doc="swing foot task weight")
    w_pelvis = Param(10.0, low=0.0, high=1e6, doc="level pelvis weight")
    w_posture = Param(0.05, low=0.0, high=1e6, doc="posture weight")
    kp = Param(60.0, low=0.0, high=1e4, doc="COM stiffness", unit="1/s^2")
    kd = Param(15.0, low=0.0, high=1e3, doc="COM damping", unit="1/s")

    def configure(self):
        model = self.dynamics.model
        self.qp = WholeBodyQP(model.nv, self.dofs, self.effort_limits)
        self.damping = model.dof_damping[self.dofs]  # the gearboxes' losses, given back
        self.corners = sole_corners(0.16, 0.08)
        self.pose = {{"l_hip_pitch": -0.35, "l_knee": 0.7, "l_ankle_pitch": -0.35,
                     "r_hip_pitch": -0.35, "r_knee": 0.7, "r_ankle_pitch": -0.35}}
        self.posture = np.array([self.pose.get(j, 0.0) for j in self.joints])
        self.lifted = {{}}

    def update(self, state, t, dt):
        dyn, dq = self.dynamics, state.all_dq
        steps, ref = state.inputs["steps"], state.inputs["com"]
        if not np.isfinite(ref[0]):
            return None
        swing = Steps.swing_now(steps, t) if np.isfinite(steps[0]) else None
        feet, tasks = [], []
        for f, name in enumerate(FEET):
            p, r = dyn.pose(name)
            centre = p + r @ SOLE_OFFSET
            jac, drift = dyn.jacobian(name, centre), dyn.jacobian_dot_qdot(name, centre)
            up = swing is not None and int(swing[0]) == f
            feet.append(Foot(jac, drift, r, self.corners, not up, target=-20.0 * (jac @ dq)))
            if not up:
                self.lifted.pop(f, None)
                continue
            start = self.lifted.setdefault(f, np.array([*centre, yaw_of(r)]))
            landing = state.inputs.get("landing")  # the COM planner may move it (a push)
            moved = landing is not None and np.isfinite(landing[0]) and int(landing[0]) == f
            target = landing[1:5] if moved else swing[1:5]
            pos, vel, acc = swing_point(start, target, swing[7], swing[8], t, 0.04)
            a = np.zeros(6)
            a[:3] = acc[:3] + 300.0 * (pos[:3] - centre) + 35.0 * (vel[:3] - jac[:3] @ dq)
            a[3:] = -35.0 * (jac[3:] @ dq) + 300.0 * np.cross(r[:, 0], [math.cos(pos[3]),
                                                                    math.sin(pos[3]), 0.0]) \\
                + 300.0 * np.cross(r[:, 2], [0.0, 0.0, 1.0])
            tasks.append(Task(jac, drift, a, self.w_foot))
        jc = dyn.com_jacobian()
        acc = ref[6:9] + self.kp * (ref[:3] - dyn.com()) + self.kd * (ref[3:6] - jc @ dq)
        tasks.append(Task(jc, np.zeros(3), acc, self.w_com))
        _, pelvis = dyn.pose("pelvis")
        jp = dyn.jacobian("pelvis")[3:]
        level = 200.0 * np.cross(pelvis[:, 2], [0.0, 0.0, 1.0]) - 30.0 * (jp @ dq)
        level[2] = -30.0 * (jp[2] @ dq)  # the heading is free: it follows the feet
        tasks.append(Task(jp, dyn.jacobian_dot_qdot("pelvis")[3:], level, self.w_pelvis))
        rows = np.zeros((len(self.dofs), len(dq)))
        rows[np.arange(len(self.dofs)), self.dofs] = 1.0
        tasks.append(Task(rows, np.zeros(len(self.dofs)),
                          50.0 * (self.posture - state.q) - 10.0 * state.dq, self.w_posture))
        solution = self.qp.solve(dyn.mass_matrix(), dyn.bias(), tasks, feet)
        self.exports["status"][:] = (1.0, 0.0)
        return solution.tau + self.damping * state.dq
'''

# part -> (template, what it is, the walking.yaml controller it replaces)
PARTS = {
    "footsteps": (_FOOTSTEPS, "footstep planner", "footsteps"),
    "com_planner": (_COM, "centre-of-mass planner", "com_planner"),
    "estimator": (_ESTIMATOR, "state estimator", "estimator"),
    "whole_body": (_WHOLE_BODY, "whole-body controller", "whole_body"),
}


def walking_skeleton_files(name: str, kind: str, yaml_name: str = "controllers.yaml") -> dict[str, str]:
    """{file name: text}: `<stem>.py` (the walking stack's part `kind`, one of PARTS) and the
    walking stack's YAML with that part replaced by it."""
    if kind not in PARTS:
        raise InputError(f"unknown part '{kind}'", hint="parts: arm, " + ", ".join(PARTS))
    stem, cls = class_name(name)
    template, what, part = PARTS[kind]
    code = _HEADER.format(cls=cls, what=what, part=part) + template.format(cls=cls)
    yaml_text = mex_one.walking_path().read_text()
    pattern = re.compile(rf"(\n  {part}:[^\n]*\n    type: )\S+")
    yaml_text, count = pattern.subn(rf"\g<1>{stem}/{cls}", yaml_text)
    assert count == 1, part
    if kind in ("footsteps", "com_planner"):  # these read no estimate: the base binding goes
        yaml_text = _unbind_base(yaml_text, part)
    header = (f"# Mex-One's walking stack with its {what} replaced by {cls} ({stem}.py, next to "
              f"this file).\n#   mexone sim --controllers {yaml_name}\n")
    return {f"{stem}.py": code, yaml_name: header + yaml_text}


def _unbind_base(text: str, part: str) -> str:
    """walking.yaml with `part`'s binding of the estimator's base taken out."""
    out, inside = [], False
    for line in text.split("\n"):
        if line.startswith("  ") and not line.startswith("   "):
            inside = line.strip().startswith(f"{part}:")
        if inside and line.strip() == "inputs: {base: estimator/base}":
            continue
        out.append(line.replace(", base: estimator/base}", "}") if inside else line)
    return "\n".join(out)


def __getattr__(name: str) -> object:
    if name == "KINDS":  # renamed: a walking part is not a controller's kind
        warn_renamed("mexone.walking.skeletons.KINDS", "PARTS")
        return PARTS
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
