"""Shared fixtures; under MEXONE_CI=1 a skipped test is a failed test."""

from __future__ import annotations

import os
import signal
import threading
import time
from pathlib import Path

import pytest

# Cameras render offscreen; MuJoCo picks its OpenGL platform when it is first imported.
if not os.environ.get("DISPLAY"):
    os.environ.setdefault("MUJOCO_GL", "egl")
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

# A run started in the background by a shell (`bash .ci/run &`) inherits SIGINT ignored, and so
# would every mexone process the tests start (exec keeps an ignored signal ignored): the Ctrl-C
# tests would see their SIGINT dropped. A handled signal is reset to the default on exec.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

# Grading with the hidden variation needs a teacher's secret (mexone.exercises.grading.hidden_rng):
# the suite's own, fixed so that its graded numbers repeat; a test of the secret sets its own.
os.environ.setdefault("MEXONE_EXERCISE_SECRET", "mexone's test suite, not a course's secret")

DATA = Path(__file__).parent / "data"
IN_CI = os.environ.get("MEXONE_CI") == "1"


# ----- two phases (tests/phases.py): the files that only compute side by side, then the others ----
def pytest_collection_modifyitems(config, items):
    import phases

    phase = os.environ.get("MEXONE_TEST_PHASE", "")
    if not phase:
        return  # a plain `pytest`: every test, one at a time
    if phase not in phases.PHASES:
        raise pytest.UsageError(f"MEXONE_TEST_PHASE={phase!r}: one of {', '.join(phases.PHASES)}, "
                                "or unset for every test")
    if phases.missing():
        raise pytest.UsageError(f"tests/phases.py's SHARES_THE_CPU names {', '.join(phases.missing())}, "
                                "which do not exist: remove or rename them")
    keep, drop = [], []
    for item in items:
        (keep if phases.shares_the_cpu(item.path) == (phase == "parallel") else drop).append(item)
    if drop:
        config.hook.pytest_deselected(items=drop)
        items[:] = keep


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    report = outcome.get_result()
    if IN_CI and report.skipped and not hasattr(report, "wasxfail"):
        report.outcome = "failed"
        reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else report.longrepr
        report.longrepr = f"skipped in CI (MEXONE_CI=1), which must run everything: {reason}"


# ----- no thread left behind -----------------------------------------------------------------------
# A thread a test (or a fixture of its module) starts must end by that scope's teardown: a
# leaked simulation, viser or IK thread keeps running in every later test, costs them CPU and
# can touch their state. Threads a session-scoped fixture starts (rospy's) live for the session.
THREAD_GRACE = 5.0  # s for the threads of a closed server or lab to notice and end
_session_threads: set[threading.Thread] = set()
_suspects: dict[threading.Thread, str] = {}  # thread -> the test that saw it start
_THREADS_BEFORE = pytest.StashKey[set]()
# the session's rospy node (tests/ros1/conftest.py): its registration manager, TCPROS server,
# XML-RPC server and /rosout publisher start when it first needs them and live as long as the
# process, as in any node
_NODE_MACHINERY = ("rospy.impl.registration", "rospy.impl.tcpros_base", "rosgraph.xmlrpc")


def _for_the_session(thread: threading.Thread) -> bool:
    owner = getattr(getattr(thread, "_target", None), "__self__", None)
    if type(owner).__name__ == "QueuedConnection":  # a publisher's queue to one subscriber
        return getattr(getattr(owner, "_connection", None), "name", None) == "/rosout"
    if thread.name == "tqdm_monitor":  # tqdm's one monitor of every bar, for the process's life
        return True
    if type(thread).__module__ == "rospy.timer":  # an action server's status timer sleeps on ROS
        return True  # time: under the session's /use_sim_time with no /clock left it never wakes
    return thread in _session_threads or type(owner).__module__.startswith(_NODE_MACHINERY)


@pytest.hookimpl(wrapper=True)
def pytest_fixture_setup(fixturedef, request):
    before = set(threading.enumerate())
    try:
        return (yield)
    finally:
        if fixturedef.scope == "session":
            _session_threads.update(set(threading.enumerate()) - before)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_protocol(item, nextitem):
    item.stash[_THREADS_BEFORE] = set(threading.enumerate())
    return (yield)


