"""`mexone identify` against synthetic truth: bags recorded from a Mex-One whose damping, friction,
armature and torso mass were changed by known factors, fitted with the unchanged model. Small
versions (three joints, 6 s bags) here; the whole robot in tests marked slow and in
benchmarks/identify.py."""

from __future__ import annotations

import json
import logging
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
import bagtools  # noqa: E402

from mexone import signals  # noqa: E402
from mexone.cli import main  # noqa: E402
from mexone.description.check import check_model  # noqa: E402
from mexone.description.loader import load_model  # noqa: E402
from mexone.identify.recording import regular_times  # noqa: E402
from mexone.identify.session import Options, identify  # noqa: E402

SMALL = ("l_hip_pitch", "l_knee", "l_elbow")  # a leg (two joints that load each other), an arm
TOLERANCE = {"damping": 0.05, "mass": 0.05, "frictionloss": 0.10, "armature": 0.10}


@pytest.fixture(scope="module")
def hung(tmp_path_factory):
    """Truth differs from nominal on SMALL only; a fitting bag and a held-out one, on a stand."""
    folder = tmp_path_factory.mktemp("hung")
    models = bagtools.make_models(folder, joints=SMALL, torso=False)
    fit = bagtools.record(folder / "fit.mcap", models.truth, models.controllers, "fixed", 6.0)
    val = bagtools.record(folder / "val.mcap", models.truth, models.controllers, "fixed", 6.0,
                          seed=1)
    return models, fit, val


def _errors(result, truth: dict[str, float]) -> dict[str, float]:
    """Relative error of every identified value against the truth."""
    return {u.name: abs(result.fit.values[i] / truth[u.name] - 1)
            for i, u in enumerate(result.fit.unknowns) if not u.nuisance}


def _assert_within(errors: dict[str, float], scale: float = 1.0) -> None:
    wrong = {name: round(err, 4) for name, err in errors.items()
             if err > scale * TOLERANCE[name.split(":")[0]]}
    assert wrong == {}, errors


def test_recovers_damping_friction_and_armature_and_validation_rms_drops_10x(hung):
    models, fit, val = hung
    options = Options(model=models.nominal, controllers=models.controllers, joints=SMALL)
    result = identify([fit], options, [val])
    _assert_within(_errors(result, models.values))
    assert len(result.fit.unknowns) == 9 + 1 and not result.fit.interrupted
    assert result.rms_before > 1e-4  # the nominal model was measurably wrong
    assert result.rms_before / result.rms_after >= 10
    assert np.all(np.isfinite(result.fit.halfwidth))  # exact data: tiny, but computed


@pytest.mark.slow
def test_noise_and_jitter_still_within_10_percent(hung, tmp_path):
    """1 mrad of Gaussian noise on positions, 10 ms of stamp jitter (and receive times late by
    as much), joint names shuffled in every message, written as a ROS 1 bag by a driver
    publishing joint states at 500 Hz; 20 s of data (6 s leave friction 50% uncertain)."""
    _, _, val = hung
    models = bagtools.make_models(tmp_path, joint_state_rate=500.0, joints=SMALL, torso=False)
    clean = bagtools.record(tmp_path / "clean.mcap", models.truth, models.controllers, "fixed", 20.0)
    noisy = bagtools.rewrite_ros1(clean, tmp_path / "noisy.bag", noise=1e-3, jitter=0.010,
                                  shuffle=True, seed=3)
    options = Options(model=models.nominal, controllers=models.controllers, joints=SMALL)
    result = identify([noisy], options, [val])
    errors = _errors(result, models.values)
    wrong = {n: round(e, 4) for n, e in errors.items() if e > 0.10}
    assert wrong == {}, errors
    assert result.rms_before / result.rms_after >= 10
    # the 95% intervals are honest: the truth within three half-widths of every value
    half = result.fit.halfwidth
    truth = np.array([models.values.get(u.name, 0.0) for u in result.fit.unknowns])
    miss = np.abs(result.fit.values - truth) / half
    assert np.all(np.isfinite(half)) and np.all(miss[:-1] < 3), miss  # (the delay's truth: ~0)


@pytest.mark.slow
def test_torso_mass_from_a_standing_squat(tmp_path):
    """The torso 20% heavier, seen by a standing robot's knees and hips as it squats."""
    models = bagtools.make_models(tmp_path, joints=(), torso=True)
    bag = bagtools.record(tmp_path / "stand.mcap", models.truth, models.controllers, "standing", 5.0)
    options = Options(model=models.nominal, controllers=models.controllers, params=("mass",),
                      links=("torso",))
    result = identify([bag], options)
    _assert_within(_errors(result, models.values))
    assert result.experiments[0].fixed_base is False


def test_regular_times_removes_jitter():
    rng = np.random.default_rng(0)
    true = 3.0 + 0.02 * np.arange(500)
    stamps = true + rng.normal(0, 0.010, true.size)
    fitted = regular_times(stamps)
    assert np.sqrt(np.mean((fitted - true) ** 2)) < 0.001  # 10 ms of jitter -> under 1 ms
    steps = np.cumsum(rng.uniform(0.01, 0.5, 50))  # a student's commands: left alone
    assert np.array_equal(regular_times(steps), steps)


# ----- the command line ---------------------------------------------------------------------------

