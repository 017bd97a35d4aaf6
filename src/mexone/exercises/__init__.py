"""Exercises a teacher assigns and mexone grades (`mexone exercise`): see docs/exercises.md.

A front end: it uses the lab, the routines runtime and the controllers; no core module imports it.
"""

from mexone.exercises.exercise import Exercise, exercises, find_exercise, load_exercise
from mexone.exercises.grading import Check, GradeContext, Result, grade, gradescope_json
from mexone.exercises.isolate import Limits, SubmissionFailed, run_isolated
from mexone.exercises.sim import Run, Variation, simulate

__all__ = ["Exercise", "exercises", "find_exercise", "load_exercise", "Check", "GradeContext",
           "Result", "grade", "gradescope_json", "Limits", "SubmissionFailed", "run_isolated",
           "Run", "Variation", "simulate", "self_check"]


def self_check(name: str, submission: str) -> int:
    """The local self-check `mexone exercise start` writes (check.py): grade the file on the
    nominal robot (no hidden variation) and print the report; 0 if it passes, 1 if not, 2 (and
    one line, as the CLI says it) if it cannot be graded: the file is missing, or not a file."""
    import sys

    from mexone.errors import MexoneError
    from mexone.exercises.grading import as_text

    try:
        result = grade(find_exercise(name), submission, local=True)
    except MexoneError as exc:
        print(f"mexone: {exc.one_line()}", file=sys.stderr)
        return 2
    print(as_text(result))
    return 0 if result.passed else 1
