"""A Python controller's topics (PythonController.topics): each update sees the newest message
that arrived on `/<ns>/<name>` since the last one, or None; nothing arrives while the
controller is stopped; a malformed declaration is a TypeError naming the class. The same class
in the lab's process (handed over in Python) and in its own process (named by the YAML: the
messages cross to its worker)."""

from __future__ import annotations

import textwrap

import pytest

from mexone.bus.msgs import Float64, Header, Point, Pose, PoseArray, Quaternion, Time
from mexone.control import PythonController, load_control_config
from mexone.description.urdf import read_urdf
from mexone.errors import MexoneError
from mexone.lab import Lab

CONTROLLER = """\
from mexone.bus.msgs import Float64
from mexone.control import PythonController

class Listener(PythonController):
    topics = {"setpoint": Float64, "limits/max": Float64}
    def configure(self):
        self.seen = []
    def update(self, state, t, dt):
        self.seen.append({name: (msg.data if msg is not None else None)
                          for name, msg in state.messages.items()})
        return [0.0]
    def report(self):
        return {"seen": self.seen}
"""

POSE = """from mexone.bus.msgs import PoseArray
from mexone.control import PythonController

class Poses(PythonController):
    topics = {"targets": PoseArray}
    def configure(self):
        self.got = None
    def update(self, state, t, dt):
        msg = state.messages["targets"]
        if msg is not None:
            self.got = [type(msg).__name__, msg.header.frame_id, msg.header.stamp.to_sec(),
                        [[p.position.x, p.orientation.w] for p in msg.poses]]
        return [0.0]
    def report(self):
        return {"got": self.got}
"""


def _lab(tmp_path, turntable, where: str, module: str, text: str, cls: str):
    write_urdf, _ = turntable
    write_urdf(tmp_path)
    (tmp_path / f"{module}.py").write_text(text)
    (tmp_path / "controllers.yaml").write_text(textwrap.dedent(f"""\
        turntable:
          listener:
            type: {module}/{cls}
            joints: [yaw]
            update_rate: 100
        """))
    classes = None
    if where == "in the lab's process":
        namespace: dict = {"__name__": module}
        exec(compile(text, str(tmp_path / f"{module}.py"), "exec"), namespace)
        classes = {f"{module}/{cls}": namespace[cls]}
    return Lab.create(read_urdf(tmp_path / "turntable.urdf"),
                      load_control_config(tmp_path / "controllers.yaml", classes=classes))


@pytest.fixture(params=["in the lab's process", "in its own process"])
def lab(request, tmp_path, turntable):
    return _lab(tmp_path, turntable, request.param, "listening", CONTROLLER, "Listener")


def _seen(lab) -> list[dict]:
    return lab.manager.controllers["listener"].report()["seen"]


def test_each_update_sees_the_newest_message_since_the_last_or_none(lab):
    ns = lab.namespace
    lab.sim.step(20)  # two updates, nothing published
    assert _seen(lab)[-1] == {"setpoint": None, "limits/max": None}
    lab.bus.publish(f"{ns}/setpoint", Float64(1.0))
    lab.bus.publish(f"{ns}/setpoint", Float64(2.0))  # the newer one wins
    lab.bus.publish(f"{ns}/limits/max", Float64(9.0))
    before = len(_seen(lab))
    lab.sim.step(10)
    assert _seen(lab)[before] == {"setpoint": 2.0, "limits/max": 9.0}
    lab.sim.step(10)
    assert _seen(lab)[-1] == {"setpoint": None, "limits/max": None}  # taken once, not again
    assert len(lab.bus.topic(f"{ns}/setpoint", Float64).subscriptions) == 1


def test_a_stopped_controller_holds_no_subscription_and_sees_nothing_sent_meanwhile(lab):
    ns = lab.namespace
    lab.manager.switch(stop=["listener"])
    assert lab.bus.topic(f"{ns}/setpoint", Float64).subscriptions == []
    lab.bus.publish(f"{ns}/setpoint", Float64(5.0))
    lab.manager.switch(start=["listener"])
    lab.sim.step(10)
    assert _seen(lab)[-1]["setpoint"] is None
    lab.bus.publish(f"{ns}/setpoint", Float64(6.0))
    lab.sim.step(10)
    assert _seen(lab)[-1]["setpoint"] == 6.0


def test_a_nested_message_reaches_a_worker_whole(tmp_path, turntable):
    """A message of messages (header, stamp, a list of poses) is rebuilt in the worker as the
    same classes with the same numbers."""
    lab = _lab(tmp_path, turntable, "in its own process", "posing", POSE, "Poses")
    lab.bus.publish(f"{lab.namespace}/targets", PoseArray(
        Header(3, Time.from_sec(1.5), "world"),
        [Pose(Point(0.25, 0, 0), Quaternion(w=0.5)), Pose(Point(-1.0, 0, 0))]))
    lab.sim.step(10)
    assert lab.manager.controllers["listener"].report()["got"] == \
        ["PoseArray", "world", 1.5, [[0.25, 0.5], [-1.0, 1.0]]]


def test_a_worker_takes_only_mexone_messages(tmp_path, turntable):
    """A controller in its own process declaring a topic of a class of its own is refused in
    one line naming the class (only mexone.bus.msgs messages cross to a worker)."""
    text = CONTROLLER.replace("from mexone.bus.msgs import Float64",
                              "from dataclasses import dataclass\n@dataclass\nclass Float64:\n"
                              "    data: float = 0.0")
    with pytest.raises(MexoneError, match=r"Listener.topics\['setpoint'\]: Float64 is not a "
                                          "message class of mexone.bus.msgs"):
        _lab(tmp_path, turntable, "in its own process", "listening", text, "Listener")


@pytest.mark.parametrize("topics, message", [
    (["cmd_vel"], "must be a dict of topic name -> message class, not list"),
    ({"/cmd_vel": Float64}, "is not a topic name relative to the robot's namespace"),
    ({"cmd vel": Float64}, "is not a topic name relative"),
    ({"cmd_vel": "Twist"}, r"topics\['cmd_vel'\] must be a message class"),
])
def test_a_malformed_topics_declaration_names_the_class(topics, message):
    with pytest.raises(TypeError, match="Bad.topics") as info:
        type("Bad", (PythonController,), {"topics": topics})
    assert info.match(message)
