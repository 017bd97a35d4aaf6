"""The Exercises panel (`mexone sim --exercise`), driven through viser's wire protocol as a page
drives it: Check on the starter names its failing checks, on the reference solution gives full
marks, a second Check while one runs is refused, a hanging submission shows its reason within
the exercise's limit while the simulation keeps running; a file the page names outside the
exercise folder is refused; the panel plug-in registry."""

from __future__ import annotations

import re
import shutil
import socket
import threading
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
import viser
from hypothesis import given, settings
from hypothesis import strategies as st
from websockets.sync.client import connect

from helpers import free_port, run_cli, wait_until
from mexone.control.config import load_control_config
from mexone.errors import InputError
from mexone.exercises.exercise import find_exercise
from mexone.gui.app import GuiApp
from mexone.gui.exercises import (
    CheckOutcome,
    ExercisesPanel,
    fenced,
    inside,
    open_exercise,
    outcome_markdown,
)
from mexone.gui.panels import PANELS, Panel, panel_types, register_panel
from mexone.lab import Lab
from mexone.physics import CompileOptions

from .test_gui_bench import call
from .test_gui_security import join, send


def page(app):
    """A websocket as the served page opens it (closed without waiting 10 s for viser's
    close frame)."""
    port = app.server.get_port()
    sock = socket.create_connection(("127.0.0.1", port))
    return connect(f"ws://127.0.0.1:{port}", sock=sock, origin=f"http://127.0.0.1:{port}",
                   subprotocols=[f"viser-v{viser.__version__}"], open_timeout=10,
                   close_timeout=0.2)


def _serve(target):
    app = GuiApp(lambda options: Lab.create(options=options), CompileOptions(), port=free_port(),
                 exercise=target)
    loop = threading.Thread(target=app.serve_forever, daemon=True)
    loop.start()
    return app, loop


@pytest.fixture(scope="module")
def home(tmp_path_factory):
    """A page for home_hold, started as a student starts it (mexone exercise start)."""
    folder = tmp_path_factory.mktemp("student") / "hh"
    code, _, err = run_cli(["exercise", "start", "home_hold", str(folder)])
    assert code == 0, err
    app, loop = _serve(open_exercise(folder))
    yield app, folder
    app.stop()
    loop.join(timeout=5)


def _button(app, label: str):
    return next(h for h in app.server.gui._gui_input_handle_from_uuid.values()
                if getattr(h, "label", None) == label)


def _result(panel: ExercisesPanel, timeout: float) -> str:
    assert wait_until(lambda: not panel.running and panel.outcome is not None
                      and panel._shown_outcome is panel.outcome, timeout=timeout)
    return panel.result.content


def test_the_panel_shows_the_statement_and_the_students_file(home):
    app, folder = home
    panel = app.panels["exercises"]
    assert list(app.panels)[0] == "exercises"
    assert "Home hold" in panel.statement.content and "# " in panel.statement.content
    assert panel.shown_file == "controllers.yaml"
    assert (folder / "controllers.yaml").read_text()[:40] in panel.file_view.content
    assert set(panel.files()) == {"README.md", "controllers.yaml", "check.py"}
    with page(app) as ws:
        join(ws)
        shown = panel.file_view.content
        (folder / ".hidden.yaml").write_text("secret: 1\n")  # in the folder, not listed
        send(ws, panel.file_choice, ".hidden.yaml")
        assert wait_until(lambda: any("'.hidden.yaml' is not one of the files this page shows"
                                      in r for r in app.refusals))
        for hostile in ("../../../etc/passwd", "/etc/passwd", "..", ""):
            send(ws, panel.file_choice, hostile)
            assert wait_until(lambda h=hostile: any(
                f"'{h}' is not a file of the exercise folder" in r for r in app.refusals))
        assert panel.file_view.content == shown  # a refused message changes nothing
        send(ws, panel.file_choice, "check.py")
        assert wait_until(lambda: panel.shown_file == "check.py")
        assert "self_check('home_hold'" in panel.file_view.content