def _leaked(threads) -> list[threading.Thread]:
    """The threads still alive after THREAD_GRACE s in all (each joined, so no fixed wait)."""
    end = time.monotonic() + THREAD_GRACE
    for thread in threads:
        thread.join(timeout=max(0.0, end - time.monotonic()))
    return [t for t in threads if t.is_alive()]


@pytest.hookimpl(wrapper=True)
def pytest_runtest_teardown(item, nextitem):
    result = yield
    new = set(threading.enumerate()) - item.stash.get(_THREADS_BEFORE, set())
    # a thread started outside `threading` (by C code) cannot be joined nor told to be finished
    new = {t for t in new if not isinstance(t, threading._DummyThread)}
    for thread in new:
        _suspects.setdefault(thread, item.nodeid)
    # a module-scoped fixture's threads may live until its module ends; then each must be gone
    module = getattr(item, "module", None)
    if nextitem is None or getattr(nextitem, "module", None) is not module:
        suspects = dict(_suspects)
        _suspects.clear()
        left = _leaked([t for t in suspects if not _for_the_session(t)])
        if left:
            names = ", ".join(f"'{t.name}' ({type(t).__module__}.{type(t).__name__}, started in "
                              f"{suspects[t]})" for t in left)
            raise AssertionError(f"{len(left)} thread(s) left behind after {item.path.name}"
                                 f"'s teardown: {names}")
    return result


@pytest.fixture(scope="session")
def data_dir() -> Path:
    return DATA


TURNTABLE_MASS, TURNTABLE_LENGTH, TURNTABLE_RADIUS = 1.0, 0.4, 0.02
# the rod's inertia about its pivot on the vertical axis
TURNTABLE_INERTIA = (TURNTABLE_MASS * (3 * TURNTABLE_RADIUS**2 + TURNTABLE_LENGTH**2) / 12
                     + TURNTABLE_MASS * (TURNTABLE_LENGTH / 2) ** 2)


def write_turntable(folder: Path, reduction=1.0, effort=50.0, damping=0.0) -> Path:
    """A rod on a vertical axis, welded to the world: gravity exerts no torque on it, so
    I q'' = torque exactly -- the plant of the closed-form controller tests."""
    m, length, r = TURNTABLE_MASS, TURNTABLE_LENGTH, TURNTABLE_RADIUS
    ixx = m * (3 * r**2 + length**2) / 12
    path = folder / "turntable.urdf"
    path.write_text(f"""<robot name="turntable">
      <link name="world"/>
      <joint name="weld" type="fixed"><parent link="world"/><child link="base"/><origin xyz="0 0 0.5"/></joint>
      <link name="base"/>
      <joint name="yaw" type="revolute">
        <parent link="base"/><child link="rod"/><axis xyz="0 0 1"/>
        <limit lower="-3" upper="3" effort="{effort}" velocity="20"/>
        <dynamics damping="{damping}" friction="0"/>
      </joint>
      <link name="rod">
        <inertial><origin xyz="{length / 2} 0 0" rpy="0 1.5707963267948966 0"/><mass value="{m}"/>
          <inertia ixx="{ixx}" ixy="0" ixz="0" iyy="{ixx}" iyz="0" izz="{m * r**2 / 2}"/></inertial>
      </link>
      <transmission name="yaw_tx"><type>transmission_interface/SimpleTransmission</type>
        <joint name="yaw"><hardwareInterface>hardware_interface/EffortJointInterface</hardwareInterface></joint>
        <actuator name="yaw_motor"><mechanicalReduction>{reduction}</mechanicalReduction></actuator>
      </transmission>
    </robot>""")
    return path


@pytest.fixture(scope="session")
def turntable():
    """(write_turntable, its inertia about the pivot), for the controller and sweep tests."""
    return write_turntable, TURNTABLE_INERTIA


# ----- a humanoid of our own, laid out as a ROS package (no transmissions) ----------------------
def _box_inertia(m: float, x: float, y: float, z: float) -> str:
    return (f'ixx="{m * (y * y + z * z) / 12:.6g}" ixy="0" ixz="0" iyy="{m * (x * x + z * z) / 12:.6g}" '
            f'iyz="0" izz="{m * (x * x + y * y) / 12:.6g}"')


