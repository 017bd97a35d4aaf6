"""The Controllers panel: rqt_controller_manager and rqt_reconfigure for the lab's controllers.

Lists every controller (state, type, update rate, time per update, why a Python controller was
stopped), starts and stops the one picked (the controller_manager's switch), reloads a Python
controller's file in place, and shows each Python controller's declared parameters as live
fields, checked on the server by the same `Param` as the YAML (a page is not trusted). Every
action runs in the simulation thread (`do`); a refusal is one line on the page.
"""

from __future__ import annotations

from mexone.errors import InputError
from mexone.gui.panels import Panel, register_panel
from mexone.lab import Lab
from mexone.ranges import number_text

__all__ = ["ControllersPanel", "controllers_table"]


def controllers_table(lab: Lab) -> str:
    """The panel's list (Markdown, one line per controller, the students' first): name, state,
    type, update rate, time per update; and why a stopped Python controller stopped."""
    manager = lab.manager
    if manager is None:
        return lab.no_controllers or "no controllers"
    infos = sorted(manager.list_controllers(), key=lambda i: i.update_rate is None)  # stable: YAML order
    rows = []
    for info in infos:
        state = "**fault**" if info.fault else info.state
        parts = [state, info.type.split("/")[-1]]
        if info.update_rate:
            parts.append(f"{number_text(info.update_rate)} Hz")
        if info.update_time:
            parts.append(f"{info.update_time * 1e6:.1f} us/update")
        if info.update_time_max:  # the real-time budget: the worst update, the deadlines missed
            parts.append(f"max {info.update_time_max * 1e6:.0f} us, {info.deadline_misses} missed")
        rows.append(f"- **{info.name}**: {' · '.join(parts)}")
        if info.fault:
            rows.append(f"  - {info.fault}")
    return "\n".join(rows)


@register_panel
class ControllersPanel(Panel):
    """rqt_controller_manager's list, switch and reload, and the Python controllers' live
    parameters (a plug-in panel: gui/panels.py)."""

    name = "controllers"
    order = 11
    period = 30

    def build(self) -> None:
        self.fields: dict[tuple[str, str], object] = {}
        gui = self.server.gui
        lab = self.lab
        self.folder = gui.add_folder("Controllers", expand_by_default=False)
        manager = lab.manager
        with self.folder:
            self.table = gui.add_markdown(controllers_table(lab))
            if manager is None:
                return
            names = list(manager.controllers) or ["(none)"]
            python = [n for n, c in manager.controllers.items() if c.reloadable]
            self.pick = gui.add_dropdown("Controller", names, initial_value=(python or names)[0])
            self.start_button = gui.add_button("Start", hint="switch_controller: start it")
            self.stop_button = gui.add_button("Stop", hint="switch_controller: stop it")
            self.reload_button = gui.add_button(
                "Reload", hint="import a Python controller's file again and restart it in place; "
                               "an error keeps the old one")
            self.start_button.on_click(lambda _: self.do(lambda: self.switch(True)))
            self.stop_button.on_click(lambda _: self.do(lambda: self.switch(False)))
            self.reload_button.on_click(lambda _: self.do(self.reload))
            for name in python:
                self._add_params(name)

    # ----- parameters ---------------------------------------------------------------------------
    def _add_params(self, name: str) -> None:
        ctrl = self.lab.manager.controllers[name]
        declared = ctrl.declared_params()
        if not declared:
            return
        gui = self.server.gui
        with gui.add_folder(f"{name} parameters", expand_by_default=False):
            for key, param in declared.items():
                value = ctrl.params.get(key, param.default)
                hint = " ".join(p for p in (param.doc, f"({param.describe()})") if p)
                if param.value_type is bool:
                    handle = gui.add_checkbox(key, bool(value), hint=hint)
                else:
                    shown = number_text(value) if param.numeric else str(value)
                    handle = gui.add_text(key, initial_value=shown, hint=hint)
                handle.on_update(lambda e, n=name, k=key: self._typed(e, n, k))
                self.fields[(name, key)] = handle

    def _typed(self, event, name: str, key: str) -> None:
        if event.client is None:  # the server set it (a refusal restored it)
            return
        text = event.target.value
        self.do(lambda: self.set_param(name, key, text))

    def set_param(self, name: str, key: str, text) -> None:
        """Simulation thread: a field's new text, parsed and checked as the YAML's value."""
        ctrl = self.lab.manager.controllers.get(name)
        if ctrl is None or not ctrl.reloadable:
            raise InputError(f"controller '{name}' is gone", hint="it was unloaded")
        param = ctrl.declared_params().get(key)
        value = text
        try:
            if param is not None and param.numeric and isinstance(text, str):
                try:
                    value = float(text.strip())
                except ValueError:
                    raise InputError(f"controller '{name}': {key} '{text[:30]}' is not a number",
                                     hint=param.describe()) from None
            self.lab.manager.set_param(name, key, value)
        except InputError:
            self.show_param(name, key)
            raise

    def show_param(self, name: str, key: str) -> None:
        handle = self.fields.get((name, key))
        ctrl = self.lab.manager.controllers.get(name)
        if handle is None or ctrl is None or not ctrl.reloadable:
            return
        value = ctrl.params.get(key)
        handle.value = value if isinstance(value, bool) else (
            number_text(value) if isinstance(value, int | float) else str(value))

    # ----- switch and reload --------------------------------------------------------------------
    def picked(self) -> str:
        name = str(self.pick.value)
        if name not in self.lab.manager.controllers:
            raise InputError(f"no controller '{name}' is loaded")
        return name

    def switch(self, start: bool) -> None:
        name = self.picked()
        manager = self.lab.manager
        if start:
            manager.switch(start=[name])
        else:
            manager.switch(stop=[name])
        self.update()

    def reload(self) -> None:
        name = self.picked()
        self.lab.manager.reload(name)
        for key in self.lab.manager.controllers[name].params:
            self.show_param(name, key)
        self.update()
        self.server_notify(f"{name} reloaded")

    def server_notify(self, text: str) -> None:
        for client in self.server.get_clients().values():
            client.add_notification("Controllers", text, auto_close_seconds=4.0, color="green")

    def update(self) -> None:
        """Refresh the table (the simulation thread, a few times a second)."""
        text = controllers_table(self.lab)
        if self.table.content != text:
            self.table.content = text
