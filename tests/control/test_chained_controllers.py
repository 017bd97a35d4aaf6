"""Chained controllers (ros2_control's chaining): an exporter's state interface read by another
controller in the same cycle, whatever their order in the YAML; a stopped exporter reads NaN;
swapping the exporter's type leaves the reader untouched; every wiring mistake refused at load
with the YAML's line; a controller that claims no joints."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
import pytest

from mexone.control import PythonController, load_control_config
from mexone.description.urdf import read_urdf
from mexone.errors import InputError
from mexone.lab import Lab

CONTROLLERS = """\
import numpy as np
from mexone.control import Param, PythonController

class Estimator(PythonController):
    exports = {"angle": 1, "rate": 1}
    def update(self, state, t, dt):
        self.exports["angle"][0] = state.all_q[0]
        self.exports["rate"][:] = state.all_dq[:1]
        self.exports_at = t

class DoubledEstimator(Estimator):
    def update(self, state, t, dt):
        self.exports["angle"][0] = 2 * state.all_q[0]
        self.exports["rate"][0] = 2 * state.all_dq[0]

class Holder(PythonController):
    inputs = {"angle": 1, "rate": 1}
    kp = Param(20.0, low=0.0)
    def configure(self):
        self.seen = []
    def update(self, state, t, dt):
        angle, rate = state.inputs["angle"][0], state.inputs["rate"][0]
        self.seen.append((t, angle, state.q[0]))
        if np.isnan(angle):
            return [0.0]
        return [-self.kp * (angle - 0.5) - 2.0 * rate]
    def report(self):  # it runs in a process of its own: what the tests read comes back here
        return {"seen": self.seen[-1]}

class Rebinder(PythonController):
    exports = {"angle": 1}
    def update(self, state, t, dt):
        self.exports["angle"] = np.zeros(1)
"""

YAML = """\
turntable:
  holder:
    type: chained/Holder
    joints: [yaw]
    inputs: {{angle: {estimator}/angle, rate: {estimator}/rate}}
  estimator:
    type: chained/{estimator_type}
    joints: []
"""


def _files(folder: Path, turntable, yaml_text: str) -> Path:
    write_urdf, _ = turntable
    write_urdf(folder)
    (folder / "chained.py").write_text(CONTROLLERS)
    path = folder / "controllers.yaml"
    path.write_text(textwrap.dedent(yaml_text))
    return path


def _lab(folder: Path, turntable, estimator_type: str = "Estimator") -> Lab:
    path = _files(folder, turntable, YAML.format(estimator="estimator", estimator_type=estimator_type))
    return Lab.create(read_urdf(folder / "turntable.urdf"), load_control_config(path))


def test_a_reader_sees_its_exporters_value_of_the_same_cycle(tmp_path, turntable):
    lab = _lab(tmp_path, turntable)
    manager = lab.manager
    assert [c.name for c in manager._running if c.kind == "python"] == ["estimator", "holder"]
    lab.sim.step(2000)
    t, angle, q = manager.controllers["holder"].report()["seen"]
    assert angle == q  # the estimator ran first in this very cycle
    assert lab.sim.joint_positions()[0] == pytest.approx(0.5, abs=1e-3)  # it regulates on it
    assert manager.exports()["estimator/angle"][0] == pytest.approx(0.5, abs=1e-3)
    with pytest.raises(ValueError):
        manager.exports()["estimator/angle"][0] = 1.0  # front ends read, never write


def test_a_stopped_exporter_reads_nan_and_a_swapped_one_is_read_the_same_way(tmp_path, turntable):
    lab = _lab(tmp_path, turntable)
    manager = lab.manager
    lab.sim.step(10)
    manager.stop("estimator")
    lab.sim.step(10)
    holder = manager.controllers["holder"]
    assert np.isnan(holder.report()["seen"][1])
    manager.start("estimator")
    lab.sim.step(10)
    assert holder.report()["seen"][1] == holder.report()["seen"][2]

    (tmp_path / "swapped").mkdir()
    swapped = _lab(tmp_path / "swapped", turntable, estimator_type="DoubledEstimator")
    swapped.sim.step(1500)
    _, angle, q = swapped.manager.controllers["holder"].report()["seen"]
    assert angle == 2 * q and q == pytest.approx(0.25, abs=1e-3)  # only the estimator changed


def test_rebinding_an_export_is_the_students_fault(tmp_path, turntable):
    path = _files(tmp_path, turntable, """\
        turntable:
          estimator: {type: chained/Rebinder, joints: []}
        """)
    lab = Lab.create(read_urdf(tmp_path / "turntable.urdf"), load_control_config(path))
    lab.sim.step(3)
    fault = lab.manager.controllers["estimator"].fault
    assert "write into it" in fault and "chained.py:" in fault


@pytest.mark.parametrize(("yaml_text", "line", "message"), [
    ("""\
turntable:
  holder: {type: chained/Holder, joints: [yaw]}
""", 2, "input 'angle' is not bound"),
    ("""\
turntable:
  holder:
    type: chained/Holder
    joints: [yaw]
    inputs: {angle: nobody/angle, rate: nobody/rate}
""", 5, "'nobody' is not a Python controller of this file"),
    ("""\
turntable:
  holder:
    type: chained/Holder
    joints: [yaw]
    inputs: {angle: est/speed, rate: est/rate}
  est: {type: chained/Estimator, joints: []}
""", 5, "'est' (Estimator) does not export 'speed'"),
    ("""\
turntable:
  holder:
    type: chained/Holder
    joints: [yaw]
    inputs: {angle: est/angle, rate: est/rate, extra: est/rate}
  est: {type: chained/Estimator, joints: []}
""", 5, "inputs names 'extra', which Holder does not declare"),
    ("""\
turntable:
  holder:
    type: chained/Holder
    joints: [yaw]
    inputs: {angle: est, rate: est/rate}
  est: {type: chained/Estimator, joints: []}
""", 5, "input 'angle' must name '<controller>/<export>'"),
])
def test_wiring_mistakes_are_refused_at_the_yamls_line(tmp_path, turntable, yaml_text, line, message):
    path = _files(tmp_path, turntable, yaml_text)
    with pytest.raises(InputError) as caught:
        load_control_config(path)
    assert message in str(caught.value) and caught.value.line == line, str(caught.value)


def test_a_circle_of_readers_is_refused(tmp_path, turntable):
    write_urdf, _ = turntable
    (tmp_path / "circle.py").write_text(textwrap.dedent("""\
        from mexone.control import PythonController

        class Both(PythonController):
            exports = {"x": 1}
            inputs = {"x": 1}
        """))
    path = tmp_path / "controllers.yaml"
    path.write_text(textwrap.dedent("""\
        turntable:
          a: {type: circle/Both, joints: [], inputs: {x: b/x}}
          b: {type: circle/Both, joints: [], inputs: {x: c/x}}
          c: {type: circle/Both, joints: [], inputs: {x: b/x}}
        """))
    with pytest.raises(InputError, match=r"read each other in a circle: b -> c -> b"):
        load_control_config(path)


@pytest.mark.parametrize(("attribute", "value", "message"), [
    ("exports", {"a/b": 1}, "is not a name"),
    ("exports", {"x": 0}, "must be a whole number >= 1"),
    ("inputs", ["x"], "must be a dict of name -> length"),
])
def test_a_malformed_declaration_fails_at_the_class(attribute, value, message):
    with pytest.raises(TypeError, match=message):
        type("Bad", (PythonController,), {attribute: value})
