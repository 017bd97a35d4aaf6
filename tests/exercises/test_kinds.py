"""A shipped exercise's submission kind says what its hand-in is, as `mexone exercise list` and
the page print it: a `routine` is a rospy routine, a `function` a file of functions the grader
calls (identify_damping's `estimate(bag) -> float` was listed as a routine), a `controller` a
PythonController class."""

from __future__ import annotations

import ast

import pytest

from helpers import run_cli
from mexone.exercises.exercise import SUBMISSION_KINDS, exercises, load_exercise
from mexone.gui.exercises import LIVE

SHIPPED = {name: load_exercise(folder) for name, folder in exercises().items()}


def _read(path) -> tuple[set[str], set[str], set[str]]:
    """The modules a Python file imports, its top-level functions and classes."""
    tree = ast.parse(path.read_text(), str(path))
    imported = {alias.name for node in ast.walk(tree) if isinstance(node, ast.Import)
                for alias in node.names}
    imported |= {f"{node.module}.{alias.name}" for node in ast.walk(tree)
                 if isinstance(node, ast.ImportFrom) and node.module for alias in node.names}
    functions = {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}
    classes = {n.name for n in tree.body if isinstance(n, ast.ClassDef)}
    return imported, functions, classes


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_the_kind_is_what_the_solution_is(name):
    ex = SHIPPED[name]
    assert ex.submission in SUBMISSION_KINDS and ex.submission in LIVE
    if not ex.file.endswith(".py"):
        assert ex.submission not in ("routine", "function", "controller"), name
        return
    imported, functions, classes = _read(ex.solution)
    rospy = "mexone.rospy" in imported
    if ex.submission == "routine":
        assert rospy, f"{name}: a routine uses `from mexone import rospy`"
    elif ex.submission == "function":
        assert functions and not rospy and not classes, f"{name}: functions the grader calls"
    else:
        assert ex.submission == "controller" and classes and not rospy, name


def test_exercise_list_says_identify_damping_hands_in_a_function():
    code, out, _ = run_cli(["exercise", "list"])
    line = next(line for line in out.splitlines() if line.startswith("identify_damping"))
    assert code == 0 and line.split()[3] == "function", line