def humanoid_urdf(name: str = "biped", mesh: str | None = None) -> str:
    """A 25-joint, 52 kg humanoid of boxes (a Unitree look-alike): legs of 6 joints, arms of 5,
    waist, neck yaw and pitch; no <transmission>; a massless imu_link on a fixed joint with a
    zero axis, robot-level named materials and a Gazebo material name. `mesh`: the pelvis's
    visual is that mesh file (package:// or relative) instead of a box."""
    parts = [f'<robot name="{name}">',
             '<material name="dark"><color rgba="0.2 0.2 0.2 1"/></material>',
             '<material name="white"><color rgba="0.9 0.9 0.9 1"/></material>']

    def link(lname: str, m: float, size: tuple, centre=(0, 0, 0), material="dark",
             collide=False, visual=None) -> None:
        c = " ".join(f"{v:g}" for v in centre)
        s = " ".join(f"{v:g}" for v in size)
        geometry = visual or f'<box size="{s}"/>'
        parts.append(
            f'<link name="{lname}"><inertial><origin xyz="{c}"/><mass value="{m}"/>'
            f'<inertia {_box_inertia(m, *size)}/></inertial>'
            f'<visual><origin xyz="{c}"/><geometry>{geometry}</geometry><material name="{material}"/>'
            '</visual>'
            + (f'<collision><origin xyz="{c}"/><geometry><box size="{s}"/></geometry></collision>'
               if collide else "") + '</link>')

    def joint(jname: str, parent: str, child: str, xyz, axis, lower, upper, effort) -> None:
        parts.append(
            f'<joint name="{jname}" type="revolute"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="{" ".join(f"{v:g}" for v in xyz)}"/><axis xyz="{axis}"/>'
            f'<limit lower="{lower}" upper="{upper}" effort="{effort}" velocity="10"/>'
            '<dynamics damping="0.5" friction="0.1"/></joint>')

    pelvis_visual = f'<mesh filename="{mesh}"/>' if mesh else None
    link("pelvis", 8.0, (0.2, 0.25, 0.12), material="white", collide=True, visual=pelvis_visual)
    link("torso", 12.0, (0.2, 0.3, 0.4), (0, 0, 0.2), "white", collide=True)
    joint("waist_yaw", "pelvis", "torso", (0, 0, 0.06), "0 0 1", -1.5, 1.5, 80)
    link("neck", 0.5, (0.05, 0.05, 0.05))
    joint("neck_yaw", "torso", "neck", (0, 0, 0.42), "0 0 1", -1.5, 1.5, 10)
    link("head", 3.0, (0.16, 0.16, 0.18), (0, 0, 0.1), "white")
    joint("neck_pitch", "neck", "head", (0, 0, 0.03), "0 1 0", -0.8, 0.8, 10)
    parts.append('<link name="imu_link"/><joint name="imu_joint" type="fixed"><parent link="torso"/>'
                 '<child link="imu_link"/><origin xyz="0 0 0.1"/><axis xyz="0 0 0"/></joint>')
    parts.append('<gazebo reference="head"><material>Gazebo/Orange</material></gazebo>')
    for side, y in (("l", 1), ("r", -1)):
        link(f"{side}_shoulder", 0.5, (0.06, 0.06, 0.06))
        joint(f"{side}_shoulder_pitch", "torso", f"{side}_shoulder", (0, 0.18 * y, 0.36), "0 1 0",
              -3, 3, 40)
        link(f"{side}_shoulder_roll_link", 0.5, (0.06, 0.06, 0.06))
        joint(f"{side}_shoulder_roll", f"{side}_shoulder", f"{side}_shoulder_roll_link",
              (0, 0.04 * y, 0), "1 0 0", -1.5, 1.5, 40)
        link(f"{side}_upper_arm", 1.5, (0.07, 0.07, 0.25), (0, 0, -0.125))
        joint(f"{side}_shoulder_yaw", f"{side}_shoulder_roll_link", f"{side}_upper_arm", (0, 0, -0.03),
              "0 0 1", -1.5, 1.5, 20)
        link(f"{side}_forearm", 1.0, (0.06, 0.06, 0.22), (0, 0, -0.11))
        joint(f"{side}_elbow", f"{side}_upper_arm", f"{side}_forearm", (0, 0, -0.25), "0 1 0",
              -2.5, 0, 30)
        link(f"{side}_hand", 0.4, (0.05, 0.08, 0.1), (0, 0, -0.05))
        joint(f"{side}_wrist", f"{side}_forearm", f"{side}_hand", (0, 0, -0.22), "0 0 1", -1.5, 1.5, 5)
        link(f"{side}_hip_yaw_link", 1.0, (0.08, 0.08, 0.06))
        joint(f"{side}_hip_yaw", "pelvis", f"{side}_hip_yaw_link", (0, 0.1 * y, -0.08), "0 0 1",
              -0.8, 0.8, 100)
        link(f"{side}_hip_roll_link", 1.0, (0.08, 0.08, 0.06))
        joint(f"{side}_hip_roll", f"{side}_hip_yaw_link", f"{side}_hip_roll_link", (0, 0, -0.06),
              "1 0 0", -0.5, 0.5, 150)
        link(f"{side}_thigh", 4.0, (0.1, 0.1, 0.35), (0, 0, -0.175))
        joint(f"{side}_hip_pitch", f"{side}_hip_roll_link", f"{side}_thigh", (0, 0, -0.03), "0 1 0",
              -2.0, 1.0, 150)
        link(f"{side}_shank", 3.0, (0.08, 0.08, 0.35), (0, 0, -0.175))
        joint(f"{side}_knee", f"{side}_thigh", f"{side}_shank", (0, 0, -0.35), "0 1 0", 0, 2.5, 150)
        link(f"{side}_ankle_link", 0.5, (0.05, 0.05, 0.04))
        joint(f"{side}_ankle_pitch", f"{side}_shank", f"{side}_ankle_link", (0, 0, -0.35), "0 1 0",
              -0.8, 0.8, 80)
        link(f"{side}_foot", 1.2, (0.24, 0.1, 0.04), (0.03, 0, -0.04), collide=True)
        joint(f"{side}_ankle_roll", f"{side}_ankle_link", f"{side}_foot", (0, 0, -0.02), "1 0 0",
              -0.4, 0.4, 60)
    parts.append("</robot>")
    return "\n".join(parts)


