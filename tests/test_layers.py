"""The package's layers: every core module imports only layers at or below its own, and no core
module imports a front end (the README's Layout section draws the same picture)."""

from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src" / "mexone"

# core layers, lowest first; a module may import its own layer and those below it
CORE = {"errors": 0, "inputs": 0, "yamlio": 0, "files": 0, "ranges": 0, "description": 1, "robots": 1, "physics": 2,
        "bus": 2, "control": 3, "sensors": 3}
FRONT_ENDS = {"lab", "routines", "rospy", "msgs", "motion", "gui", "ros1", "record", "sweep", "bench", "cli",
              "identify", "editor",
              "signals", "__main__"}


def _layer(module: str) -> str:
    return module.split(".")[1] if module.count(".") else "__init__"


def _imports(path: Path) -> list[tuple[str, int]]:
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("mexone."):
            out.append((node.module, node.lineno))
        elif isinstance(node, ast.Import):
            out += [(a.name, node.lineno) for a in node.names if a.name.startswith("mexone.")]
    return out


def test_every_module_belongs_to_a_known_layer():
    names = {p.stem if p.is_file() else p.name for p in SRC.iterdir()
             if p.name != "__pycache__" and (p.suffix == ".py" or p.is_dir())}
    assert names - {"__init__"} <= set(CORE) | FRONT_ENDS


def test_no_core_module_imports_a_layer_above_it():
    wrong = []
    for path in SRC.rglob("*.py"):
        own = path.relative_to(SRC).parts[0].removesuffix(".py")
        if own not in CORE:
            continue
        for module, line in _imports(path):
            target = _layer(module)
            if target in FRONT_ENDS or CORE.get(target, 99) > CORE[own]:
                wrong.append(f"{path.relative_to(SRC)}:{line} imports {module}")
    assert wrong == []


def test_importing_mexone_changes_no_environment():
    import os
    import subprocess
    import sys

    code = ("import os; before = dict(os.environ); import mexone, mexone.lab; "
            "print(sorted(set(os.environ.items()) ^ set(before.items())))")
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM")}
    env.pop("DISPLAY", None)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                         check=True)
    assert out.stdout.strip() == "[]"