def test_check_names_the_starters_failing_checks_then_gives_the_solution_full_marks(home):
    app, folder = home
    panel = app.panels["exercises"]
    with page(app) as ws:
        join(ws)
        check = _button(app, "Check")
        send(ws, check, True)
        assert wait_until(lambda: panel.running, timeout=5)
        t0 = app.lab.sim.time
        send(ws, check, True)  # a second click while the first runs
        assert wait_until(lambda: any("a check of home_hold is running" in r
                                      for r in app.refusals), timeout=5)
        assert wait_until(lambda: app.lab.sim.time > t0 + 0.2, timeout=10)  # the lab runs on
        text = _result(panel, timeout=120)
        assert "score 0/10" in text and "not passed" in text
        assert "failing: **stays upright**, **holds home**, **no oscillation**" in text
        assert "retune" in text  # the live step: the starter's gains on the page's robot
        shutil.copyfile(find_exercise("home_hold").solution, folder / "controllers.yaml")
        send(ws, check, True)
        assert wait_until(lambda: panel.running, timeout=5)
        assert "p: 150.0" in panel.file_view.content  # the file as checked (the solution)
        text = _result(panel, timeout=120)
    assert "**score 10/10** (passed" in text and "failing" not in text
    assert text.count("✅") == 3
    wanted = load_control_config(folder / "controllers.yaml").controllers
    for name in ("l_elbow_position_controller", "r_knee_position_controller"):
        assert app.lab.manager.controllers[name].gains[0] == wanted[name].pid  # retuned live


def test_the_exercise_list_shows_another_statement_and_refuses_what_it_does_not_offer(home):
    app, folder = home
    panel = app.panels["exercises"]
    labels = list(panel.choices())
    assert labels[0] == "home_hold (hh/)" and {"pid_spec", "identify_damping"} <= set(labels)
    with page(app) as ws:
        join(ws)
        send(ws, panel.pick, "../../etc")
        assert wait_until(lambda: any("'../../etc' is not an exercise this page offers" in r
                                      for r in app.refusals))
        assert wait_until(lambda: panel.pick.value == "home_hold (hh/)")  # restored
        send(ws, panel.pick, "pid_spec")
        assert wait_until(lambda: "PID to a specification" in panel.statement.content)
        assert panel.target.exercise.name == "pid_spec" and panel.target.folder is None
        send(ws, _button(app, "Check"), True)
        assert wait_until(lambda: any("pid_spec is not started: there is no file to check" in r
                                      for r in app.refusals))
        send(ws, panel.pick, "home_hold (hh/)")
        assert wait_until(lambda: "Home hold" in panel.statement.content)
    assert panel.target is panel.started and panel.shown_file == "controllers.yaml" and not panel.running


@pytest.fixture()
def hanging(tmp_path, monkeypatch):
    """A teacher's routine exercise with a 2 s limit, started, its routine never ending; and a
    plug-in panel whose update raises."""

    class Broken(Panel):
        name, period = "broken_for_test", 1

        def build(self) -> None:
            self.app.server.gui.add_markdown("broken panel")

        def update(self) -> None:
            raise RuntimeError("a panel's bug")

    monkeypatch.setitem(PANELS, Broken.name, Broken)
    assert run_cli(["exercise", "new", "tpl", str(tmp_path / "tpl")])[0] == 0
    yaml = tmp_path / "tpl" / "exercise.yaml"
    yaml.write_text(yaml.read_text().replace("time_limit: 30", "time_limit: 2")
                    .replace("cpu_limit: 30", "cpu_limit: 2"))
    (tmp_path / "tpl" / "figures").mkdir()  # a statement's figure: start copies it
    iio.imwrite(tmp_path / "tpl" / "figures" / "dot.png", np.zeros((4, 4, 3), np.uint8))
    with open(tmp_path / "tpl" / "statement.md", "a") as f:
        f.write("\n![the arms](figures/dot.png)\n")
    assert run_cli(["exercise", "start", str(tmp_path / "tpl"), str(tmp_path / "mine")])[0] == 0
    (tmp_path / "mine" / "routine.py").write_text("while True:\n    pass\n")
    app, loop = _serve(open_exercise(tmp_path / "mine"))
    yield app
    app.stop()
    loop.join(timeout=5)


