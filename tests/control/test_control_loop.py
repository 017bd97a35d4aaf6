"""The control loop as ros2_control draws it: only the simulation thread writes MuJoCo's
actuators, the I term integrates with the physics step it runs at, runs are deterministic with
several routines at once, and a routine that stops yielding cannot freeze the lab."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from helpers import free_port
from mexone.bus.msgs import Float64
from mexone.control import parse_control_config
from mexone.control.hardware import SimHardware
from mexone.description.urdf import read_urdf
from mexone.lab import Lab
from mexone.routines.runner import RoutineRunner

SRC = Path(__file__).resolve().parents[2] / "src" / "mexone"


def test_only_the_simulation_thread_writes_the_actuators(monkeypatch):
    """A routine, a foreign thread publishing commands (as ROS callbacks do) and GUI actions, all
    at once while the GUI's frame loop runs: every write to MuJoCo comes from that loop's thread."""
    from mexone.gui.app import GuiApp
    from mexone.physics import CompileOptions

    writers: list[int] = []
    original = SimHardware.write

    def recorded(self):
        writers.append(threading.get_ident())
        original(self)

    monkeypatch.setattr(SimHardware, "write", recorded)
    app = GuiApp(lambda options: Lab.create(options=options), CompileOptions(), port=free_port(),
                 target_rtf=0.0)
    writers.clear()  # building the lab wrote from this thread, before it handed the sim over
    loop = threading.Thread(target=app.serve_forever, daemon=True)
    loop.start()
    try:
        app.panels["routines"].choice.value = "arms"
        app.do(app.panels["routines"].start)
        manager = app.lab.manager
        topic = manager.topic("neck_yaw_position_controller")
        end = time.time() + 1.5
        k = 0
        while time.time() < end:  # another thread, as rospy's callbacks would be
            app.lab.bus.publish(topic, Float64(0.3 * np.sin(k)))
            if k % 50 == 0:
                app.do(lambda: manager.set_gains("l_knee_position_controller",
                                                  manager.controllers["l_knee_position_controller"].gains))
            k += 1
            time.sleep(0.001)
        assert app.routine is not None and app.routine.running  # the routine ran all along
    finally:
        app.stop()
        loop.join(timeout=5)
    assert len(writers) > 100
    assert set(writers) == {loop.ident}


def test_nothing_but_the_hardware_interface_writes_actuator_state():
    """A scan of the source: ctrl, act and actuator parameters are assigned in hardware.py only."""
    watched = {"ctrl", "act", "actuator_biasprm", "actuator_gainprm", "actuator_forcerange",
               "actuator_actrange", "actuator_actlimited", "actuator_gear"}
    offenders = []
    allowed = {SRC / "control" / "hardware.py",
               SRC / "bench.py",  # bench: bare MuJoCo on an MjData of its own, for comparison
               # the grader's perturbation of the plant (an amplifier k times stronger, after
               # the hardware read the gear), on the grader's own lab: the trial, not a control
               SRC / "exercises" / "course" / "robust_arm" / "grader.py",
               # a controller worker's private MjData, read by a student's deployed design: its
               # ctrl and act NaN (the worker is not told them), in the worker's own process
               SRC / "control" / "worker_main.py"}
    for path in SRC.rglob("*.py"):
        if path in allowed:
            continue
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            targets = node.targets if isinstance(node, ast.Assign) else \
                [node.target] if isinstance(node, ast.AugAssign) else []
            for target in targets:
                base = target.value if isinstance(target, ast.Subscript) else target
                if isinstance(base, ast.Attribute) and base.attr in watched:
                    offenders.append(f"{path.relative_to(SRC)}:{node.lineno}")
    assert offenders == []


def test_write_changes_exactly_the_actuator_fields_recompiling_carries_over():
    """RUNTIME_ACTUATOR_FIELDS (carried over when a model is added, replayed by identify) is the
    list of what write() changes: a field written but not listed would silently go stale."""
    from mexone.physics.attach import RUNTIME_ACTUATOR_FIELDS

    lab = Lab.create()
    hw, model = lab.manager.hw, lab.sim.model
    fields = [name for name in dir(model) if name.startswith("actuator_")
              and isinstance(getattr(model, name), np.ndarray)]
    before = {name: getattr(model, name).copy() for name in fields}
    c, rows = hw.command, np.arange(len(hw.joints))
    c.kp[:], c.kd[:], c.ki[:] = 123.0, 4.5, 6.7
    c.i_min[:], c.i_max[:], c.antiwindup[:] = -0.8, 0.9, True
    hw.gains_changed(rows)
    hw.write()  # no loop serves this lab: this thread is its simulation thread
    changed = {name for name in fields if not np.array_equal(before[name], getattr(model, name))}
    assert changed == set(RUNTIME_ACTUATOR_FIELDS)


def test_the_integral_term_integrates_with_the_new_time_step(tmp_path, turntable):
    """The joint is pinned at its upper limit (3 rad) by a load the 1 N m motor cannot beat, so
    the error to a 2.5 rad setpoint is a constant -0.5 and the I term is the ramp i e t, before
    and after the step halves. Integrating with the old step after the change would double it."""
    write, _ = turntable
    i, e = 2.0, -0.5
    lab = Lab.create(read_urdf(write(tmp_path, effort=1.0)), parse_control_config(f"""turntable:
  yaw_controller:
    type: effort_controllers/JointPositionController
    joint: yaw
    pid: {{p: 10.0, i: {i}, d: 0.1, i_clamp_min: -1000, i_clamp_max: 1000}}
