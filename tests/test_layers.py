"""The package's layers: every core module imports only layers at or below its own, no core
module imports a front end, every front end imports only itself and the front ends below it, and
no two modules import each other (the README's Layout section draws the same picture)."""

from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src" / "mexone"

# core layers, lowest first; a module may import its own layer and those below it
CORE = {"errors": 0, "cluster": 0, "inputs": 0, "sandbox": 0, "yamlio": 0, "files": 0, "ranges": 0, "origins": 0, "description": 1, "robots": 1, "physics": 2, "dynamics": 2,
        "bus": 2, "control": 3, "sensors": 3, "design": 4, "walking": 4}
# front ends, lowest first; a module may import its own front end, the core and the front ends
# of the layers below. routines/ is the machinery that runs routines in lockstep with the
# simulation (runtime, runner); rospy and motion are the libraries routines call, above it. The
# shipped routines (Mex-One's, in robots/mex_one/routines beside its ROS nodes) are user
# programs, which may import any front end as a student's may; so is the shipped course
# (exercises' graders, starters, solutions: exercise 10's uses identify).
FRONT_END_ORDER = (
    {"signals", "msgs"},
    {"lab"},
    {"routines"},
    {"rospy", "motion", "record", "ros1", "ros2", "foxglove", "bench"},
    {"exercises"},  # below the GUI: its Exercises panel shows them
    {"sweep", "identify", "gui"},
    {"editor"},
    {"cli", "hub"},  # hub: the launcher entry a JupyterHub shows (jupyter-server-proxy)
    {"notebook"},  # the lab in Jupyter: the GUI beside a notebook, checked as the CLI checks
    {"__main__"},
)
FRONT_ENDS = set().union(*FRONT_END_ORDER)
USER_PROGRAMS = (SRC / "robots" / "mex_one" / "routines", SRC / "exercises" / "course")


def _layer(module: str) -> str:
    return module.split(".")[1] if module.count(".") else "__init__"


def _imports(path: Path) -> list[tuple[str, int]]:
    """(module, line) of every mexone import that runs (those under `if TYPE_CHECKING:` do not)."""
    out = []
    for node in _runtime_nodes(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("mexone."):
            out.append((node.module, node.lineno))
        elif isinstance(node, ast.Import):
            out += [(a.name, node.lineno) for a in node.names if a.name.startswith("mexone.")]
    return out


def _runtime_nodes(tree: ast.AST):
    for node in ast.iter_child_nodes(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            continue
        yield node
        yield from _runtime_nodes(node)


def _front_end_level(name: str) -> int:
    return next(i for i, layer in enumerate(FRONT_END_ORDER) if name in layer)


def test_every_module_belongs_to_a_known_layer():
    names = {p.stem if p.is_file() else p.name for p in SRC.iterdir()
             if p.name != "__pycache__" and (p.suffix == ".py" or p.is_dir())}
    assert names - {"__init__"} <= set(CORE) | FRONT_ENDS


def test_no_core_module_imports_a_layer_above_it():
    wrong = []
    for path in SRC.rglob("*.py"):
        own = path.relative_to(SRC).parts[0].removesuffix(".py")
        if own not in CORE or any(path.is_relative_to(user) for user in USER_PROGRAMS):
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


def test_every_front_end_imports_only_front_ends_below_it():
    wrong = []
    for path in SRC.rglob("*.py"):
        own = path.relative_to(SRC).parts[0].removesuffix(".py")
        if own not in FRONT_ENDS or any(path.is_relative_to(user) for user in USER_PROGRAMS):
            continue
        for module, line in _imports(path):
            target = _layer(module)
            if target in FRONT_ENDS and target != own and \
                    _front_end_level(target) >= _front_end_level(own):
                wrong.append(f"{path.relative_to(SRC)}:{line} imports {module}")
    assert wrong == []


def _module_name(path: Path) -> str:
    parts = path.relative_to(SRC.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def test_no_two_modules_import_each_other():
    """A package's __init__, which gathers its modules for import, aside."""
    paths = {_module_name(p): p for p in SRC.rglob("*.py") if p.name != "__init__.py"}
    imports = {}
    for name, path in paths.items():
        imports[name] = set()
        for node in _runtime_nodes(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("mexone"):
                for alias in node.names:  # `from mexone.ros1 import convert` imports a module
                    full = f"{node.module}.{alias.name}"
                    imports[name].add(full if full in paths else node.module)
            elif isinstance(node, ast.Import):
                imports[name] |= {a.name for a in node.names}
    mutual = sorted(f"{a} <-> {b}" for a in imports for b in imports[a]
                    if a < b and a in imports.get(b, ()))
    assert mutual == []
