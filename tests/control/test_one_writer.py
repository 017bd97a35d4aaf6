"""One writer to MuJoCo's state: nothing but control/hardware.py writes a running simulation's
ctrl, qpos, qvel or qfrc_applied, apart from the simulator's own state API in physics/ (reset,
set_joint_positions, set_free_body, set_state, apply_joint_effort). A front end that must put the
robot somewhere asks the Simulation; a controller's command goes through SimHardware. Copies a
module makes for itself (linearisation's, the IK's, a replay's MjData) are its own business."""

from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[2] / "src" / "mexone"
FIELDS = {"ctrl", "qpos", "qvel", "qfrc_applied"}
ALLOWED = ("control/hardware.py", "physics/",
           # the robust analysis's own copies of a lab (design/twin.py's copy_lab), put back
           # between trials and kicked, never the running simulation
           "design/twin.py", "design/onset.py")


def _is_sim(node: ast.AST) -> bool:
    """`sim`, `self.sim`, `lab.sim`, `self.lab.sim`: a Simulation by mexone's naming."""
    return (isinstance(node, ast.Name) and node.id == "sim") or \
        (isinstance(node, ast.Attribute) and node.attr == "sim")


def _is_sim_data(node: ast.AST, aliases: set[str]) -> bool:
    if isinstance(node, ast.Attribute) and node.attr == "data" and _is_sim(node.value):
        return True
    return isinstance(node, ast.Name) and node.id in aliases


def _aliases(function: ast.AST) -> set[str]:
    """Names bound to a simulation's data in this function (`data = sim.data`, `model, data =
    sim.model, sim.data`)."""
    out: set[str] = set()
    for node in ast.walk(function):
        if not isinstance(node, ast.Assign):
            continue
        pairs = []
        for target in node.targets:
            if isinstance(target, ast.Tuple) and isinstance(node.value, ast.Tuple):
                pairs += list(zip(target.elts, node.value.elts, strict=False))
            else:
                pairs.append((target, node.value))
        out |= {t.id for t, v in pairs if isinstance(t, ast.Name) and _is_sim_data(v, set())}
    return out


def _written_field(target: ast.AST, aliases: set[str]) -> str | None:
    """The field a target writes (`sim.data.qpos[3] = ...`, `data.ctrl[:] = ...`), if any."""
    node = target.value if isinstance(target, ast.Subscript) else target
    if isinstance(node, ast.Attribute) and node.attr in FIELDS and _is_sim_data(node.value, aliases):
        return node.attr
    return None


def writes(source: str) -> list[tuple[int, str]]:
    tree = ast.parse(source)
    found = []
    scopes = [n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef)]
    for scope in scopes or [tree]:
        aliases = _aliases(scope)
        for node in ast.walk(scope):
            targets = node.targets if isinstance(node, ast.Assign) else \
                [node.target] if isinstance(node, ast.AugAssign) else []
            for target in targets:
                for t in (target.elts if isinstance(target, ast.Tuple) else [target]):
                    field = _written_field(t, aliases)
                    if field:
                        found.append((node.lineno, field))
    return sorted(set(found))


def test_only_hardware_py_writes_a_running_simulations_controls_and_state():
    found = []
    for path in sorted(SRC.rglob("*.py")):
        rel = path.relative_to(SRC).as_posix()
        if rel.startswith(ALLOWED):
            continue
        found += [f"{rel}:{line}: writes {field}" for line, field in writes(path.read_text())]
    assert found == []


def test_the_check_finds_what_it_looks_for():
    assert writes("def f(sim):\n    sim.data.ctrl[0] = 1.0\n") == [(2, "ctrl")]
    assert writes("def f(self):\n    self.lab.sim.data.qvel[:] += 1\n") == [(2, "qvel")]
    assert writes("def f(lab):\n    model, data = lab.sim.model, lab.sim.data\n"
                  "    data.qpos[2] = 0.3\n") == [(3, "qpos")]
    assert writes("def f(sim):\n    d = mujoco.MjData(sim.model)\n    d.qpos[:] = 0\n") == []  # a copy
    assert writes("def f(sim):\n    q = sim.data.qpos.copy()\n    q[0] = 1\n") == []
    assert writes((SRC / "control" / "hardware.py").read_text())  # the one writer writes