def write_humanoid_package(root: Path, name: str = "biped_description", mesh: bool = False) -> Path:
    """A ROS package root/name with package.xml, urdf/biped.urdf (and meshes/pelvis.stl if
    `mesh`, named package://name/meshes/pelvis.stl); returns the URDF's path."""
    folder = root / name
    (folder / "urdf").mkdir(parents=True)
    (folder / "package.xml").write_text(f"<package format='2'><name>{name}</name></package>")
    uri = None
    if mesh:
        import trimesh

        (folder / "meshes").mkdir()
        trimesh.creation.box(extents=(0.2, 0.25, 0.12)).export(folder / "meshes" / "pelvis.stl")
        uri = f"package://{name}/meshes/pelvis.stl"
    path = folder / "urdf" / "biped.urdf"
    path.write_text(humanoid_urdf(mesh=uri))
    return path


@pytest.fixture()
def humanoid(tmp_path) -> Path:
    """The humanoid's URDF inside its own ROS package in tmp_path/ws/src."""
    return write_humanoid_package(tmp_path / "ws" / "src")


@pytest.fixture()
def humanoid_with_mesh(tmp_path) -> Path:
    """The same, its pelvis drawn by meshes/pelvis.stl named package://biped_description/..."""
    return write_humanoid_package(tmp_path / "ws" / "src", mesh=True)


# ----- the wheel in a fresh venv (tests/wheelenv.py): one per session, shared -------------------
@pytest.fixture(scope="session")
def wheel(tmp_path_factory) -> Path:
    """The wheel built from a copy of the files git knows."""
    import wheelenv

    return wheelenv.build_wheel(tmp_path_factory)


@pytest.fixture(scope="session")
def venv(wheel, tmp_path_factory):
    """A fresh venv (no system site-packages) with the wheel installed: a `wheelenv.Venv`."""
    import wheelenv

    return wheelenv.make_venv(wheel, tmp_path_factory)
