"""Test helpers: record a bag from a Mex-One (on a stand or standing, with any URDF and YAML),
make the nominal and "truth" models, and rewrite a bag the way a real robot's would look --
ROS 1, joints in a shuffled order, position noise, jittered stamps -- or without some topics."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rosbags.rosbag1 import Writer

from mexone.description.loader import load_model
from mexone.identify.patch import Change, patch_urdf
from mexone.lab import Lab
from mexone.physics.compile import CompileOptions, Spawn
from mexone.record.bag import BagRecorder, typestore_for
from mexone.record.reader import FLOAT64, MULTI, TRAJECTORY, read_bag
from mexone.robots import mex_one
from mexone.routines.runner import RoutineRunner

# Servo-class rotor inertia through the gearbox (kg m^2): the nominal model's armature. Mex-One
# ships without any (Gazebo has none), so "changed by known factors" needs a starting value.
ARMATURE = {"leg": 0.01, "arm": 0.005, "head": 0.002}
FACTORS = {  # truth = nominal x factor, cycling over the joints: 0.5x to 3x, different per joint
    "damping": (0.5, 1.5, 2.0, 3.0, 0.7, 2.5, 1.3),
    "frictionloss": (2.0, 0.5, 3.0, 1.5, 0.6, 2.5, 1.2),
    "armature": (1.5, 3.0, 0.5, 2.0, 2.5, 0.7, 1.8),
}
TORSO_MASS_FACTOR = 1.2


def _group(joint: str) -> str:
    if joint.startswith("neck"):
        return "head"
    return "arm" if "shoulder" in joint or "elbow" in joint else "leg"


@dataclass
class Models:
    nominal: Path
    truth: Path
    controllers: Path
    values: dict[str, float]  # unknown name -> true value


def make_models(folder: Path, joint_state_rate: float | None = None,
                joints: tuple[str, ...] | None = None, torso: bool = True) -> Models:
    """Mex-One with servo armature (nominal), and the truth: the damping, friction and armature
    of every joint (or of `joints`) times a known factor, the torso 20% heavier (unless not
    `torso`). Optionally a controllers YAML whose joint_state_controller publishes faster (what
    a real driver does: 500 Hz and up)."""
    text = Path(mex_one.urdf_path()).read_text()
    robot = load_model(mex_one.urdf_path())
    every = [j.name for j in robot.moving_joints]
    nominal = patch_urdf(text, [Change("armature", j, "", 0.0, ARMATURE[_group(j)])
                                for j in every], "tests: servo armature")
    (folder / "nominal.urdf").write_text(nominal)
    reread = load_model(folder / "nominal.urdf")
    changes, values = [], {}
    for i, joint in enumerate(every):
        if joints is not None and joint not in joints:
            continue
        dyn = reread.joint_dynamics(joint)
        for kind, attr in (("damping", "damping"), ("frictionloss", "friction"),
                           ("armature", "armature")):
            old = getattr(dyn, attr)
            new = old * FACTORS[kind][i % len(FACTORS[kind])]
            changes.append(Change(kind, joint, "", old, new))
            values[f"{kind}:{joint}"] = new
    if torso:
        mass = reread.links["torso"].inertial.mass
        changes.append(Change("mass", "torso", "", mass, TORSO_MASS_FACTOR * mass))
        values["mass:torso"] = TORSO_MASS_FACTOR * mass
    (folder / "truth.urdf").write_text(patch_urdf(nominal, changes, "tests: truth"))
    (folder / "truth.json").write_text(json.dumps(values, indent=1))
    controllers = Path(mex_one.controllers_path())
    if joint_state_rate is not None:
        controllers = folder / "controllers.yaml"
        controllers.write_text(Path(mex_one.controllers_path()).read_text().replace(
            "publish_rate: 50.0", f"publish_rate: {joint_state_rate}"))
    return Models(folder / "nominal.urdf", folder / "truth.urdf", controllers, values)


def record(out: Path, model: Path | None, controllers: Path | None, base: str, seconds: float,
           seed: int = 0) -> Path:
    """The shipped excitation routine on a Mex-One (hung 0.3 m up on a stand, or standing)."""
    fixed = base == "fixed"
    lab = Lab.create(model, controllers, options=CompileOptions(fixed_base=fixed),
                     spawn=Spawn((0.0, 0.0, 0.3 if fixed else 0.0)))
    runner = RoutineRunner(lab, "excitation", {"_base": "fixed" if fixed else "standing",
                                               "_seed": seed})
    recorder = BagRecorder(lab, out)
    try:
        runner.run(seconds)
    finally:
        recorder.close()
    assert runner.error is None, runner.error
    return out


def rewrite_ros1(src: Path, dst: Path, *, noise: float = 0.0, jitter: float = 0.0,
                 shuffle: bool = False, drop: tuple[str, ...] = (), rename: dict | None = None,
                 base_link: str = "pelvis", seed: int = 0) -> Path:
    """src as a ROS 1 bag a real driver might have written: positions + N(0, noise) rad, header
    stamps + N(0, jitter) s (the driver's clock), receive times late by |N(0, jitter)| s (the
    network, first in first out), joint names shuffled per message, topics whose name contains a
    string of `drop` left out, joint names renamed."""
    rng = np.random.default_rng(seed)

    def late(times: np.ndarray) -> np.ndarray:
        return np.maximum.accumulate(times + np.abs(rng.normal(0, jitter, len(times))))

    contents = read_bag(src, frames=(base_link,))
    store = typestore_for(True)
    T = store.types
    rename = rename or {}

    def time(t: float):
        t = max(t, 1e-6)
        return T["builtin_interfaces/msg/Time"](sec=int(t), nanosec=int(round((t % 1) * 1e9)) % 10**9)

    def header(seq: int, t: float, frame: str = ""):
        return T["std_msgs/msg/Header"](seq=seq, stamp=time(t), frame_id=frame)

    out: list[tuple[float, str, str, object]] = []
    arrivals = late(np.array([s.t for s in contents.states]))
    for seq, (s, received) in enumerate(zip(contents.states, arrivals, strict=True)):
        if any(d in s.topic for d in drop):
            continue
        order = rng.permutation(len(s.names)) if shuffle else np.arange(len(s.names))
        stamp = (s.stamp if s.stamp is not None else s.t) + rng.normal(0, jitter)
        pos = s.position + rng.normal(0, noise, len(s.position))
        msg = T["sensor_msgs/msg/JointState"](
            header=header(seq, stamp), name=[rename.get(s.names[i], s.names[i]) for i in order],
            position=pos[order], velocity=s.velocity[order] if len(s.velocity) else s.velocity,
            effort=s.effort[order] if len(s.effort) else s.effort)
        out.append((received, s.topic, "sensor_msgs/msg/JointState", msg))
    for topic, msgs in contents.commands.items():
        if any(d in topic for d in drop):
            continue
        for m, received in zip(msgs, late(np.array([m.t for m in msgs])), strict=True):
            if m.msgtype == FLOAT64:
                msg = T[FLOAT64](data=float(m.values[0]))
            elif m.msgtype == MULTI:
                layout = T["std_msgs/msg/MultiArrayLayout"](dim=[], data_offset=0)
                msg = T[MULTI](layout=layout, data=m.values)
            else:
                assert m.msgtype == TRAJECTORY
                points = [T["trajectory_msgs/msg/JointTrajectoryPoint"](
                    positions=p.positions, velocities=p.velocities, accelerations=np.zeros(0),
                    effort=np.zeros(0), time_from_start=T["builtin_interfaces/msg/Duration"](
                        sec=int(p.time_from_start), nanosec=int(round((p.time_from_start % 1) * 1e9))))
                    for p in m.points]
                msg = T[TRAJECTORY](header=header(0, m.stamp or 0.0), joint_names=list(m.joint_names),
                                    points=points)
            out.append((received, topic, m.msgtype, msg))
    if not any("tf" in d for d in drop):
        for tf in contents.transforms:
            vec = T["geometry_msgs/msg/Vector3"](x=tf.xyz[0], y=tf.xyz[1], z=tf.xyz[2])
            w, x, y, z = tf.quat
            quat = T["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w)
            stamped = T["geometry_msgs/msg/TransformStamped"](
                header=header(0, tf.t, tf.parent), child_frame_id=tf.child,
                transform=T["geometry_msgs/msg/Transform"](translation=vec, rotation=quat))
            out.append((tf.t, "/tf", "tf2_msgs/msg/TFMessage", T["tf2_msgs/msg/TFMessage"](
                transforms=[stamped])))
    out.sort(key=lambda item: item[0])
    with Writer(dst) as writer:
        connections = {}
        for t, topic, msgtype, msg in out:
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, msgtype, typestore=store)
            writer.write(connections[topic], int(max(t, 1e-6) * 1e9),
                         store.serialize_ros1(msg, msgtype))
    return dst
