"""`mexone bench`: what mexone costs and how fast it can go, all measured in one run.

Rows (each a ratio or a rate measured side by side in the same process run, so they hold on a
noisy machine)::

  overhead       Mex-One with 21 PD controllers and joint states at 50 Hz vs bare mj_step on
                 the very same compiled model, controls and actuator settings; and the same
                 with the full PID (I terms with clamps on all 21 joints)
  pybullet       the same URDF in PyBullet (extra [peers]): 1 ms steps, 21 joints under its
                 POSITION_CONTROL motors; step-time ratio, and the no-controller fall side by side
  sensors        the PD row again with every light sensor read (pelvis IMU and both ankle FT at
                 100 Hz, sole contacts at 50 Hz), then also COM/ZMP/support polygon at 50 Hz;
                 and the Kinect's cost per frame (RGB; depth image + point cloud) offscreen
  sensor states  the five light sensors read by a 100 Hz controller (`SensorSuite.states`) and
                 broadcast to one subscriber each, vs the PD-only run (issue 25: <= 1.15)
  cold start     process start to the first simulated millisecond of `mexone sim --headless`
  parallel       robot-seconds per wall second with 1..N workers: mujoco.rollout threads (the PD
                 controllers run inside MuJoCo, so the controlled robot rolls out in C) and
                 processes each running a full mexone Lab
  Python ctrl    a student's PD at 1 kHz: the framework's cost per update in the lab's process
                 (a class handed over), and in a worker process (a class the YAML names): the
                 round trip, the lab's CPU per update, the real-time factor kept, start, memory
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import mujoco
import numpy as np

from mexone import signals
from mexone.bus.msgs import JointState
from mexone.control import load_control_config
from mexone.lab import Lab, cached_lab
from mexone.physics.monitor import RunMonitor
from mexone.robots import mex_one

__all__ = ["BenchReport", "run_bench", "format_report"]


@dataclass
class BenchReport:
    machine: str
    sim_seconds: float
    overhead: dict = field(default_factory=dict)
    overhead_full_pid: dict = field(default_factory=dict)
    overhead_sensors: dict = field(default_factory=dict)
    overhead_balance: dict = field(default_factory=dict)
    sensor_states: dict = field(default_factory=dict)
    camera: dict = field(default_factory=dict)
    pybullet: dict | None = None
    cold_start_s: float | None = None
    parallel: list[dict] = field(default_factory=list)
    python_controller: dict = field(default_factory=dict)

    def as_json(self) -> dict:
        return asdict(self)


def _best(fn, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        signals.check()  # a signal stops the bench between two timed runs (signals.Stop)
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def with_integral_terms(lab: Lab) -> None:
    """Give every position controller an I term that acts (i and a clamp), keeping p and d."""
    manager = lab.manager
    for ctrl in manager.controllers.values():
        if ctrl.holds_position and ctrl.tunable:
            manager.set_gains(ctrl.name, [replace(g, i=0.5 * g.p, i_clamp_min=-2.0, i_clamp_max=2.0)
                                          for g in ctrl.gains])
    lab.sim.step(1)  # the update writes the new gains into the actuators


def read_light_sensors(lab: Lab, balance_topics: bool = False) -> None:
    """Subscribe to every sensor that is not a camera, so all of them publish; and to the
    COM/ZMP/support polygon topics if asked."""
    for sensor in lab.sensors.sensors.values():
        for output in sensor.outputs:
            if not output.heavy:
                lab.bus.subscribe(output.topic, output.type, lambda msg: None)
    if not balance_topics:
        return
    balance = lab.sensors.balance
    for key, topic in balance.topics.items():
        lab.bus.subscribe(topic, balance.types[key], lambda msg: None)


LIGHT_SENSOR_RATE = 100.0  # Hz of the controller reading the sensors' states in `sensor_states`


def read_states_at(lab: Lab, rate: float = LIGHT_SENSOR_RATE) -> None:
    """A controller's read phase at `rate`: every light sensor's state, every field touched."""
    states = lab.sensors.states
    imus = [n for n, k in states.kinds().items() if k == "imu"]
    fts = [n for n, k in states.kinds().items() if k == "force_torque"]
    contacts = [n for n, k in states.kinds().items() if k == "contact"]

    taken: list = []

    def read(_sim) -> None:  # every field, as a balance controller takes them
        taken.clear()
        for name in imus:
            imu = states[name]
            taken.extend((imu.orientation, imu.angular_velocity, imu.linear_acceleration))
        for name in fts:
            ft = states[name]
            taken.extend((ft.force, ft.torque))
        for name in contacts:
            contact = states[name]
            taken.extend((contact.in_contact, contact.force))

    lab.sim.add_periodic(1.0 / rate, read)


def sensor_states(sim_seconds: float, repeats: int) -> dict:
    """Mex-One on its PD controllers with joint states at 50 Hz (the PD-only run), against the
    same with the five light sensors read by a 100 Hz controller and broadcast to one
    subscriber each (IMU, both ankle FT at 100 Hz; both sole contacts at 50 Hz). Paired runs,
    CPU time of this thread, as `overhead`."""
    plain, read = Lab.create(), Lab.create()
    read_light_sensors(read)
    read_states_at(read)
    runs = {}
    for key, lab in (("pd", plain), ("sensors", read)):
        lab.bus.subscribe(f"{lab.namespace}/joint_states", JointState, lambda msg: None)
        steps = round(sim_seconds / lab.sim.timestep)

        def run(sim=lab.sim, steps=steps) -> float:
            sim.reset()
            start = time.thread_time()
            sim.step(steps)
            return time.thread_time() - start

        runs[key] = run
    pds, reads = [], []
    for k in range(max(8, 4 * repeats)):
        signals.check()
        if k % 2:
            pds.append(runs["pd"]())
            reads.append(runs["sensors"]())
        else:
            reads.append(runs["sensors"]())
            pds.append(runs["pd"]())
    ratio = float(np.median(np.array(reads) / np.array(pds)))
    return {"pd_s_per_sim_s": float(np.median(pds)) / sim_seconds,
            "sensors_s_per_sim_s": float(np.median(reads)) / sim_seconds, "ratio": ratio}


def overhead(sim_seconds: float, repeats: int, full_pid: bool = False,
             sensors: bool = False, balance: bool = False) -> dict:
    """mexone's stepping vs bare mj_step on the same model, data layout and controls.

    Measured in pairs, bare and mexone back to back in alternating order, in CPU time of this
    thread: a shared VM's other tenants slow whole seconds down, so only paired ratios hold."""
    lab = Lab.create()
    if full_pid:
        with_integral_terms(lab)
    if sensors:
        read_light_sensors(lab, balance)
    lab.bus.subscribe(f"{lab.namespace}/joint_states", JointState, lambda msg: None)  # 50 Hz, read
    sim = lab.sim
    model = sim.model
    data = mujoco.MjData(model)
    steps = round(sim_seconds / model.opt.timestep)
    ctrl = sim.data.ctrl.copy()
    clock = time.thread_time

    def bare() -> float:
        mujoco.mj_resetData(model, data)
        data.ctrl[:] = ctrl
        start = clock()
        mujoco.mj_step(model, data, steps)
        return clock() - start

    def ours() -> float:
        sim.reset()
        start = clock()
        sim.step(steps)
        return clock() - start

    bares, ourses = [], []
    for k in range(max(8, 4 * repeats)):
        signals.check()
        first, second = (bare, ours) if k % 2 else (ours, bare)
        a, b = first(), second()
        bares.append(a if first is bare else b)
        ourses.append(b if first is bare else a)
    ratio = float(np.median(np.array(ourses) / np.array(bares)))
    return {"bare_s_per_sim_s": float(np.median(bares)) / sim_seconds,
            "mexone_s_per_sim_s": float(np.median(ourses)) / sim_seconds, "ratio": ratio}


