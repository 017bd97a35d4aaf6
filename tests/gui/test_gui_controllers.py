"""The page's Controllers panel, driven as its clicks and fields drive it (handlers in the
simulation thread): the table against the manager, a live parameter checked by the same Param as
the YAML (a refusal restores the field), Stop/Start through the controller_manager's switch, and
Reload re-importing the student's file in place."""

from __future__ import annotations

import threading

import pytest

from helpers import free_port, wait_until
from mexone.control.skeleton import skeleton_files
from mexone.errors import InputError
from mexone.gui.app import GuiApp
from mexone.lab import Lab
from mexone.physics import CompileOptions

from .test_gui_bench import call

NAME = "my_pd_controller"


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    folder = tmp_path_factory.mktemp("ctl")
    for file, text in skeleton_files("my_pd").items():
        (folder / file).write_text(text)
    yaml = folder / "controllers.yaml"
    gui = GuiApp(lambda options: Lab.create(controllers=yaml, options=options), CompileOptions(),
                 port=free_port(), record_folder=folder, model_folder=folder)
    thread = threading.Thread(target=gui.serve_forever, daemon=True)
    thread.start()
    yield gui, folder
    gui.stop()
    thread.join(timeout=5)


def test_table_params_switch_and_reload(app):
    gui, folder = app
    panel, manager = gui.panels["controllers"], gui.lab.manager
    call(gui, panel.update)
    first = panel.table.content.splitlines()[0]  # the student's controller comes first
    assert first.startswith(f"- **{NAME}**: running · MyPd · 1000 Hz · ") and "us/update" in first
    assert panel.pick.value == NAME
    call(gui, lambda: panel.set_param(NAME, "kp", "35"))
    assert manager.controllers[NAME].params["kp"] == 35.0
    for bad in ("abc", "-1", "nan"):
        with pytest.raises(InputError, match="controller 'my_pd_controller': kp"):
            call(gui, lambda b=bad: panel.set_param(NAME, "kp", b))
        assert panel.fields[(NAME, "kp")].value == "35"  # restored
    call(gui, lambda: panel.switch(False))
    assert not manager.controllers[NAME].running
    call(gui, lambda: panel.switch(True))
    assert manager.controllers[NAME].running
    old = manager.controllers[NAME]
    text = (folder / "my_pd.py").read_text()
    (folder / "my_pd.py").write_text(text.replace("kp = Param(20.0", "kp = Param(21.0"))
    call(gui, panel.reload)
    new = manager.controllers[NAME]
    assert new is not old and new.running and new.params["kp"] == 35.0  # the live value kept
    assert new.plugin.cls.declared_params()["kp"].default == 21.0
    # a bug: the panel says it stopped and why; the page was told (its log handler)
    (folder / "my_pd.py").write_text(text.replace('        tau = self.kp', '        1 / 0\n        tau = self.kp'))
    call(gui, panel.reload)
    broken = manager.controllers[NAME]
    assert wait_until(lambda: broken.fault is not None, timeout=20)
    call(gui, panel.update)
    lines = panel.table.content.splitlines()
    assert lines[0].startswith(f"- **{NAME}**: **fault** · MyPd") and "ZeroDivisionError" in lines[1]
    assert any("ZeroDivisionError" in line and line.startswith("[ERROR]") for line in gui.console)