"""))
    sim, hw = lab.sim, lab.manager.hw
    sim.data.qfrc_applied[0] = 5.0
    sim.step(2000)  # pinned at the limit by now
    lab.bus.publish("/turntable/yaw_controller/command", Float64(2.5))
    sim.step(1)
    t0, z0 = sim.time, sim.data.act[hw.layout.i_act[0]]
    sim.step(500)
    sim.set_timestep(0.0005)
    sim.step(1000)
    elapsed = sim.time - t0
    assert elapsed == pytest.approx(1.0)
    error = sim.joint_positions()[0] - 3.0
    assert abs(error) < 0.01  # pinned (MuJoCo's limits are soft by a hair)
    z = sim.data.act[hw.layout.i_act[0]] - z0
    assert z == pytest.approx(e * elapsed, rel=0.02)
    i_term = sim.data.actuator_force[hw.layout.integral[0]]
    assert i_term == pytest.approx(i * sim.data.act[hw.layout.i_act[0]], rel=1e-9)
    assert abs(z - e * (0.5 + 2 * 0.5)) > 0.2  # what a stale dt would have given


ROUTINE_A = """
from mexone import rospy
from mexone.msgs import Float64, JointState
seen = []
rospy.init_node("left")
rospy.Subscriber("/mex_rb/joint_states", JointState, lambda m: seen.append(m.position[0]))
pub = rospy.Publisher("/mex_rb/l_elbow_position_controller/command", Float64, queue_size=1)
rate = rospy.Rate(10)
k = 0
while not rospy.is_shutdown():
    pub.publish(Float64(-0.8 if k % 2 else -0.2 - 0.001 * len(seen)))
    k += 1
    rate.sleep()
"""

ROUTINE_B = """
from mexone import rospy
from mexone.msgs import Float64
rospy.init_node("right")
pub = rospy.Publisher("/mex_rb/r_elbow_position_controller/command", Float64, queue_size=1)
neck = rospy.Publisher("/mex_rb/neck_yaw_position_controller/command", Float64, queue_size=1)
rate = rospy.Rate(7)
while not rospy.is_shutdown():
    t = rospy.get_time()
    pub.publish(Float64(-0.5 - 0.3 * (int(t * 3) % 2)))
    neck.publish(Float64(0.2 if int(t) % 2 else -0.2))
    rate.sleep()