_BENCH_CONTROLLER = """\
from mexone.control import Param, PythonController


class MyPd(PythonController):
    kp = Param(20.0, low=0.0, high=1e4)
    kd = Param(1.0, low=0.0, high=1e3)

    def activate(self, state):
        self.q0 = state.q.copy()

    def update(self, state, t, dt):
        return self.kp * (self.q0 - state.q) - self.kd * state.dq
"""


def python_controller_cost(sim_seconds: float, repeats: int) -> dict:
    """What the framework costs per update of a student's PythonController (a PD on Mex-One's
    left arm at 1 kHz): the manager's read -> update -> write per update (timed inside a run),
    minus the same update() called in a bare loop on the same State, plus what waking the loop
    every physics step costs the simulation (a do-nothing control's extra time per step). The
    physics itself is left out: it is the same with any controller."""
    with tempfile.TemporaryDirectory() as folder:  # the class handed over: in this process
        yaml_path = _bench_controller(Path(folder))
        namespace: dict = {"__name__": "mexone_bench_controller"}
        exec(compile(_BENCH_CONTROLLER, str(Path(folder) / "my_pd.py"), "exec"), namespace)
        lab = Lab.create(controllers=load_control_config(
            yaml_path, classes={"my_pd/MyPd": namespace["MyPd"]}))
    sim, manager = lab.sim, lab.manager
    runner = manager.controllers["my_pd_controller"]
    steps = round(sim_seconds / sim.timestep)
    clock = time.thread_time  # CPU time of this thread: a loaded machine's other tenants excluded
    real_update = manager.update
    spent = [0.0]

    def timed_update(s) -> None:
        start = clock()
        real_update(s)
        spent[0] += clock() - start

    def loop() -> float:
        sim.reset()
        spent[0], before = 0.0, runner.updates
        manager.update = timed_update  # shadows the method for this run
        try:
            sim.step(steps)
        finally:
            del manager.update
        return spent[0] / max(1, runner.updates - before)

    def bare() -> float:
        impl, state = runner.impl, runner.state
        update = impl.update
        start = clock()
        for k in range(steps):
            update(state, k * 0.001, 0.001)
        return (clock() - start) / steps

    class _Wake:  # a control that needs every step and does nothing (its step known, as the
        wake_ns = -math.inf  # manager's is: reading model.opt.timestep costs ~1 us a step)

        def __init__(self, step_ns: int) -> None:
            self.step_ns = step_ns

        def update(self, s) -> None:
            self.wake_ns = s.time_ns + self.step_ns

    def wake_cost() -> float:
        manager.stop("my_pd_controller")
        try:
            sim.reset()
            start = time.thread_time()
            sim.step(steps)
            idle = time.thread_time() - start
            wake = _Wake(round(sim.timestep * 1e9))
            sim.add_control(wake)
            sim.reset()
            start = time.thread_time()
            sim.step(steps)
            busy = time.thread_time() - start
            sim.remove_control(wake)
        finally:
            manager.start("my_pd_controller")
        return (busy - idle) / steps

    def clock_cost() -> float:  # what timing each update adds to the update's measured time
        start = clock()
        for _ in range(10_000):
            clock()
        return (clock() - start) / 10_000

    loops, bares, wakes = [], [], []
    for _ in range(max(4, 2 * repeats)):
        signals.check()
        loops.append(loop())
        bares.append(bare())
        wakes.append(wake_cost())
    student, manager_time = float(np.median(bares)), float(np.median(loops)) - clock_cost()
    wake = max(0.0, float(np.median(wakes)))
    return {"student_us": student * 1e6, "manager_us_per_update": manager_time * 1e6,
            "wake_us_per_step": wake * 1e6,
            "framework_us_per_update": (manager_time - student + wake) * 1e6,
            **worker_controller_cost(sim_seconds)}


