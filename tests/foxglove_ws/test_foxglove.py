"""`mexone sim --foxglove` against Foxglove's own WebSocket client (npm @foxglove/ws-protocol on
node, client.js): none of mexone's code decodes what it receives."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from helpers import free_port, run_cli
from mexone.foxglove.server import json_schema, to_json

HERE = Path(__file__).parent
SRC = HERE.parents[1] / "src"
NODE_MODULES = HERE / "node_modules" / "@foxglove" / "ws-protocol"


@pytest.fixture(scope="module")
def seen():
    pytest.importorskip("foxglove", reason="foxglove-sdk is not installed (pip install "
                                           "'.[foxglove]')")
    node = shutil.which("node")
    if node is None or not NODE_MODULES.is_dir():
        pytest.skip("node and `npm install --prefix tests/foxglove_ws` are needed (scripts/test.sh)")
    port = free_port()
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(SRC), os.environ.get("PYTHONPATH", "")]))
    sim = subprocess.Popen([sys.executable, "-m", "mexone", "sim", "--foxglove", str(port),
                            "--headless"], env=env, stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True)
    try:
        # the server listens once the line naming it is out
        line = sim.stderr.readline()
        assert f"ws://127.0.0.1:{port}" in line, line + sim.stderr.read()
        client = subprocess.run([node, str(HERE / "client.js"), f"ws://127.0.0.1:{port}",
                                 "/mex_rb/joint_states", "/mex_rb/kinect/rgb/image_raw"],
                                capture_output=True, text=True, timeout=120, cwd=HERE)
    finally:
        sim.terminate()
        _, err = sim.communicate(timeout=30)
    assert client.returncode == 0, client.stderr + err
    return json.loads(client.stdout)


def test_every_topic_is_a_channel_with_its_schema(seen):
    channels = seen["channels"]
    assert "error" not in seen
    assert channels["/mex_rb/joint_states"] == {"schemaName": "sensor_msgs/msg/JointState",
                                                "encoding": "json",
                                                "schemaEncoding": "jsonschema"}
    assert channels["/mex_rb/kinect/rgb/image_raw"]["schemaName"] == "foxglove.RawImage"
    assert channels["/tf"]["schemaName"] == "foxglove.FrameTransforms"
    assert channels["/robot_description"]["schemaName"] == "std_msgs/msg/String"
    for topic in ("/mex_rb/imu", "/mex_rb/l_ankle_ft", "/mex_rb/kinect/depth/points",
                  "/mex_rb/neck_yaw_position_controller/state"):
        assert topic in channels


def test_joint_states_decode_with_sim_time(seen):
    states = seen["joint_states"]
    assert len(states) == 5
    assert len(states[0]["name"]) == len(states[0]["position"]) == 21
    stamps = [s["stamp"]["sec"] * 1e9 + s["stamp"]["nsec"] for s in states]
    assert stamps == sorted(stamps) and stamps[-1] - stamps[0] == pytest.approx(4 * 0.02e9)  # 50 Hz
    assert states[-1]["log_time"] == stamps[-1]  # logged at the message's sim time
    assert seen["times"] and max(seen["times"]) >= stamps[0] - 0.1e9  # the server's clock is sim time


def test_image_decodes(seen):
    image = seen["images"][0]
    assert (image["width"], image["height"], image["encoding"]) == (640, 480, "rgb8")
    assert image["bytes"] == image["step"] * image["height"] == 640 * 480 * 3
    assert 5 < image["mean"] < 250  # a rendered scene, not a blank buffer


def test_urdf_is_served_and_nothing_outside_the_package(seen):
    assert seen["server"]["capabilities"] == ["time", "assets"]
    assert seen["asset"] > 1000  # package://mex_rb/urdf/mex_rb.urdf, for the 3D panel
    assert seen["escape"] == "refused"


def test_schema_and_message_agree():
    from mexone.bus import msgs

    schema = json_schema(msgs.JointState)
    message = to_json(msgs.JointState(msgs.Header(3, msgs.Time(1, 5), "base"), ["a"], [1.0]))
    assert set(schema["properties"]) == set(message)
    assert set(schema["properties"]["header"]["properties"]) == set(message["header"]) == {
        "stamp", "frame_id"}
    assert message["header"]["stamp"] == {"sec": 1, "nsec": 5}
    assert to_json(msgs.Image(data=b"\x00\xff"))["data"] == "AP8="


def test_a_taken_port_is_one_line():
    pytest.importorskip("foxglove")
    import socket

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        code, _, err = run_cli(["sim", "--foxglove", str(port), "--headless", "--duration",
                                "0.01"])
    assert code == 2 and err.count("\n") == 1 and f"127.0.0.1:{port}" in err
