"""Bags, plots, CSV and videos, each read back by an independent reader."""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from mexone.lab import Lab
from mexone.record.bag import BagRecorder
from mexone.routines.runner import RoutineRunner


def mexone(*args, cwd=None, timeout=240):
    return subprocess.run([sys.executable, "-m", "mexone", *args], capture_output=True, text=True,
                          cwd=cwd, timeout=timeout)


def record_sweep(path: Path):
    lab = Lab.create()
    recorder = BagRecorder(lab, path)
    RoutineRunner(lab, "joint_steps").run(2.0)
    recorder.close()
    published = {name: topic.count for name, topic in lab.bus.topics.items() if topic.count}
    return path, published


@pytest.fixture(scope="module", params=[".mcap", ".bag"])
def recorded(request, tmp_path_factory):
    return record_sweep(tmp_path_factory.mktemp("bags") / f"sweep{request.param}")


def test_every_published_message_is_in_the_bag(recorded):
    path, published = recorded
    with AnyReader([path]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        types = {c.topic: c.msgtype for c in reader.connections}
        states = [reader.deserialize(raw, c.msgtype) for c, _, raw in
                  reader.messages(connections=[c for c in reader.connections
                                               if c.topic == "/mex_rb/joint_states"])]
    assert counts == published
    assert counts["/mex_rb/joint_states"] == 100 and counts["/clock"] == 2000
    assert types["/tf"] == "tf2_msgs/msg/TFMessage"
    assert types["/mex_rb/l_shoulder_pitch_position_controller/command"] == "std_msgs/msg/Float64"
    assert types["/mex_rb/l_elbow_position_controller/state"] == \
        "control_msgs/msg/JointControllerState"
    stamps = [s.header.stamp.sec + s.header.stamp.nanosec * 1e-9 for s in states]
    np.testing.assert_allclose(stamps, 0.02 * np.arange(1, 101), atol=1e-9)
    assert list(states[0].name) == sorted(states[0].name)


def test_sensor_topics_are_recorded_and_read_back(recorded):
    """IMU, ankle wrenches, sole contacts and the balance topics, at their rates; no images."""
    path, published = recorded
    with AnyReader([path]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        types = {c.topic: c.msgtype for c in reader.connections}
        contact = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages(
            connections=[c for c in reader.connections if c.topic == "/mex_rb/l_foot_contact"])]
        imu = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages(
            connections=[c for c in reader.connections if c.topic == "/mex_rb/imu"])]
    assert counts["/mex_rb/imu"] == 200 and counts["/mex_rb/l_ankle_ft"] == 200
    assert counts["/mex_rb/l_foot_contact"] == 100 and counts["/mex_rb/zmp"] == 100
    assert types["/mex_rb/l_foot_contact"] == "gazebo_msgs/msg/ContactsState"
    assert types["/mex_rb/support_polygon"] == "geometry_msgs/msg/PolygonStamped"
    assert not any("kinect" in t for t in counts)  # cameras render for subscribers only
    assert contact[-1].states[0].collision1_name == "mex_rb::l_foot::l_foot_collision_0"
    assert np.mean([m.linear_acceleration.z for m in imu[50:]]) == pytest.approx(9.81, abs=0.05)


def test_mcap_is_plain_rosbag2_for_the_mcap_library(tmp_path):
    path, published = record_sweep(tmp_path / "sweep.mcap")
    store = get_typestore(Stores.ROS2_HUMBLE)
    counts: dict[str, int] = {}
    with path.open("rb") as handle:
        reader = make_reader(handle)
        assert reader.get_header().profile == "ros2"
        for schema, channel, message in reader.iter_messages():
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if channel.topic == "/mex_rb/joint_states":
                msg = store.deserialize_cdr(message.data, schema.name)
                assert len(msg.position) == 21 and message.log_time % 1_000_000 == 0
    assert counts == published


def test_plot_png_and_csv(recorded, tmp_path):
    path, _ = recorded
    png = tmp_path / "out.png"
    out = mexone("plot", str(path), "-o", str(png))
    assert out.returncode == 0, out.stderr
    from PIL import Image

    image = np.asarray(Image.open(png).convert("L"), dtype=float)
    assert image.shape[0] > 200 and image.shape[1] > 800 and image.std() > 10
    table = tmp_path / "out.csv"
    out = mexone("plot", str(path), "-o", str(table), "--joints", "l_shoulder_pitch", "l_knee")
    assert out.returncode == 0, out.stderr
    rows = list(csv.DictReader(table.open()))
    assert len(rows) == 2 * 100
    elbow = [r for r in rows if r["joint"] == "l_shoulder_pitch"]
    assert min(float(r["command_rad"]) for r in elbow) < -1.0  # the sweep went down
    knee = [r for r in rows if r["joint"] == "l_knee"]
    assert all(r["command_rad"] == "" for r in knee)  # no command was sent to the knee