def test_a_hanging_submission_shows_its_reason_and_the_lab_runs_on(hanging):
    app = hanging
    panel = app.panels["exercises"]
    assert app.panels["routines"].files["exercise: routine.py"].name == "routine.py"  # to Start by hand
    sent = panel.statement._impl.props._markdown  # what the page gets: the figure inlined
    assert "![the arms](data:image/png;base64," in sent
    assert wait_until(lambda: any("broken_for_test panel stopped: RuntimeError: a panel's bug"
                                  in line for line in app.console), timeout=5)
    t0 = app.lab.sim.time
    call(app, panel.check)
    text = _result(panel, timeout=2 + 60)
    assert "exceeded the time limit of 2 s" in text and "failing: **runs**" in text
    assert panel.outcome.seconds < 2 + 10  # within the limit (+ the grader's start-up)
    assert app.lab.sim.time > t0 + 0.5 and app.routine is None  # nothing ran in the lab
    assert sum("a panel's bug" in line for line in app.console) == 1  # said once, left out


def test_the_server_refuses_a_file_outside_the_folder(tmp_path):
    (tmp_path / "in.yaml").write_text("a: 1\n")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "x.yaml").write_text("")
    (tmp_path / "link.yaml").symlink_to(tmp_path / "sub" / "x.yaml")
    assert inside(tmp_path, "in.yaml") == tmp_path / "in.yaml"
    for bad in ("sub/x.yaml", "link.yaml", "sub", "../in.yaml", "missing.yaml"):
        with pytest.raises(InputError, match="is not a file of the exercise folder"):
            inside(tmp_path, bad)


@settings(derandomize=True, max_examples=60, deadline=None)
@given(st.text(max_size=40))
def test_any_name_but_the_folders_own_files_is_refused_in_one_line(tmp_path_factory, name):
    folder = tmp_path_factory.getbasetemp() / "hyp"
    folder.mkdir(exist_ok=True)
    (folder / "mine.py").write_text("")
    if name == "mine.py":
        return
    with pytest.raises(InputError, match="is not a file of the exercise folder") as caught:
        inside(folder, name)
    assert len(caught.value.one_line().splitlines()) == 1


def test_sim_exercise_refusals_are_one_line():
    code, _, err = run_cli(["sim", "--exercise", "no_such_exercise"])
    assert code == 2 and err.startswith("mexone: no exercise 'no_such_exercise'")
    assert len(err.strip().splitlines()) == 1
    code, _, err = run_cli(["sim", "--exercise", "home_hold", "--headless"])
    assert code == 2 and "--exercise is a panel of the page" in err


def test_the_panel_registry():
    names = [cls.name for cls in panel_types()]
    assert names[:1] == ["exercises"] and {"controllers", "load"} <= set(names)
    with pytest.raises(TypeError, match="a Panel subclass with a name"):
        register_panel(type("NotAPanel", (), {"name": "x"}))

    class Twin(Panel):
        name = "controllers"

    with pytest.raises(TypeError, match="two panels are named 'controllers'"):
        register_panel(Twin)
    assert PANELS["controllers"].__module__ == "mexone.gui.controllers"