"""


def _trajectory(tmp_path, routines: list[str]) -> np.ndarray:
    lab = Lab.create()
    samples = []
    lab.sim.add_periodic(0.01, lambda s: samples.append(s.data.qpos.copy()))
    runner = RoutineRunner(lab)
    for i, text in enumerate(routines):
        path = tmp_path / f"routine_{i}.py"
        path.write_text(text)
        runner.add(path)
    runner.run(2.0)
    assert runner.error is None
    return np.array(samples)


def test_runs_are_bit_identical_with_one_and_with_two_routines(tmp_path):
    one = [_trajectory(tmp_path, [ROUTINE_A]) for _ in range(2)]
    assert np.array_equal(one[0], one[1])
    two = [_trajectory(tmp_path, [ROUTINE_A, ROUTINE_B]) for _ in range(2)]
    assert np.array_equal(two[0], two[1])
    assert not np.array_equal(one[0], two[0])  # the second routine did move the robot


STUCK = ["while True:\n    x = 1\n", "import time\ntime.sleep(120)\n",
         "while True:\n    try:\n        pub.publish(Float64(0.1))\n    except Exception:\n        pass\n"]


def _run_stuck(folder: Path, body: str) -> tuple[subprocess.CompletedProcess, float, float]:
    """`mexone run` of a routine that never yields: its output, its wall time and its own CPU
    time (s, user + system, as the kernel counted them for that process)."""
    path = folder / "stuck.py"
    path.write_text("from mexone import rospy\nfrom mexone.msgs import Float64\n"
                    "pub = rospy.Publisher('/mex_rb/neck_yaw_position_controller/command', Float64)\n"
                    + body)
    start = time.time()
    with (folder / "out").open("w+") as stdout, (folder / "err").open("w+") as stderr:
        proc = subprocess.Popen([sys.executable, "-m", "mexone", "run", str(path), "--duration",
                                 "3", "--json"], stdout=stdout, stderr=stderr, text=True)
        guard = threading.Timer(120, proc.kill)  # a hang's guard, not the claim
        guard.start()
        try:  # wait4: its exit and what it used, as the kernel counted them
            _, status, usage = os.wait4(proc.pid, 0)
        finally:
            guard.cancel()
        proc.returncode = os.waitstatus_to_exitcode(status)
        stdout.seek(0)
        stderr.seek(0)
        out = subprocess.CompletedProcess(proc.args, proc.returncode, stdout.read(), stderr.read())
    return out, time.time() - start, usage.ru_utime + usage.ru_stime


@pytest.fixture(scope="module")
def stuck_runs(tmp_path_factory, request):
    """The selected stuck routines' runs, all started at once (each lab waits 5 s of wall time
    for its watchdog; one at a time the waits add up): body -> Future of (output, wall time)."""
    selected = {item.callspec.params["body"] for item in request.session.items
                if item.module is request.module and hasattr(item, "callspec")
                and "body" in item.callspec.params}
    with ThreadPoolExecutor(max_workers=len(STUCK)) as pool:
        yield {body: pool.submit(_run_stuck, tmp_path_factory.mktemp("stuck"), body)
               for body in STUCK if body in selected}


@pytest.mark.parametrize("body", STUCK)
def test_a_routine_that_never_yields_is_abandoned_with_a_message(stuck_runs, body):
    out, took, cpu = stuck_runs[body].result()
    print(f"abandoned after {took:.1f} s of wall time, {cpu:.1f} s of its CPU time")
    assert out.returncode == 1, out.stderr
    if "sleep" in body:  # asleep: the watchdog's 5 s and a start-up on a loaded machine, not 120
        assert took < 25
    else:  # a busy loop is abandoned after 5 s of its own running (a wait for a CPU is not its,
        # runtime._abandon_stalled): on shared cores that is the process's CPU time (5 s of the
        # loop, the simulation stopped meanwhile, ~1 s of start-up), not the wall time
        assert cpu < 5 + 4
    assert "routine did not yield to the simulation for 5 s (call rate.sleep())" in out.stdout
    assert "Traceback" not in out.stderr


def test_the_gui_stays_responsive_and_stop_works_with_a_stuck_routine(tmp_path):
    from mexone.gui.app import GuiApp
    from mexone.physics import CompileOptions

    (tmp_path / "spin.py").write_text("while True:\n    pass\n")
    app = GuiApp(lambda options: Lab.create(options=options), CompileOptions(), port=free_port(),
                 routine_dirs=[tmp_path])
    loop = threading.Thread(target=app.serve_forever, daemon=True)
    loop.start()
    try:
        app.panels["routines"].choice.value = "spin.py"
        app.do(app.panels["routines"].start)
        time.sleep(0.5)
        t0 = app.lab.sim.time
        app.do(app.panels["routines"].stop_routine)  # Stop works at once, although the routine never yields
        deadline = time.time() + 3
        while (app.routine is not None or app.lab.sim.time < t0 + 0.5) and time.time() < deadline:
            time.sleep(0.05)
        assert app.routine is None
        assert app.lab.sim.time > t0 + 0.5  # the simulation went on in real time
        # and the spinning thread ended: left running it took half the GIL for the rest of the
        # process (the later GUI tests lost real time in a full run)
        spinning = [t for t in threading.enumerate() if t.name == "routine spin"]
        for thread in spinning:
            thread.join(timeout=5)
        assert not any(t.is_alive() for t in spinning)
    finally:
        app.stop()
        loop.join(timeout=5)