def _bench_controller(folder: Path) -> Path:
    """The benchmark's PD (my_pd.py) in Mex-One's YAML on the left arm; the YAML's path."""
    from mexone.control.skeleton import skeleton_files

    for name, text in skeleton_files("my_pd").items():
        (folder / name).write_text(text)
    (folder / "my_pd.py").write_text(_BENCH_CONTROLLER)
    return folder / "controllers.yaml"


def worker_controller_cost(sim_seconds: float) -> dict:
    """The same PD named by the YAML, so in a worker process (control/worker.py): the wall time
    of an update's round trip (the lab writes the state, wakes the worker, waits for its
    command) and the lab's CPU time per update, both as medians per update; the real-time
    factor the lab keeps at --rtf 1 with it at 1 kHz (the lateness per step, so a loaded
    machine shows); the worker's start (the interpreter, mexone's imports, the student's file,
    to the configured object) and its memory (proportional set size)."""
    from mexone.control.controllers.isolated import IsolatedRunner
    from mexone.control.worker import Worker

    starts = []
    for _ in range(3):  # the interpreter and mexone's imports, to its greeting: no student code
        start = time.perf_counter()
        worker = Worker()
        worker.ready()
        starts.append(time.perf_counter() - start)
        worker.kill()
    with tempfile.TemporaryDirectory() as folder:
        yaml_path = _bench_controller(Path(folder))
        start = time.perf_counter()
        lab = Lab.create(controllers=yaml_path)
        create_s = time.perf_counter() - start
        sim, runner = lab.sim, lab.manager.controllers["my_pd_controller"]
        assert isinstance(runner, IsolatedRunner)
        walls, cpus = [], []
        real_update = runner.update

        def timed(t: float, dt: float) -> None:
            wall, cpu = time.perf_counter(), time.thread_time()
            real_update(t, dt)
            walls.append(time.perf_counter() - wall)
            cpus.append(time.thread_time() - cpu)

        runner.update = timed
        steps = round(sim_seconds / sim.timestep)
        sim.step(200)  # warm
        walls.clear()
        cpus.clear()
        sim.step(steps)
        worker_us = float(runner._out[0]) * 1e6  # its last update, as it timed itself
        runner.update = real_update
        sim.target_rtf = 1.0
        paced = time.perf_counter()
        sim.run(min(sim_seconds, 1.0))
        rtf = min(sim_seconds, 1.0) / (time.perf_counter() - paced)
        pid = runner.worker.process.pid
        pss = _pss_mb(pid)
        start = time.perf_counter()
        lab.manager.reload("my_pd_controller")  # a fresh worker: describe, create, configure
        reload_s = time.perf_counter() - start
        lab.manager.close()
    return {"worker_round_trip_us": float(np.median(walls)) * 1e6,
            "worker_round_trip_p99_us": float(np.percentile(walls, 99)) * 1e6,
            "worker_lab_cpu_us_per_update": float(np.median(cpus)) * 1e6,
            "worker_student_us": worker_us, "worker_rtf_at_1": rtf,
            "worker_lab_create_s": create_s, "worker_reload_s": reload_s, "worker_pss_mb": pss,
            "worker_start_s": float(np.median(starts))}


