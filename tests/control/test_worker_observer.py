"""A student's Observer subclass (mexone.design.observers) named in a controllers YAML runs in the
controller worker like any student class (issue 36: every student PythonController from a YAML
runs in a process of its own): `mexone sim` runs it, its estimate tracks the true state, a
chained reader in another worker reads its export, and it estimates what the same class in the
lab's own process estimates (the worker reads the same encoders and motor torques)."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest
import yaml

from mexone.control.config import load_control_config
from mexone.design import linearize, operating_point
from mexone.design.observers import kalman, save_estimator
from mexone.lab import Lab
from mexone.robots import mex_one

STUDENT = '''
import numpy as np

from mexone.control import PythonController
from mexone.design.observers import Observer


class RateKF(Observer):
    """A student's Kalman filter of the left elbow's rate, from its encoder."""

    exports = {"rate": 1}


class RateReader(PythonController):
    """A chained reader: keeps what the filter exported, as a controller acting on it would."""

    inputs = {"rate": 1}

    def configure(self):
        self.seen = []

    def update(self, state, t, dt):
        self.seen.append(float(state.inputs["rate"][0]))

    def report(self):
        return {"updates": len(self.seen), "finite": bool(np.isfinite(self.seen[1:]).all()),
                "last": self.seen[-1] if self.seen else None}
'''


@pytest.fixture(scope="module")
def student_yaml(tmp_path_factory):
    """The student's folder: the design file (a Kalman filter of the elbow, its rate
    exported), the class file and the YAML: the filter, the reader, the shipped PD."""
    folder = tmp_path_factory.mktemp("observer")
    lab = Lab.create()
    lab.sim.run(0.3)
    point = operating_point(lab, support="fixed")
    plant = linearize(lab, point=point, joints=["l_elbow"], held="rigid", fixed_base=True,
                      period=0.001)
    est = kalman(plant, ["l_elbow:q"], [10.0], [1e-8], exports={"rate": np.array([[0.0, 1.0]])})
    save_estimator(folder / "kf.npz", est)
    (folder / "rate_kf.py").write_text(textwrap.dedent(STUDENT))
    ns, shipped = next(iter(yaml.safe_load(mex_one.controllers_path().read_text()).items()))
    entries = {"rate_kf": {"type": "rate_kf/RateKF", "joints": [], "update_rate": 1000,
                           "design_file": "kf.npz"},
               "reader": {"type": "rate_kf/RateReader", "joints": [],
                          "inputs": {"rate": "rate_kf/rate"}}}
    path = folder / "controllers.yaml"
    path.write_text(yaml.safe_dump({ns: {**entries, **shipped}}, sort_keys=False))
    return path


def test_sim_runs_a_students_observer_in_its_worker(student_yaml):
    out = subprocess.run([sys.executable, "-m", "mexone", "sim", "--headless", "--duration", "1",
                          "--controllers", str(student_yaml), "--json"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "Traceback" not in out.stderr
    reports = json.loads(out.stdout)["controllers"]
    assert "fault" not in reports["rate_kf"] and "fault" not in reports["reader"], reports
    assert reports["reader"]["updates"] >= 999 and reports["reader"]["finite"], reports


def estimates(lab: Lab) -> tuple[np.ndarray, np.ndarray]:
    """The forearm pushed: (the filter's exported rate, the elbow's true rate) every step."""
    model = lab.sim.model
    dof = int(model.jnt_dofadr[model.joint("l_elbow").id])
    exported = lab.manager.exports()["rate_kf/rate"]
    estimate, true = [], []

    def sample(sim) -> None:
        estimate.append(float(exported[0]))
        true.append(float(sim.data.qvel[dof]))

    lab.sim.run(0.3)
    lab.sim.add_periodic(lab.sim.timestep, sample)
    lab.sim.apply_wrench("l_forearm", (20.0, 0.0, 0.0), duration=0.1)
    lab.sim.run(0.4)
    return np.array(estimate), np.array(true)


def test_the_workers_estimate_tracks_the_elbow_as_in_the_labs_process(student_yaml):
    lab = Lab.create(controllers=student_yaml)
    assert type(lab.manager.controllers["rate_kf"]).__name__ == "IsolatedRunner"  # its worker
    worker, true = estimates(lab)
    assert np.sqrt(np.mean(true**2)) > 0.05  # the push moved the elbow
    assert np.sqrt(np.mean((worker - true) ** 2)) < 0.1 * np.sqrt(np.mean(true**2))
    here, _ = estimates(Lab.create(controllers=load_control_config(student_yaml,
                                                                   in_process=True)))
    np.testing.assert_allclose(worker, here, atol=1e-9)