def test_check_runs_a_controller_plug_in_in_the_lab_and_grades_it(tmp_path):
    """gravity_compensation's exercise.yaml says how: the student's class on the arm, the arm
    raised; the reference then holds the raised arm on the page and scores full marks."""
    folder = tmp_path / "gc"
    assert run_cli(["exercise", "start", "gravity_compensation", str(folder)])[0] == 0
    mine = folder / "gravity_compensation.py"
    mine.write_text("import os\nos._exit(3)\n")  # ends whatever process imports it
    app, loop = _serve(open_exercise(folder))
    try:
        panel = app.panels["exercises"]
        call(app, panel.check)
        text = _result(panel, timeout=90)
        assert "not applied: your file did not run in the self-check" in text
        assert "failing: **runs**" in text and "score 0/10" in text
        assert "gravity_compensation" not in app.lab.manager.controllers  # never imported
        t0 = app.lab.sim.time
        assert wait_until(lambda: app.lab.sim.time > t0 + 0.1)  # the page's lab runs on
        shutil.copyfile(find_exercise("gravity_compensation").solution, mine)
        call(app, panel.check)
        text = _result(panel, timeout=90)
        assert "the lab restarted with your GravityCompensation" in text
        assert "**score 10/10** (passed" in text
        manager = app.lab.manager
        ctrl = manager.controllers["gravity_compensation"]
        assert ctrl.running and ctrl.fault is None
        assert Path(ctrl.plugin.file).read_text() == (folder / "gravity_compensation.py").read_text()
        elbow = app.lab.sim.model.joint("l_elbow").qposadr[0]
        assert abs(app.lab.sim.data.qpos[elbow] + 0.6) < 0.02  # the raised arm, held
        assert "l_elbow_position_controller" not in manager.controllers
        assert "r_elbow_position_controller" in manager.controllers
    finally:
        app.stop()
        loop.join(timeout=5)


@pytest.mark.parametrize("bad, said", [
    ("live_controller: [1]", "'live_controller' must be a mapping"),
    ("live_controller: {class: 'no way', joints: [a]}", "'class' is 'no way'"),
    ("live_controller: {class: A, joints: []}", "'joints' is []"),
    ("live_controller: {class: A, joints: [a], pose: {a: yes}}", "'pose' must map joint names"),
    ("live: maybe", "'live' is 'maybe': write true or false"),
])
def test_a_bad_live_setting_is_one_line(tmp_path, bad, said):
    assert run_cli(["exercise", "new", "tpl", str(tmp_path / "tpl")])[0] == 0
    yaml = tmp_path / "tpl" / "exercise.yaml"
    yaml.write_text(yaml.read_text() + bad + "\n")
    with pytest.raises(InputError, match=re.escape(said)) as caught:
        find_exercise(tmp_path / "tpl")
    assert str(yaml) in caught.value.one_line() and "\n" not in caught.value.one_line()


@settings(derandomize=True, max_examples=60, deadline=None)
@given(st.text(max_size=60), st.text(max_size=60))
def test_what_a_grader_or_a_submission_says_is_plain_text_on_the_page(name, output):
    exercise = find_exercise("home_hold")
    test = {"name": name, "output": output, "status": "failed", "score": 0, "max_score": 10}
    report = {"score": 0, "tests": [test], "extra_data": {"max_score": 10, "failure": output}}
    text = outcome_markdown(exercise, CheckOutcome(report=report, checks=[test],
                                                   live=output))
    assert "<" not in text and ">" not in text.replace("&gt;", "")
    rows = [line for line in text.splitlines() if line.startswith("| ❌")]
    assert len(rows) == 1 and len(re.split(r"(?<!\\)\|", rows[0])) == 6  # its 4 cells, no more
    assert fenced(output + "```", "yaml").splitlines()[-1] not in output + "```"


def test_check_opens_a_urdf_in_the_lab_and_the_panel_survives_the_load(tmp_path):
    folder = tmp_path / "mc"
    assert run_cli(["exercise", "start", "model_checks", str(folder)])[0] == 0
    shutil.copyfile(find_exercise("model_checks").solution, folder / "mex_rb.urdf")
    app, loop = _serve(open_exercise(folder))
    try:
        panel = app.panels["exercises"]
        before = panel.result
        call(app, panel.check)
        text = _result(panel, timeout=90)
        assert "opened mex_rb.urdf (Load)" in text and "**score 10/10** (passed" in text
        assert app.model_label == "mex_rb.urdf" and panel.result is not before  # rebuilt
        assert "Model checks" in panel.statement.content
    finally:
        app.stop()
        loop.join(timeout=5)