def _pss_mb(pid: int) -> float | None:
    """A process's proportional set size, MB (its private memory plus its share of libraries)."""
    try:
        for line in Path(f"/proc/{pid}/smaps_rollup").read_text().splitlines():
            if line.startswith("Pss:"):
                return int(line.split()[1]) / 1024
    except (OSError, ValueError):
        pass
    return None


def camera_cost(sim_seconds: float) -> dict:
    """CPU ms per Kinect frame (30 Hz of sim time), RGB alone and depth + cloud, as the extra
    CPU of a run with those subscribers over the same run without."""
    lab = Lab.create()
    sim, kinect = lab.sim, lab.sensors.sensors["kinect"]
    steps = round(sim_seconds / sim.timestep)

    def run(topics: tuple[str, ...]) -> float:
        subs = [lab.bus.subscribe(kinect.topics[k], lab.bus.topics[kinect.topics[k]].type,
                                  lambda msg: None) for k in topics]
        sim.reset()
        start = time.thread_time()
        sim.step(steps)
        spent = time.thread_time() - start
        for sub in subs:
            sub.unregister()
        return spent

    run(("image", "points"))  # renderer created and warmed up outside the measurement
    base = run(())
    frames = sim_seconds * kinect.rate
    return {"rgb_ms_per_frame": 1e3 * (run(("image",)) - base) / frames,
            "depth_cloud_ms_per_frame": 1e3 * (run(("points",)) - base) / frames,
            "width": kinect.camera.width, "height": kinect.camera.height,
            "gl": os.environ.get("MUJOCO_GL", "default")}