def run_cli(argv: list[str], capsys, monkeypatch) -> tuple[int, str, str]:
    monkeypatch.setattr(signals, "stop_on_signals", lambda: None)  # pytest keeps its handlers
    logging.getLogger("mexone").handlers.clear()
    code = main(argv)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_cli_json_patched_urdf_and_report(hung, tmp_path, capsys, monkeypatch):
    models, fit, val = hung
    out = tmp_path / "out"
    argv = [str(fit), "--model", str(models.nominal), "--controllers", str(models.controllers),
            "--joints", "l_elbow", "--params", "damping,armature", "--validate", str(val),
            "-o", str(out), "--json", "--max-iterations", "4"]
    code, stdout, err = run_cli(["identify", *argv], capsys, monkeypatch)
    assert code == 0, err
    report = json.loads(stdout)  # one object, nothing else on stdout
    assert set(report["params"]) == {"damping", "armature"}
    assert set(report["params"]["damping"]) == {"l_elbow"}
    assert report["rms_after"] < report["rms_before"]
    # the patched URDF, read back by mexone's reader and by urdfdom's check_urdf
    patched = out / "nominal.urdf"
    assert subprocess.run(["check_urdf", str(patched)], capture_output=True).returncode == 0
    before, after = load_model(models.nominal), load_model(patched)
    for joint in before.joints:
        old, new = before.joint_dynamics(joint), after.joint_dynamics(joint)
        if joint == "l_elbow":
            assert new.damping == pytest.approx(report["params"]["damping"]["l_elbow"], rel=1e-4)
            assert new.armature == pytest.approx(report["params"]["armature"]["l_elbow"], rel=1e-4)
            assert new.friction == old.friction
        else:
            assert new == old, joint
    assert {n: link.inertial for n, link in before.links.items()} == \
        {n: link.inertial for n, link in after.links.items()}
    # <dynamics> and the <gazebo> override were patched alike: nothing says two things
    assert [f for f in check_model(after) if f.code == "value-conflict"] == []
    # only the identified attributes and one comment changed
    import difflib

    diff = [line for line in difflib.unified_diff(models.nominal.read_text().splitlines(),
                                                  patched.read_text().splitlines(), n=0)
            if line[:1] in "+-" and not line.startswith(("+++", "---"))]
    removed = [d for d in diff if d.startswith("-")]
    # the elbow's <dynamics> (armature) and its <gazebo> override (damping: where it is read from)
    assert len(removed) == 2 and all("damping" in d or "armature" in d for d in removed), diff
    assert any("mexone identify (fitted to fit.mcap)" in d and "damping" in d for d in diff)
    text = (out / "report.md").read_text()
    assert "fit.png" in text and "val.png" in text and "damping:l_elbow" in text
    assert (out / "fit.png").stat().st_size > 10_000 and (out / "val.png").exists()
    assert json.loads((out / "identify.json").read_text())["params"] == report["params"]
    # run again: the files are the user's now
    code, _, err = run_cli(["identify", *argv], capsys, monkeypatch)
    assert code == 2 and err.count("\n") == 1 and "--force" in err


@pytest.mark.parametrize("case,expected", [
    ("no_states", "no sensor_msgs/JointState messages (no joint_states)"),
    ("no_commands", "no commands for the controllers"),
    ("strangers", "joints foot_joint_x are not in the model"),
])
def test_bad_bag_is_one_line(hung, tmp_path, capsys, monkeypatch, case, expected):
    models, fit, _ = hung
    drop = {"no_states": ("joint_states",), "no_commands": ("command",)}.get(case, ())
    rename = {"l_knee": "foot_joint_x"} if case == "strangers" else None
    bag = bagtools.rewrite_ros1(fit, tmp_path / f"{case}.bag", drop=drop, rename=rename)
    code, stdout, err = run_cli(["identify", str(bag), "--model", str(models.nominal),
                                 "--controllers", str(models.controllers), "-o",
                                 str(tmp_path / "out")], capsys, monkeypatch)
    assert code == 2 and stdout == ""
    assert err.startswith(f"mexone: {bag}: ") and err.count("\n") == 1, err
    assert expected in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()


def test_unknown_joint_and_param_are_one_line(hung, tmp_path, capsys, monkeypatch):
    models, fit, _ = hung
    base = ["identify", str(fit), "--model", str(models.nominal), "--controllers",
            str(models.controllers), "-o", str(tmp_path / "out")]
    code, _, err = run_cli([*base, "--joints", "l_knee,tail"], capsys, monkeypatch)
    assert code == 2 and "no moving joint tail" in err and err.count("\n") == 1
    code, _, err = run_cli([*base, "--params", "damping,stiffness"], capsys, monkeypatch)
    assert code == 2 and "unknown parameter stiffness" in err and err.count("\n") == 1


@pytest.mark.slow
def test_ctrl_c_keeps_the_best_fit_so_far(hung, tmp_path):
    """Every joint (63 parameters): Ctrl-C a second into the fit -> one line, exit 130, and the
    outputs with the best values evaluated so far."""
    models, fit, _ = hung
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "mexone", "identify", str(fit), "--model",
                             str(models.nominal), "--controllers", str(models.controllers), "-o",
                             str(out), "--json", "-v"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    lines = []
    for line in proc.stderr:  # stages, one per line when stderr is not a terminal
        lines.append(line)
        if "fitting" in line:
            break
    time.sleep(1.0)
    proc.send_signal(subprocess.signal.SIGINT)
    stdout, rest = proc.communicate(timeout=240)
    assert proc.returncode == 130, "".join(lines) + rest
    assert rest.strip().splitlines()[-1].startswith("mexone: interrupted after"), rest
    assert "Traceback" not in rest
    report = json.loads(stdout)
    assert report["interrupted"] is True and len(report["params"]["damping"]) == 21
    assert report["rms_after"] <= report["rms_before"]
    assert (out / "nominal.urdf").exists() and "Interrupted" in (out / "report.md").read_text()
