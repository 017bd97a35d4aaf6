"""LQR balance of Mex-One on ONE foot from the full linearisation (issue 32, worked example 6a).

MuJoCo's LQR tutorial recipe, done with mexone.design and python-control:
1. the operating point: a pose on the left foot whose centre of mass is over the sole (the
   left arm out and the left leg's roll searched until `operating_point` leaves no torque on the
   base), the torques u0 that hold it by inverse dynamics with the foot-height search;
2. A, B from `linearize` (mjd_transitionFD through the contacts, effort inputs: every joint's
   PD off, the motors as torque sources through the hardware's effort interface);
3. Q from the COM-minus-foot Jacobian (keep the centre of mass over the foot) plus joint costs,
   R on the torques, K from `control.dlqr`;
4. u = u0 - K dx at every 1 ms step, dx = state_deviation of the measured state.

    PYTHONPATH=src python examples/control_design/one_foot_lqr.py [--figure lqr.png]

prints the acceptance numbers (stand, noise, u0 alone, pushes against the shipped PD) and saves
a figure of the centre of mass over the foot.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import control
import mujoco
import numpy as np

from mexone.control.hardware import SimHardware
from mexone.design import OperatingPoint, linearize, operating_point, state_deviation
from mexone.dynamics import Dynamics
from mexone.lab import Lab
from mexone.motion.push import PUSH_SECONDS, apply_wrench
from mexone.physics.compile import Spawn
from mexone.physics.monitor import has_fallen

__all__ = ["one_foot_pose", "Design", "design", "LqrLoop", "Run", "run", "survives",
           "largest_push", "smoothed_noise", "noise_std", "lqr", "setup", "figure",
           "BALANCE_JOINTS", "DIRECTIONS", "main"]

LIFT = {"r_hip_pitch": -0.9, "r_knee": 1.6, "r_hip_roll": -0.15,  # the right foot up, clear
        "l_shoulder_roll": 1.5}  # of the left leg; the left arm out
BALANCE_JOINTS = ("l_hip_yaw", "l_hip_roll", "l_hip_pitch", "l_knee", "l_ankle_pitch",
                  "l_ankle_roll", "waist_yaw")  # the tutorial's "balance dofs": stance leg, waist
DIRECTIONS = {"left": (0.0, 1.0, 0.0), "right": (0.0, -1.0, 0.0),
              "forward": (1.0, 0.0, 0.0), "backward": (-1.0, 0.0, 0.0)}
PUSH_LINK = "pelvis"


def one_foot_pose(lab: Lab, iterations: int = 6) -> OperatingPoint:
    """The operating point on the left foot: the right foot lifted, the left arm out, the left
    leg's roll (hip and ankle opposite: the sole flat) and pitch searched by Newton's method
    until the inverse dynamics leaves no torque on the base (the COM over the sole)."""

    def pose(v: np.ndarray) -> dict[str, float]:
        roll, pitch = float(v[0]), float(v[1])
        return {**LIFT, "l_hip_roll": -roll, "l_ankle_roll": roll, "l_ankle_pitch": pitch,
                "l_hip_pitch": -pitch}

    def residual(v: np.ndarray) -> np.ndarray:
        return operating_point(lab, pose(v), support="left").residual[3:5]

    v = np.array([0.13, 0.0])
    for _ in range(iterations):
        r = residual(v)
        if np.abs(r).max() < 1e-4:
            break
        jac = np.column_stack([(residual(v + e) - r) / 1e-3 for e in 1e-3 * np.eye(2)])
        v = v - np.linalg.solve(jac, r)
    return operating_point(lab, pose(v), support="left")


@dataclass
class Design:
    """The LQR: the model `sys` (with `sys.linearization`), gain K, the point, closed-loop
    poles, and how long linearising took (s)."""

    point: OperatingPoint
    sys: control.StateSpace
    K: np.ndarray
    poles: np.ndarray
    linearize_seconds: float


def design(lab: Lab, point: OperatingPoint, balance_cost: float = 1000.0,
           balance_joint_cost: float = 3.0, other_joint_cost: float = 0.3,
           base_cost: float = 0.01, velocity_cost: float = 0.01, r: float = 0.05) -> Design:
    """The tutorial's Q (COM over the foot, joint costs) and R = r I, K from control.dlqr;
    unlike the tutorial, small costs on the base and the velocities (the Riccati solve refuses
    undetected modes on the unit circle)."""
    start = time.perf_counter()
    sys = linearize(lab, point=point)
    seconds = time.perf_counter() - start
    nv = lab.sim.model.nv
    dyn = Dynamics(lab.sim.model, _data_at(lab.sim.model, point.qpos), lab.sim.compiled.bodies,
                   lab.sim.compiled.bodies.values())
    com_minus_foot = dyn.com_jacobian() - dyn.jacobian("l_foot")[:3]
    q_balance = com_minus_foot[:2].T @ com_minus_foot[:2]  # horizontal COM over the foot
    balance = dyn.dofs(list(BALANCE_JOINTS))
    joint_weights = np.full(nv, other_joint_cost)
    joint_weights[:6] = base_cost  # the tutorial has 0: the base slides and turns freely
    # on friction alone (modes on the unit circle), which Riccati needs seen
    joint_weights[balance] = balance_joint_cost
    q_pos = balance_cost * q_balance + np.diag(joint_weights)
    q = np.block([[q_pos, np.zeros((nv, nv))],
                  [np.zeros((nv, nv)), velocity_cost * np.eye(nv)]])
    # method: SciPy's solver even where slycot is installed (SLICOT's refuses this model)
    gain, _, poles = control.dlqr(sys.A, sys.B, q, r * np.eye(sys.ninputs), method="scipy")
    return Design(point, sys, np.asarray(gain), np.asarray(poles), seconds)


def _data_at(model: mujoco.MjModel, qpos: np.ndarray) -> mujoco.MjData:
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_forward(model, data)
    return data


def smoothed_noise(steps: int, n: int, std: np.ndarray, seed: int = 0,
                   width: float = 0.8, dt: float = 0.001) -> np.ndarray:
    """The tutorial's control noise: white noise through a Gaussian kernel `width` s wide,
    normalised to unit variance, times `std` per channel. (steps, n)."""
    rng = np.random.default_rng(seed)
    white = rng.standard_normal((steps, n))
    k = max(1, int(width / dt))
    kernel = np.exp(-0.5 * np.linspace(-3, 3, k) ** 2)
    kernel /= np.linalg.norm(kernel)
    out = np.column_stack([np.convolve(white[:, i], kernel, mode="same") for i in range(n)])
    return out * std


@dataclass
class Run:
    """What one simulated run gave: time (s), COM-minus-foot (m, x y), whether and when it fell,
    the wall and CPU seconds, and a log of what an observer needs (u, IMU, encoders, true dx)."""

    t: list[float] = field(default_factory=list)
    com_offset: list[np.ndarray] = field(default_factory=list)
    fell_at: float | None = None
    wall: float = 0.0
    cpu: float = 0.0
    sim_time: float = 0.0
    log: dict[str, list[np.ndarray]] = field(default_factory=dict)

    @property
    def fell(self) -> bool:
        return self.fell_at is not None


class LqrLoop:
    """u = u0 - K dx (+ noise) written every step through the hardware's effort interface (the
    lab's SimHardware: the shipped controllers stopped, each joint's PD released, the motors'
    feed-forward torque alone, clamped to the URDF effort limits as the manager does)."""

    def __init__(self, lab: Lab, d: Design, feedback: bool = True,
                 noise: np.ndarray | None = None, noise_from: float = 0.0, log: bool = False):
        self.lab, self.d, self.feedback = lab, d, feedback
        self.noise, self.noise_from, self.log = noise, noise_from, log
        manager = lab.manager
        manager.switch(stop=[n for n, c in manager.controllers.items() if c.running])
        self.hardware: SimHardware = manager.hw
        self.rows = self.hardware.rows([n.split(":")[0] for n in d.sys.input_labels])
        self.hardware.release(self.rows)
        self.limit = self.hardware.effort_limit[self.rows]
        self.u0 = d.sys.linearization.u0
        self.step = 0
        self.records: dict[str, list[np.ndarray]] = {"u": [], "dx": [], "gyro": [], "acc": []}
        model = lab.sim.model
        self.gyro = _sensor_slice(model, "imu/gyro")
        self.acc = _sensor_slice(model, "imu/acc")

    def __call__(self, sim) -> None:
        dx = state_deviation(self.d.sys, sim.data.qpos, sim.data.qvel)
        u = self.u0 - self.d.K @ dx if self.feedback else self.u0.copy()
        if self.noise is not None and sim.time >= self.noise_from:
            k = min(self.step, len(self.noise) - 1)
            u = u + self.noise[k]
            self.step += 1
        if self.log:
            self.records["u"].append(u.copy())
            self.records["dx"].append(dx)
            self.records["gyro"].append(sim.data.sensordata[self.gyro].copy())
            self.records["acc"].append(sim.data.sensordata[self.acc].copy())
        self.hardware.command.effort[self.rows] = np.clip(u, -self.limit, self.limit)
        self.hardware.write()


def _sensor_slice(model: mujoco.MjModel, name: str) -> slice:
    s = model.sensor(name).id
    adr = int(model.sensor_adr[s])
    return slice(adr, adr + int(model.sensor_dim[s]))


def _fresh_lab(point: OperatingPoint, controllers: bool) -> Lab:
    """A headless lab with the robot at rest at the point (the shipped PD, if asked, holding the
    point's pose as its setpoints)."""
    lab = Lab.create(spawn=Spawn(joints=tuple(_joint_angles(point).items())))
    data = lab.sim.data
    data.qpos[:] = point.qpos
    data.qvel[:] = 0.0
    mujoco.mj_forward(lab.sim.model, data)
    return lab


def _joint_angles(point: OperatingPoint) -> dict[str, float]:
    return {name: float(point.qpos[adr]) for name, adr in _JOINT_ADR.items()}


_JOINT_ADR: dict[str, int] = {}


def run(point: OperatingPoint, controller: str | Callable[[Lab], Callable] = "pd",
        duration: float = 10.0, push: tuple[str, float] | None = None, push_at: float = 1.0,
        sample: float = 0.01) -> Run:
    """One headless run from the point: `controller` "pd" (the shipped controllers holding the
    pose) or a factory lab -> per-step callback (an LqrLoop); an optional push (direction,
    impulse N s over 0.1 s on the pelvis) at `push_at`. Stops at a fall."""
    lab = _fresh_lab(point, controllers=controller == "pd")
    sim = lab.sim
    if controller != "pd":
        loop = controller(lab)
        sim.add_periodic(sim.model.opt.timestep, loop)
        loop(sim)
    start_height = sim.base_height
    if push is not None:
        force = np.asarray(DIRECTIONS[push[0]]) * push[1] / PUSH_SECONDS
        timer = None

        def kick(s) -> None:
            s.remove_periodic(timer)
            apply_wrench(s, PUSH_LINK, force, duration=PUSH_SECONDS)
        timer = sim.add_periodic(push_at, kick)
    out = Run()
    dyn = Dynamics.live(sim)

    def watch(s) -> None:
        dyn.refresh()
        out.t.append(s.time)
        out.com_offset.append((dyn.com() - dyn.pose("l_foot")[0])[:2])
        if out.fell_at is None and has_fallen(s, start_height):
            out.fell_at = s.time

    wall, cpu = time.perf_counter(), time.process_time()
    out.sim_time = sim.run(duration, on_tick=watch, tick=sample, until=lambda: out.fell)
    out.wall, out.cpu = time.perf_counter() - wall, time.process_time() - cpu
    if controller != "pd":
        out.log = loop.records

    return out


def lqr(d: Design, **kwargs) -> Callable[[Lab], LqrLoop]:
    """A run()'s controller factory for the design (kwargs: LqrLoop's)."""
    return lambda lab: LqrLoop(lab, d, **kwargs)


def survives(point: OperatingPoint, controller, direction: str, impulse: float,
             settle: float = 1.0, after: float = 2.0) -> bool:
    """Standing `after` s after a push of `impulse` N s on the pelvis in `direction`."""
    return not run(point, controller, settle + after, push=(direction, impulse),
                   push_at=settle, sample=0.05).fell


def largest_push(point: OperatingPoint, controller, direction: str, high: float = 12.0,
                 resolution: float = 0.1) -> float:
    """The largest impulse survived, by bisection between 0 and `high` to `resolution` N s."""
    low = 0.0
    if survives(point, controller, direction, high):
        return high
    while high - low > resolution:
        mid = 0.5 * (low + high)
        if survives(point, controller, direction, mid):
            low = mid
        else:
            high = mid
    return low


def noise_std(d: Design, balance: float = 0.01, other: float = 0.08) -> np.ndarray:
    """The noise's std per input, on the controls as they are (joint torques, N m): `balance` on
    BALANCE_JOINTS, `other` else. (As fractions of the effort limits, as the tutorial's
    normalised controls would read, the noise is 40-100x larger: pass scale=effort limits.)"""
    names = [n.split(":")[0] for n in d.sys.input_labels]
    return np.array([balance if n in BALANCE_JOINTS else other for n in names])


_EFFORT_LIMITS: dict[str, float] = {}


def setup(lab: Lab) -> None:
    """Record the robot's joint addresses and effort limits (for fresh labs and the noise)."""
    model = lab.sim.model
    for j in lab.sim.robot.actuated_joints:
        _JOINT_ADR[j.name] = int(model.jnt_qposadr[model.joint(j.name).id])
        _EFFORT_LIMITS[j.name] = float(j.limit.effort)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--figure", default="lqr_balance.png")
    parser.add_argument("--resolution", type=float, default=0.1, help="push bisection, N s")
    parser.add_argument("--no-push", action="store_true")
    args = parser.parse_args()
    lab = Lab.create()
    setup(lab)
    point = one_foot_pose(lab)
    d = design(lab, point)

    print(f"operating point: contacts {point.contacts}, residual torque "
          f"{np.abs(point.residual[3:]).max():.1e} N m; linearised in "
          f"{1e3 * d.linearize_seconds:.1f} ms ({d.sys.nstates} states, {d.sys.ninputs} inputs);"
          f" largest closed-loop |z| {np.abs(d.poles).max():.6f}")
    steps = 22_000
    noise = smoothed_noise(steps, d.sys.ninputs, noise_std(d))
    both = run(point, lqr(d, noise=noise, noise_from=10.0), duration=22.0)
    print(f"LQR: stands 10 s then 12 s with noise: fell at {both.fell_at} "
          f"(RTF {both.sim_time / both.cpu:.2f} per CPU second)")
    alone = run(point, lqr(d, feedback=False), duration=10.0)
    print(f"u0 alone: fell at {alone.fell_at} s")
    if not args.no_push:
        for name in DIRECTIONS:
            pd = largest_push(point, "pd", name, resolution=args.resolution)
            ours = largest_push(point, lqr(d), name, resolution=args.resolution)
            print(f"push {name:<8}: LQR {ours:.2f} N s, shipped PD {pd:.2f} N s")
    figure(both, alone, args.figure)


def figure(both: Run, alone: Run, path: str) -> None:
    """The centre of mass over the foot (mm) in time: LQR with noise from 10 s, u0 alone."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 3.2))
    offsets = 1e3 * np.array(both.com_offset)
    ax.plot(both.t, offsets[:, 0], label="LQR: COM - foot, x")
    ax.plot(both.t, offsets[:, 1], label="LQR: COM - foot, y")
    off = 1e3 * np.array(alone.com_offset)
    ax.plot(alone.t, off[:, 1], "--", label="u0 alone, y (falls)")
    ax.axvline(10.0, color="grey", lw=0.8)
    ax.set_xlabel("time (s); control noise from 10 s")
    ax.set_ylabel("mm")
    ax.set_ylim(-60, 60)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    print(f"figure: {path}")


if __name__ == "__main__":
    main()