def _fall_mexone(seconds: float) -> dict:
    lab = Lab.create(controllers=False)
    monitor = RunMonitor(lab.sim)
    lab.sim.run(seconds, on_tick=monitor.tick, tick=0.01)
    s = monitor.summary()
    return {"rest_time_s": s.rest_time, "base_height_m": s.base_height}


def pybullet_compare(sim_seconds: float, repeats: int) -> dict | None:
    try:
        import pybullet as pb
    except ImportError:
        return None
    from mexone.description.loader import load_model
    from mexone.description.urdf import write_urdf

    robot = load_model(mex_one.urdf_path())
    for link in robot.links.values():
        link.visuals = []  # PyBullet cannot resolve package:// meshes; physics uses primitives
    frames = [n for n, link in robot.links.items() if link.inertial is None]  # the Kinect's frames:
    for name in frames:  # PyBullet would give each 1 kg ("No inertial data for link")
        del robot.links[name]
    robot.joints = {n: j for n, j in robot.joints.items() if j.child not in frames}
    robot.sensors = []
    with tempfile.TemporaryDirectory() as tmp:
        urdf = Path(tmp) / "mex_rb.urdf"
        urdf.write_text(write_urdf(robot))
        client = pb.connect(pb.DIRECT)
        try:
            return _pybullet_rows(pb, client, str(urdf), robot, sim_seconds, repeats)
        finally:
            pb.disconnect(client)


def _pybullet_rows(pb, client, urdf: str, robot, sim_seconds: float, repeats: int) -> dict:
    steps = round(sim_seconds / 0.001)

    def build(controlled: bool):
        pb.resetSimulation(physicsClientId=client)
        pb.setTimeStep(0.001, physicsClientId=client)
        pb.setGravity(0, 0, -9.81, physicsClientId=client)
        plane = pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=client)
        pb.createMultiBody(0, plane, physicsClientId=client)
        body = pb.loadURDF(urdf, [0, 0, 0.6], flags=pb.URDF_USE_SELF_COLLISION,
                           physicsClientId=client)
        joints = [j for j in range(pb.getNumJoints(body, physicsClientId=client))
                  if pb.getJointInfo(body, j, physicsClientId=client)[2] == pb.JOINT_REVOLUTE]
        names = [pb.getJointInfo(body, j, physicsClientId=client)[1].decode() for j in joints]
        forces = [robot.joints[n].limit.effort for n in names]
        if controlled:
            pb.setJointMotorControlArray(body, joints, pb.POSITION_CONTROL,
                                         targetPositions=[0.0] * len(joints), forces=forces,
                                         physicsClientId=client)
        else:  # PyBullet's default velocity motors lock the joints: switch them off
            pb.setJointMotorControlArray(body, joints, pb.VELOCITY_CONTROL,
                                         forces=[0.0] * len(joints), physicsClientId=client)
        return body, joints

    def run_controlled() -> None:
        build(True)
        for _ in range(steps):
            pb.stepSimulation(physicsClientId=client)

    ours = Lab.create()

    def run_ours() -> None:
        ours.sim.reset()
        ours.sim.step(steps)

    pb_time, our_time = _best(run_controlled, repeats), _best(run_ours, repeats)
    body, _ = build(False)
    rest, height = None, None
    for k in range(1, 8001):
        pb.stepSimulation(physicsClientId=client)
        if k % 10 == 0:
            speeds = [np.linalg.norm(pb.getBaseVelocity(body, physicsClientId=client)[0])]
            speeds += [np.linalg.norm(s[6]) for s in pb.getLinkStates(
                body, range(pb.getNumJoints(body, physicsClientId=client)), computeLinkVelocity=1,
                physicsClientId=client)]
            still = max(speeds) < 0.01
            rest = (rest if rest is not None else k * 0.001) if still else None
    height = pb.getBasePositionAndOrientation(body, physicsClientId=client)[0][2]
    return {"pybullet_s_per_sim_s": pb_time / sim_seconds,
            "mexone_s_per_sim_s": our_time / sim_seconds, "mexone_speedup": pb_time / our_time,
            "fall": {"pybullet": {"rest_time_s": rest, "base_height_m": height},
                     "mexone": _fall_mexone(8.0)}}


