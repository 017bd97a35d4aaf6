"""The real rviz from Debian, under Xvfb, shows what a gazebo_ros user expects: the robot model,
its TF and the Kinect's point cloud, with the cloud lying on the object the Kinect sees (the
frame-convention test, by eye and by pixel). A pillar is spawned 1.7 m in front of Mex-One with
gazebo_ros' spawn_urdf_model; rviz draws from above (TopDownOrtho: a linear map from world x, y
to pixels), so the cloud's nearest pixels must form the pillar's front face."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from test_bridge import RSP, free_port, ros_env, start_roscore, stop  # noqa: E402
from test_parity import start_sim  # noqa: E402

pytestmark = pytest.mark.slow

PILLAR_X, HALF = 1.9, 0.2  # m: a 0.4 x 0.4 x 2 m pillar centred 1.9 m ahead, its face at 1.7 m
PILLAR = f"""<robot name="pillar"><link name="pillar"><inertial><mass value="50"/>
<inertia ixx="17" iyy="17" izz="1.3" ixy="0" ixz="0" iyz="0"/></inertial>
<collision><geometry><box size="{2 * HALF} {2 * HALF} 2"/></geometry></collision>
<visual><geometry><box size="{2 * HALF} {2 * HALF} 2"/></geometry></visual></link></robot>"""
SCALE, CENTRE_X = 100.0, 1.6  # px per m; the world x at the view's centre
BACKGROUND = (20, 20, 30)
CLOUD = (255, 0, 255)  # magenta: no link, axis or grid is drawn in it

TOP_DOWN = f"""Panels: []
Visualization Manager:
  Class: ""
  Displays:
    - Class: rviz/RobotModel
      Name: RobotModel
      Enabled: true
      Robot Description: robot_description
      Visual Enabled: true
      Collision Enabled: false
    - Class: rviz/TF
      Name: TF
      Enabled: true
      Show Names: false
      Show Arrows: false
      Show Axes: true
      Marker Scale: 0.3
    - Class: rviz/PointCloud2
      Name: Kinect
      Enabled: true
      Topic: /mex_rb/kinect/depth/points
      Style: Points
      Size (Pixels): 2
      Color Transformer: FlatColor
      Color: {CLOUD[0]}; {CLOUD[1]}; {CLOUD[2]}
      Alpha: 1
      Queue Size: 2
  Enabled: true
  Global Options:
    Background Color: {BACKGROUND[0]}; {BACKGROUND[1]}; {BACKGROUND[2]}
    Fixed Frame: world
    Frame Rate: 10
  Name: root
  Tools: []
  Value: true
  Views:
    Current:
      Class: VIEW_CLASS
VIEW_VALUES
      Name: Current View
      Target Frame: <Fixed Frame>
    Saved: ~
Window Geometry:
  Height: 600
  Width: 800
  X: 0
  Y: 0
  Hide Left Dock: true
  Hide Right Dock: true
