"""The suite's two phases (tests/phases.py): the files run side by side under pytest-xdist stay
off what a neighbour on the CPU would disturb or what they would build twice."""

from __future__ import annotations

import ast
from pathlib import Path

import phases

ROOT = phases.TESTS.parent
# a session's venv (built once, in the serial phase), a browser's page timing, ROS's clocks
FIXTURES = {"venv", "wheel", "ros_master", "browser", "chromium"}
MODULES = ("rospy", "rclpy", "playwright", "ray", "mexone.ros1", "mexone.ros2", "mexone.hub",
           "mexone.gui", "mexone.bench")


def listed() -> list[Path]:
    files = []
    for entry in phases.SHARES_THE_CPU:
        path = phases.TESTS / entry
        files += sorted(path.rglob("test_*.py")) if entry.endswith("/") else [path]
    return [f for f in files if f != Path(__file__).resolve()]  # this file names them all


def what_it_uses(path: Path) -> set[str]:
    """The fixtures its functions take, the modules it imports, and a Ray backend it asks for."""
    used: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.FunctionDef):
            used |= {a.arg for a in node.args.args} & FIXTURES
        elif isinstance(node, ast.Import):
            used |= {a.name for a in node.names if a.name.startswith(MODULES)}
        elif isinstance(node, ast.ImportFrom):
            module = node.module or ""
            if module.startswith(MODULES):
                used.add(module)
            used |= {a.name for a in node.names if a.name in FIXTURES}  # helpers' chromium()
        elif isinstance(node, ast.Constant) and node.value == "ray":
            used.add('"ray"')
    return used


def test_every_listed_file_exists():
    assert phases.missing() == []


def test_the_files_side_by_side_use_no_browser_ros_ray_or_the_session_venv():
    uses = {str(p.relative_to(ROOT)): sorted(what_it_uses(p)) for p in listed()}
    assert {name: u for name, u in uses.items() if u} == {}


def test_the_check_sees_what_it_looks_for():
    """The scan above finds each thing in the file that uses it (it cannot pass by finding none)."""
    assert "venv" in what_it_uses(ROOT / "tests" / "test_notebooks.py")
    assert "ros_master" in what_it_uses(ROOT / "tests" / "ros1" / "test_parity.py")
    assert "chromium" in what_it_uses(ROOT / "tests" / "gui" / "test_gui_browser.py")
    assert '"ray"' in what_it_uses(ROOT / "tests" / "design" / "test_robust_balance.py")


def test_a_file_is_in_one_phase():
    assert phases.shares_the_cpu(phases.TESTS / "dynamics" / "test_queries.py")
    assert phases.shares_the_cpu(phases.TESTS / "walking" / "test_stack.py")
    assert not phases.shares_the_cpu(phases.TESTS / "walking" / "test_realtime_loop.py")
    assert not phases.shares_the_cpu(phases.TESTS / "test_notebooks.py")


def test_the_test_script_runs_both_phases_with_xdist_installed():
    script = (ROOT / "scripts" / "test.sh").read_text()
    assert "MEXONE_TEST_PHASE=parallel python3 -m pytest -n auto --dist loadfile" in script
    assert "MEXONE_TEST_PHASE=serial python3 -m pytest" in script
    assert '"pytest-xdist' in (ROOT / "pyproject.toml").read_text()
    # the serial phase runs a failed test once more and names it (-r R); the parallel one never
    assert "MEXONE_TEST_PHASE=serial python3 -m pytest --reruns 1 -r fER" in script
    assert "--reruns" not in script.split("MEXONE_TEST_PHASE=parallel")[1].split("\n")[0]
    assert '"pytest-rerunfailures' in (ROOT / "pyproject.toml").read_text()