def cold_start(repeats: int) -> float:
    cmd = [sys.executable, "-m", "mexone", "sim", "--headless", "--duration", "0.001", "--json"]
    return _best(lambda: subprocess.run(cmd, capture_output=True, check=True), repeats)


def _lab_worker(seconds: float) -> float:
    lab = cached_lab()
    lab.sim.reset()
    lab.sim.step(round(seconds / lab.sim.timestep))
    return seconds


def parallel(workers: int, sim_seconds: float) -> list[dict]:
    lab = Lab.create()
    model = lab.sim.model
    steps = round(sim_seconds / model.opt.timestep)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    state = np.zeros(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, lab.sim.data, state, spec)
    control = np.tile(lab.sim.data.ctrl, (1, steps, 1))
    from mujoco import rollout

    rows = []
    for n in range(1, workers + 1):
        datas = [mujoco.MjData(model) for _ in range(n)]
        batch = 2 * n
        wall = _best(lambda datas=datas, batch=batch: rollout.rollout(
            [model] * batch, datas, np.tile(state, (batch, 1)), np.tile(control, (batch, 1, 1))), 2)
        rows.append({"backend": "mujoco.rollout threads", "workers": n,
                     "robot_s_per_wall_s": batch * sim_seconds / wall})
    for n in range(1, workers + 1):
        with ProcessPoolExecutor(n) as pool:
            list(pool.map(_lab_worker, [0.01] * (4 * n)))  # every worker builds its Lab
            start = time.perf_counter()
            list(pool.map(_lab_worker, [sim_seconds] * (2 * n)))
            wall = time.perf_counter() - start
        rows.append({"backend": "processes (full Lab)", "workers": n,
                     "robot_s_per_wall_s": 2 * n * sim_seconds / wall})
    for row in rows:
        first = next(r for r in rows if r["backend"] == row["backend"] and r["workers"] == 1)
        row["efficiency"] = row["robot_s_per_wall_s"] / (row["workers"] * first["robot_s_per_wall_s"])
    return rows


def machine() -> str:
    cpu = "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{os.cpu_count()} cores, {cpu}, Python {sys.version.split()[0]}, MuJoCo {mujoco.__version__}"


def run_bench(quick: bool = False, progress=None) -> BenchReport:
    sim_seconds, repeats = (1.0, 2) if quick else (5.0, 5)
    report = BenchReport(machine(), sim_seconds)
    steps = [("overhead", lambda: overhead(sim_seconds, repeats)),
             ("overhead_full_pid", lambda: overhead(sim_seconds, repeats, full_pid=True)),
             ("overhead_sensors", lambda: overhead(sim_seconds, repeats, sensors=True)),
             ("overhead_balance", lambda: overhead(sim_seconds, repeats, sensors=True,
                                                   balance=True)),
             ("sensor_states", lambda: sensor_states(sim_seconds, repeats)),
             ("camera", lambda: camera_cost(min(sim_seconds, 2.0))),
             ("pybullet", lambda: pybullet_compare(sim_seconds, repeats)),
             ("cold_start_s", lambda: cold_start(2 if quick else 3)),
             ("parallel", lambda: parallel(os.cpu_count() or 1, sim_seconds)),
             ("python_controller", lambda: python_controller_cost(min(sim_seconds, 2.0),
                                                                  repeats))]
    for name, fn in steps:
        if progress:
            progress(name)
        setattr(report, name, fn())
    return report


