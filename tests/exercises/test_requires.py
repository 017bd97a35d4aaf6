"""Check.requires, the one rule for checks that presume another (a pose held presumes the robot
standing): in an episode where the required check failed, the check earns nothing and says why;
a grader naming a check it did not return is the teacher's one-line error."""

from __future__ import annotations

from pathlib import Path

import pytest

from mexone.errors import InputError
from mexone.exercises.grading import Check, presumed

GRADER = Path("grader.py")


def test_a_check_earns_nothing_when_the_one_it_requires_failed():
    fell = Check.true("stays upright", False, "fell at 0.80 s", weight=4)
    home = Check.at_most("holds home", 0.001, 0.01, " rad", weight=3, requires="stays upright")
    free = Check.at_most("speed", 0.1, 1.0)  # requires nothing: unaffected
    out = presumed([fell, home, free], GRADER)
    assert [(c.name, c.fraction) for c in out] == [("stays upright", 0.0), ("holds home", 0.0),
                                                   ("speed", 1.0)]
    assert out[1].output == "not counted: stays upright failed (fell at 0.80 s)"
    assert out[1].weight == 3 and home.fraction == 1.0  # the grader's Check is left alone
    stood = Check.true("stays upright", True, "stood")
    assert presumed([stood, home], GRADER)[1] is home


def test_requiring_a_check_not_returned_is_the_graders_error():
    home = Check.at_most("holds home", 0.001, 0.01, requires="stays up")
    with pytest.raises(InputError) as err:
        presumed([Check.true("stays upright", True), home], GRADER)
    assert err.value.one_line() == "grader.py: check 'holds home' requires 'stays up', which " \
                                   "grade(ctx) did not return"