def test_plot_topic_fields_as_rqt_plot_names_them(recorded, tmp_path):
    """`--topics` takes rqt_plot's paths: a field, a sub-message or a whole topic."""
    path, _ = recorded
    table = tmp_path / "imu.csv"
    out = mexone("plot", str(path), "-o", str(table), "--topics",
                 "/mex_rb/imu/linear_acceleration/z", "/mex_rb/l_ankle_ft/wrench/force")
    assert out.returncode == 0, out.stderr
    rows = list(csv.DictReader(table.open()))
    fields = {r["field"] for r in rows}
    assert fields == {"/mex_rb/imu/linear_acceleration/z"} | {
        f"/mex_rb/l_ankle_ft/wrench/force/{c}" for c in "xyz"}
    acc = [r for r in rows if r["field"].endswith("acceleration/z")]
    times = np.array([float(r["time_s"]) for r in acc])
    np.testing.assert_allclose(np.diff(times), 0.01, atol=1e-6)  # 100 Hz of header stamps
    assert len(acc) == 200
    # the pelvis barely moves while the arms sweep: proper acceleration ~ +g, up
    assert np.median([float(r["value"]) for r in acc]) == pytest.approx(9.81, abs=0.2)
    png = tmp_path / "imu.png"
    out = mexone("plot", str(path), "-o", str(png), "--topics", "/mex_rb/imu", "/mex_rb/zmp")
    assert out.returncode == 0 and "13 fields" in out.stdout, out.stdout + out.stderr  # 10 + 3
    out = mexone("plot", str(path), "-o", str(tmp_path / "x.png"), "--topics", "/mex_rb/imu/foo")
    assert out.returncode == 2 and out.stderr.count("\n") == 1 and "/mex_rb/imu/foo" in out.stderr


def test_render_mp4_and_gif(tmp_path):
    import imageio.v3 as iio

    mp4 = tmp_path / "arms.mp4"
    out = mexone("render", "arms", "-o", str(mp4), "--duration", "2", "--size", "320x240")
    assert out.returncode == 0, out.stderr
    frames = iio.imread(mp4)
    assert frames.shape == (60, 240, 320, 3)
    assert np.abs(frames[-1].astype(int) - frames[0]).mean() > 0.1  # the arms moved
    assert frames[0].std() > 10
    gif = tmp_path / "arms.gif"
    out = mexone("render", "arms", "-o", str(gif), "--duration", "0.5", "--size", "160x120",
                 "--camera", "90,-20,3")
    assert out.returncode == 0, out.stderr
    assert iio.imread(gif).shape[0] == 15


def test_bad_outputs(tmp_path):
    out = mexone("record", "-o", str(tmp_path / "run.txt"), "--duration", "0.1")
    assert out.returncode == 2 and "name the bag .mcap (ROS 2) or .bag (ROS 1)" in out.stderr
    kept = tmp_path / "kept.mcap"
    kept.write_text("mine")
    out = mexone("record", "-o", str(kept), "--duration", "0.1")
    assert out.returncode == 2 and kept.read_text() == "mine" and "--force" in out.stderr
    notbag = tmp_path / "notbag.bag"
    notbag.write_text("hello")
    out = mexone("plot", str(notbag), "-o", str(tmp_path / "p.png"))
    assert out.returncode == 2 and "not a bag (it starts with neither" in out.stderr
    assert out.stderr.count("\n") == 1


def test_plot_unknown_joint(recorded, tmp_path):
    path, _ = recorded
    out = mexone("plot", str(path), "-o", str(tmp_path / "x.png"), "--joints", "l_wing")
    assert out.returncode == 2 and "the bag has no joint l_wing" in out.stderr


def test_sim_and_run_take_record(tmp_path):
    bag = tmp_path / "run.bag"
    out = mexone("run", "home", "--duration", "0.5", "--quiet", "--record", str(bag))
    assert out.returncode == 0, out.stderr
    with AnyReader([bag]) as reader:
        assert {c.topic for c in reader.connections} >= {"/mex_rb/joint_states", "/clock", "/tf"}
    bag2 = tmp_path / "sim.mcap"
    out = mexone("sim", "--headless", "--duration", "0.3", "--record", str(bag2))
    assert out.returncode == 0 and Path(bag2).stat().st_size > 1000
