"""The Load panel: open another robot without restarting the server.

The page picks a name from a list the server made of the robot files under the folder mexone
was started in (never a path the page sends), or uploads one file, which is saved under a
fresh temporary folder (never next to the user's files). A robot opened from the page gets
controllers with gains from its physics (`--controllers auto`), since the command line's YAML
belonged to the first robot. Building the new Lab happens before anything is torn down, so a
file that does not load leaves the running robot as it was, with the error on the page.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import viser

from mexone.errors import InputError
from mexone.gui.panels import Panel, register_panel

__all__ = ["LoadPanel", "model_choices", "save_upload", "MODEL_SUFFIXES"]

MODEL_SUFFIXES = (".urdf", ".xacro", ".sdf", ".xml", ".mjcf")
MAX_DEPTH = 3  # folders below the start folder searched
MAX_CHOICES = 300
MAX_UPLOAD = 20 * 1024 * 1024  # bytes
_SKIP = {"node_modules", "__pycache__", "build", "devel", "install", "log"}


def model_choices(folder: Path) -> dict[str, Path]:
    """{name relative to `folder`: path} of the robot files under it, nearest first."""
    found: dict[str, Path] = {}

    def walk(directory: Path, depth: int) -> None:
        try:
            entries = sorted(directory.iterdir())
        except OSError:
            return
        for entry in entries:
            if len(found) >= MAX_CHOICES or entry.name.startswith("."):
                continue
            if entry.is_file() and entry.name.lower().endswith(MODEL_SUFFIXES):
                found[str(entry.relative_to(folder))] = entry
        for entry in entries:
            if entry.is_dir() and not entry.is_symlink() and depth < MAX_DEPTH \
                    and not entry.name.startswith(".") and entry.name not in _SKIP:
                walk(entry, depth + 1)

    walk(folder, 0)
    return found


def save_upload(name: str, content: bytes) -> Path:
    """An uploaded file, saved under a new temporary folder by its plain name."""
    plain = Path(str(name)).name
    if not plain or not plain.lower().endswith(MODEL_SUFFIXES):
        raise InputError(f"Load: '{name}' is not a robot file",
                         hint="upload a .urdf, .urdf.xacro, .sdf or MJCF .xml")
    if len(content) > MAX_UPLOAD:
        raise InputError(f"Load: '{plain}' is {len(content) / 1e6:.0f} MB, more than "
                         f"{MAX_UPLOAD / 1e6:.0f} MB")
    folder = Path(tempfile.mkdtemp(prefix="mexone-upload-"))
    path = folder / plain
    path.write_bytes(content)
    return path


@register_panel
class LoadPanel(Panel):
    """Open another robot from the server's list or an upload (a plug-in panel: gui/panels.py)."""

    name = "load"
    order = 90

    def load(self, path: Path) -> None:
        self.host.load(path)

    def build(self) -> None:
        self.folder = self.host.settings.model_folder
        self.choices = model_choices(self.folder)
        gui = self.server.gui
        with gui.add_folder("Load robot", expand_by_default=False):
            gui.add_markdown(f"now: `{self.host.model_label}`")
            names = tuple(self.choices) or ("(no robot files here)",)
            self.choice = gui.add_dropdown("File", names, initial_value=names[0],
                                           hint=f"robot files under {self.folder}")
            row = gui.add_button_group("", ("Open", "Refresh list"))
            row.on_click(lambda e: self.do(self.refresh if e.target.value == "Refresh list"
                                           else lambda: self.open(self.choice.value)))
            self.upload = gui.add_upload_button("Upload a robot file", icon=viser.Icon.UPLOAD,
                                                hint="one self-contained .urdf/.sdf/.xml")
            self.upload.on_upload(lambda e: self._uploaded(e.target.value))

    def refresh(self) -> None:
        self.choices = model_choices(self.folder)
        self.choice.options = tuple(self.choices) or ("(no robot files here)",)

    def open(self, name: str) -> None:
        """Simulation thread: the named file, if it is one the server listed."""
        path = self.choices.get(name)
        if path is None:
            raise InputError(f"Load: '{name}' is not one of the files this server offers",
                             hint="pick one from the list (Refresh list after adding files)")
        self.load(path)

    def _uploaded(self, uploaded) -> None:
        name, content = uploaded.name, uploaded.content
        self.do(lambda: self.load(save_upload(name, content)))