"""
VIEWS = {
    "top": ("rviz/TopDownOrtho", f"      Angle: 0\n      Scale: {SCALE}\n      X: {CENTRE_X}\n"
                                 "      Y: 0"),
    "orbit": ("rviz/Orbit", "      Distance: 4.5\n      Yaw: 3.6\n      Pitch: 0.45\n"
                            "      Focal Point:\n        X: 1.0\n        Y: 0\n        Z: 0.8"),
}


def _display() -> tuple[subprocess.Popen, str]:
    """A fresh Xvfb on a display number it picks itself (-displayfd): never another process's."""
    read, write = os.pipe()
    proc = subprocess.Popen(["Xvfb", "-displayfd", str(write), "-screen", "0", "1024x768x24",
                             "-nolisten", "tcp"], pass_fds=(write,), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    os.close(write)
    with os.fdopen(read) as pipe:
        number = pipe.readline().strip()  # written once the server accepts connections
    if not number:
        raise AssertionError("Xvfb did not start")
    return proc, f":{number}"


def _grab(display: str) -> np.ndarray:
    from PIL import ImageGrab

    return np.asarray(ImageGrab.grab(xdisplay=display).convert("RGB"))


def _rviz(tmp_path: Path, port: int, display: str, view: str) -> subprocess.Popen:
    kind, values = VIEWS[view]
    config = tmp_path / f"{view}.rviz"
    config.write_text(TOP_DOWN.replace("VIEW_CLASS", kind).replace("VIEW_VALUES", values))
    env = ros_env(port)  # mex_rb (meshes for the robot model) found as the README says
    env.update(DISPLAY=display, LIBGL_ALWAYS_SOFTWARE="1")
    log = Path(os.environ.get("TMPDIR", "/tmp")) / f"mexone-rviz-{view}.log"
    with open(log, "w") as out:  # the child keeps its own copy of the descriptor
        return subprocess.Popen(["rviz", "-d", str(config)], env=env, stdout=out, stderr=out,
                                start_new_session=True)


def _save(shot: np.ndarray) -> str:
    from PIL import Image

    path = Path(os.environ.get("TMPDIR", "/tmp")) / f"mexone-rviz-{os.getpid()}.png"
    Image.fromarray(shot).save(path)
    return str(path)


def _wait_for_cloud(display: str, timeout: float = 120.0) -> np.ndarray:
    deadline = time.time() + timeout
    while time.time() < deadline:
        shot = _grab(display)
        if (np.all(shot == CLOUD, axis=-1)).sum() > 500:
            time.sleep(1.0)  # one more frame at the final pose
            return _grab(display)
        time.sleep(0.5)
    raise AssertionError(f"rviz never drew the Kinect's cloud (screen: {_save(shot)})")


def _ros(port: int, *command: str, timeout: float = 60) -> str:
    """A ROS command-line tool against this module's master; its output (one line on failure)."""
    try:
        done = subprocess.run(command, env=ros_env(port), capture_output=True, text=True,
                              timeout=timeout)
    except subprocess.TimeoutExpired:
        raise AssertionError(f"{' '.join(command[:3])} timed out after {timeout} s") from None
    assert done.returncode == 0, f"{' '.join(command[:3])}: {done.stderr.strip()[-500:]}"
    return done.stdout


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """A master of its own (nothing left by other modules: registrations, TF, sim time) with
    the sim, robot_state_publisher and a pillar spawned as a gazebo_ros user would."""
    if not shutil.which("rviz") or not shutil.which("Xvfb"):
        pytest.skip("Debian's rviz and xvfb are not installed")
    port = free_port()
    core = start_roscore(port)
    sim = rsp = xvfb = None
    try:
        _ros(port, "rosparam", "set", "/use_sim_time", "true")
        sim = start_sim(port)
        try:
            _ros(port, "rostopic", "echo", "-n", "1", "--noarr", "/mex_rb/joint_states/header",
                 timeout=90)
        except AssertionError as exc:
            stop(sim)
            raise AssertionError(f"{exc}; the sim said: {sim.stderr.read()[-800:]}") from None
        # robot_state_publisher reads robot_description once at start: only after the sim set it
        rsp = subprocess.Popen([RSP, "joint_states:=/mex_rb/joint_states"], env=ros_env(port),
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                               start_new_session=True)
        request = {"model_name": "pillar", "model_xml": PILLAR, "robot_namespace": "",
                   "initial_pose": {"position": {"x": PILLAR_X, "y": 0.0, "z": 1.0},
                                    "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}},
                   "reference_frame": "world"}
        assert "success: True" in _ros(port, "rosservice", "call", "--wait",
                                       "/gazebo/spawn_urdf_model", json.dumps(request))
        xvfb, display = _display()
        yield tmp_path_factory.mktemp("rviz"), port, display
    finally:
        for proc in (rsp, sim, xvfb, core):
            if proc is not None:
                stop(proc)


def test_rviz_draws_the_robot_and_the_kinect_cloud_on_the_pillar(scene):
    tmp_path, port, display = scene
    rviz = _rviz(tmp_path, port, display, "top")
    try:
        shot = _wait_for_cloud(display)
    finally:
        stop(rviz)
    # the render area: the background's bounding box; its centre is (CENTRE_X, 0) in the world
    ys, xs = np.nonzero(np.all(shot == BACKGROUND, axis=-1))
    cx, cy = (xs.min() + xs.max()) / 2.0, (ys.min() + ys.max()) / 2.0

    def world(col: np.ndarray, row: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return CENTRE_X + (col - cx) / SCALE, -(row - cy) / SCALE  # x right, y up

    rows, cols = np.nonzero(np.all(shot == CLOUD, axis=-1))
    x, y = world(cols, rows)
    near = x < PILLAR_X  # nothing can be seen between the Kinect and the pillar but the pillar
    face_x = PILLAR_X - HALF
    assert near.sum() > 30, "the pillar's face is missing from the cloud"
    np.testing.assert_allclose(x[near], face_x, atol=0.03)  # 3 px: on the face
    assert y[near].min() == pytest.approx(-HALF, abs=0.03)  # and as wide as it
    assert y[near].max() == pytest.approx(HALF, abs=0.03)
    # the robot model is drawn where the robot stands (non-background pixels around the origin)
    r0, c0 = int(round(cy)), int(round(cx - CENTRE_X * SCALE))
    patch = shot[r0 - 15:r0 + 16, c0 - 15:c0 + 16]
    assert np.any(~np.all(patch == BACKGROUND, axis=-1)), "no robot drawn at the origin"
    if os.environ.get("MEXONE_SCREENSHOT_DIR"):  # the README's picture, in perspective
        from PIL import Image

        rviz = _rviz(tmp_path, port, display, "orbit")
        try:
            Image.fromarray(_wait_for_cloud(display)[:600, :800]).save(
                Path(os.environ["MEXONE_SCREENSHOT_DIR"]) / "rviz.png")
        finally:
            stop(rviz)