def format_report(report: BenchReport) -> str:
    o = report.overhead
    lines = [f"machine: {report.machine}; {report.sim_seconds:g} s of sim time per measurement",
             "",
             f"{'what':<44} {'value':>12}",
             f"{'bare mj_step, CPU s per sim s':<44} {o['bare_s_per_sim_s']:12.4f}",
             f"{'mexone + 21 PD + joint states, CPU s/sim s':<44} {o['mexone_s_per_sim_s']:12.4f}",
             f"{'overhead ratio, PD (target <= 1.06)':<44} {o['ratio']:12.3f}"]
    f = report.overhead_full_pid
    if f:
        lines += [f"{'bare mj_step, full-PID model, CPU s/sim s':<44} {f['bare_s_per_sim_s']:12.4f}",
                  f"{'overhead ratio, full PID, I on all (<= 1.10)':<44} {f['ratio']:12.3f}",
                  f"{'full PID vs bare PD model (what I terms cost)':<44} "
                  f"{f['mexone_s_per_sim_s'] / o['bare_s_per_sim_s']:12.3f}"]
    f = report.overhead_sensors
    if f:
        lines.append(f"{'overhead ratio, PD + IMU, 2 FT, 2 contacts':<44} {f['ratio']:12.3f}")
    f = report.overhead_balance
    if f:
        lines.append(f"{'overhead ratio, the same + COM, ZMP, polygon':<44} {f['ratio']:12.3f}")
    f = report.sensor_states
    if f:
        lines.append(f"{'5 sensors read at 100 Hz + broadcast, vs PD':<44} {f['ratio']:12.3f}")
    c = report.camera
    if c:
        size = f"{c['width']}x{c['height']}"
        lines += [f"{f'Kinect {size} RGB, CPU ms per frame':<44} {c['rgb_ms_per_frame']:12.1f}",
                  f"{'Kinect depth + point cloud, CPU ms per frame':<44} "
                  f"{c['depth_cloud_ms_per_frame']:12.1f}"]
    pb = report.pybullet
    if pb is None:
        missing = 'not installed (pip install ".[peers]")'
        lines.append(f"{'pybullet':<44} {missing:>12}")
    else:
        lines += [f"{'pybullet, wall s per sim s':<44} {pb['pybullet_s_per_sim_s']:12.4f}",
                  f"{'mexone speed-up over pybullet':<44} {pb['mexone_speedup']:12.2f}"]
        for who in ("mexone", "pybullet"):
            fall = pb["fall"][who]
            rest = "never" if fall["rest_time_s"] is None else f"{fall['rest_time_s']:.2f} s"
            label = f"fall without controllers, {who}: rest at / height"
            lines.append(f"{label:<52} {rest:>7} / {fall['base_height_m']:.3f} m")
    lines.append(f"{'cold start (process to 1 ms simulated), s':<44} {report.cold_start_s:12.2f}")
    for row in report.parallel:
        label = f"{row['backend']}, {row['workers']} worker(s)"
        lines.append(f"{label:<44} {row['robot_s_per_wall_s']:8.1f} robot-s/s, "
                     f"efficiency {row['efficiency']:.2f}")
    p = report.python_controller
    if p:
        lines += [f"{'PythonController PD, 3 joints, 1 kHz: student us':<44} {p['student_us']:12.2f}",
                  f"{'  manager cycle per update, CPU us':<44} {p['manager_us_per_update']:12.2f}",
                  f"{'  waking the loop every step, us':<44} {p['wake_us_per_step']:12.2f}",
                  f"{'  framework us per update (target <= 10)':<44} "
                  f"{p['framework_us_per_update']:12.2f}",
                  f"{'the same PD in a worker process: round trip us':<44} "
                  f"{p['worker_round_trip_us']:12.2f}",
                  f"{'  round trip p99, us':<44} {p['worker_round_trip_p99_us']:12.2f}",
                  f"{'  lab CPU us per update (target <= 30)':<44} "
                  f"{p['worker_lab_cpu_us_per_update']:12.2f}",
                  f"{'  real-time factor kept at --rtf 1':<44} {p['worker_rtf_at_1']:12.3f}",
                  f"{'  a worker process up (no student code), s':<44} {p['worker_start_s']:12.2f}",
                  f"{'  Lab.create with it, s; a reload, s':<44} "
                  f"{p['worker_lab_create_s']:6.2f} {p['worker_reload_s']:5.2f}",
                  f"{'  worker memory (PSS), MB':<44} {p['worker_pss_mb'] or 0:12.1f}"]
    return "\n".join(lines)
