"""The worked controllers' figure for docs/worked-controllers.md: each one's experiment, plotted.

    PYTHONPATH=src python examples/controllers/figure.py [out.png]

(default: docs/images/worked-controllers.png)

Every curve is sampled from the simulation each 1 ms step (read between steps, in the
simulation thread); the experiments are those of tests/examples/test_worked_controllers.py.
"""

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from mexone.cli.common import read_pose  # noqa: E402
from mexone.lab import Lab  # noqa: E402
from mexone.motion.push import PUSH_SECONDS  # noqa: E402
from mexone.physics.compile import Spawn  # noqa: E402

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]


def lab_of(name: str, shipped: bool = False) -> Lab:
    """The example's YAML (or Mex-One's own controllers) with the example's pose."""
    folder = HERE / name
    pose = folder / "pose.yaml"
    joints = tuple(read_pose(pose).items()) if pose.exists() else ()
    return Lab.create(controllers=None if shipped else folder / "controllers.yaml",
                      spawn=Spawn(joints=joints))


def record(lab: Lab, seconds: float, value) -> tuple[np.ndarray, np.ndarray]:
    times, values = [], []

    def sample(sim) -> None:
        times.append(sim.time)
        values.append(value(sim))

    lab.sim.add_periodic(lab.sim.timestep, sample)
    lab.sim.run(seconds)
    return np.array(times), np.array(values)


def joint(lab: Lab, name: str):
    adr = int(lab.sim.model.joint(name).qposadr[0])
    return lambda sim: sim.data.qpos[adr]


def main() -> None:
    default = ROOT / "docs" / "images" / "worked-controllers.png"
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else default
    fig, axes = plt.subplots(2, 2, figsize=(10, 7))

    ax = axes[0, 0]
    for label, gravity in (("gravity compensation", 1.0), ("damping alone", 0.0)):
        lab = lab_of("01_gravity_float")
        lab.manager.controllers["gravity_float"].set_param("gravity", gravity)
        lab.sim.apply_joint_effort("r_shoulder_pitch", 0.5, duration=0.2, start=0.5)
        q = joint(lab, "r_shoulder_pitch")
        q0 = q(lab.sim)
        t, v = record(lab, 1.5, lambda sim, q=q, q0=q0: 1e3 * (q(sim) - q0))
        ax.plot(t, v, label=label)
    ax.axvspan(0.5, 0.7, color="k", alpha=0.1, label="0.5 N m push")
    ax.set(title="1. the right arm floats, then is pushed", xlabel="t (s)",
           ylabel="shoulder pitch moved (mrad)", ylim=(-50, 450))

    ax = axes[0, 1]
    sys.path.insert(0, str(HERE / "02_computed_torque_move"))
    from computed_torque_move import minimum_jerk

    q0 = np.array(list(read_pose(HERE / "02_computed_torque_move" / "pose.yaml").values()))
    move = np.array([-0.8, -0.9])  # the YAML's move_shoulder, move_elbow, in 1 s

    def reference(t: float) -> np.ndarray:
        return q0 + minimum_jerk(t, 1.0)[0] * move

    for label, shipped in (("computed torque", False), ("shipped PID", True)):
        lab = lab_of("02_computed_torque_move", shipped)
        if shipped:
            def command(sim, lab=lab):
                q = reference(sim.time)
                lab.manager.command("r_shoulder_pitch_position_controller", [q[0]])
                lab.manager.command("r_elbow_position_controller", [q[1]])
            lab.sim.add_periodic(lab.sim.timestep, command)
        elbow = joint(lab, "r_elbow")
        t, v = record(lab, 1.5, lambda sim, e=elbow: 1e3 * (e(sim) - reference(sim.time)[1]))
        ax.plot(t, v, label=label)
    ax.set(title="2. a 1 s minimum-jerk move, then hold", xlabel="t (s)",
           ylabel="elbow error (mrad)")

    ax = axes[1, 0]
    lab = lab_of("03_hand_circle")
    sim = lab.sim
    body = sim.body_id("r_forearm")
    point = np.array([0.0, 0.0, -0.17])

    def hand(s):
        return s.data.xpos[body] + s.data.xmat[body].reshape(3, 3) @ point

    start = hand(sim)
    _, path = record(lab, 4.0, lambda s: 1e3 * (hand(s) - start))
    sys.path.insert(0, str(HERE / "03_hand_circle"))
    from hand_circle import circle

    ring = np.array([1e3 * (circle(t, start, 0.04, 0.5)[0] - start) for t in np.linspace(0, 4, 400)])
    ax.plot(ring[:, 1], ring[:, 2], "k--", label="the circle")
    ax.plot(path[:, 1], path[:, 2], label="the hand, two turns")
    ax.set(title="3. the right hand draws a 4 cm circle", xlabel="y (mm)", ylabel="z (mm)",
           aspect="equal")

    ax = axes[1, 1]
    for label, shipped in (("LQR on the sway", False), ("PD alone", True)):
        lab = lab_of("04_lqr_sway", shipped)
        lab.sim.run(0.5)
        y0 = lab.sim.data.subtree_com[1][1]
        lab.sim.apply_wrench("torso", (0.0, 1.0 / PUSH_SECONDS, 0.0), duration=PUSH_SECONDS)
        t, v = record(lab, 1.5, lambda s, y0=y0: 1e3 * (s.data.subtree_com[1][1] - y0))
        ax.plot(t, v, label=label)
    ax.set(title="4. 1 N s sideways push at the torso", xlabel="t (s)",
           ylabel="centre of mass, y (mm)")

    for ax in axes.flat:
        ax.grid(alpha=0.3)
        ax.legend()
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
