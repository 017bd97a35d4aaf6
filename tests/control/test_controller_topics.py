"""A Python controller's topics (PythonController.topics): each update sees the newest message
that arrived on `/<ns>/<name>` since the last one, or None; nothing arrives while the
controller is stopped; a malformed declaration is a TypeError naming the class."""

from __future__ import annotations

import textwrap

import pytest

from mexone.bus.msgs import Float64
from mexone.control import PythonController, load_control_config
from mexone.description.urdf import read_urdf
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
"""


@pytest.fixture
def lab(tmp_path, turntable):
    write_urdf, _ = turntable
    write_urdf(tmp_path)
    (tmp_path / "listening.py").write_text(CONTROLLER)
    (tmp_path / "controllers.yaml").write_text(textwrap.dedent("""\
        turntable:
          listener:
            type: listening/Listener
            joints: [yaw]
            update_rate: 100
        """))
    return Lab.create(read_urdf(tmp_path / "turntable.urdf"),
                      load_control_config(tmp_path / "controllers.yaml"))


def _listener(lab):
    runner = lab.manager.controllers["listener"]
    return runner, runner.impl


def test_each_update_sees_the_newest_message_since_the_last_or_none(lab):
    runner, impl = _listener(lab)
    ns = lab.namespace
    lab.sim.step(20)  # two updates, nothing published
    assert impl.seen[-1] == {"setpoint": None, "limits/max": None}
    lab.bus.publish(f"{ns}/setpoint", Float64(1.0))
    lab.bus.publish(f"{ns}/setpoint", Float64(2.0))  # the newer one wins
    lab.bus.publish(f"{ns}/limits/max", Float64(9.0))
    before = len(impl.seen)
    lab.sim.step(10)
    assert impl.seen[before] == {"setpoint": 2.0, "limits/max": 9.0}
    lab.sim.step(10)
    assert impl.seen[-1] == {"setpoint": None, "limits/max": None}  # taken once, not again
    assert len(lab.bus.topic(f"{ns}/setpoint", Float64).subscriptions) == 1


def test_a_stopped_controller_holds_no_subscription_and_sees_nothing_sent_meanwhile(lab):
    runner, impl = _listener(lab)
    ns = lab.namespace
    lab.manager.switch(stop=["listener"])
    assert lab.bus.topic(f"{ns}/setpoint", Float64).subscriptions == []
    lab.bus.publish(f"{ns}/setpoint", Float64(5.0))
    lab.manager.switch(start=["listener"])
    lab.sim.step(10)
    assert impl.seen[-1]["setpoint"] is None
    lab.bus.publish(f"{ns}/setpoint", Float64(6.0))
    lab.sim.step(10)
    assert impl.seen[-1]["setpoint"] == 6.0


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
