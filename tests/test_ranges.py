"""ranges.py, the one home of every user-set quantity's range: the docs' table is generated from
it when the docs are built (and has every range), numbers print as people write them, and the CLI, the check and
the editor refuse a value by the same Range."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from mexone import ranges
from mexone.errors import InputError


def test_the_generated_docs_table_has_every_range():
    """`python -m mexone.ranges` prints the page the docs build writes (tests/test_docs.py checks
    the built page too), one row per range."""
    generated = subprocess.run([sys.executable, "-m", "mexone.ranges"], capture_output=True, text=True,
                               check=True).stdout
    assert generated == ranges.docs_page()
    rows = [line for line in generated.splitlines() if line.startswith("| ") and "---" not in line]
    assert len(rows) == len(ranges.RANGES) + 1  # the header, then one per range
    for r in ranges.RANGES:  # every range has its row
        assert f"| {r.name} | " in generated


@pytest.mark.parametrize("value, text", [
    (np.float64(0.0), "0"), (np.float32(0.5), "0.5"), (1e300, "1e+300"), (-1e-300, "-1e-300"),
    (float("nan"), "NaN"), (np.inf, "inf"), (-np.inf, "-inf"), (3, "3"), (123456789.0, "1.23457e+08"),
])
def test_numbers_print_without_numpy_reprs_or_300_digits(value, text):
    assert ranges.number_text(value) == text


def test_a_range_refuses_in_one_line_naming_the_value_and_the_bounds():
    with pytest.raises(InputError) as refused:
        ranges.MASS.check(np.float64(1e300), "mass of 'arm'")
    assert refused.value.one_line() == "mass of 'arm' 1e+300 must be a finite number >= 1e-09 and <= 100000 kg"
    for bad in (True, "heavy", None, float("nan"), 1e-300, 0.0):
        with pytest.raises(InputError):
            ranges.MASS.check(bad)
    assert ranges.STEPS.check(7.0) == 7 and isinstance(ranges.STEPS.check(7.0), int)
    with pytest.raises(InputError, match="whole number"):
        ranges.STEPS.check(1.5)


def test_the_cli_check_and_controllers_use_the_same_bounds():
    from mexone.cli.common import DURATION, PORT, RTF, Number
    from mexone.control.spec import PidGains
    from mexone.description.check import MAX_LINK_MASS, MAX_MOMENT

    assert (RTF.low, RTF.high) == (ranges.RTF.low, ranges.RTF.high)
    assert (DURATION.low, DURATION.high, PORT.integer) == (ranges.DURATION.low, ranges.DURATION.high, True)
    assert Number.of(ranges.SIZE).low_open
    assert (ranges.MASS.high, ranges.MOMENT.high) == (MAX_LINK_MASS, MAX_MOMENT)
    assert PidGains(ranges.GAIN_P.high).problem() is None
    assert "p 1e+300 must be" in PidGains(1e300).problem()


@pytest.mark.parametrize("mass, words", [("1e-300", "mass 1e-300 kg is below any robot link's (at least 1e-09 kg)"),
                                         ("1e300", "mass 1e+300 kg is beyond any robot link's (at most 1e+05 kg)")])
def test_check_reports_an_absurd_mass_by_the_mass_range(tmp_path, mass, words):
    from mexone.description.check import check_model
    from mexone.description.urdf import read_urdf

    (tmp_path / "r.urdf").write_text(
        f'<robot name="r"><link name="base"><inertial><mass value="{mass}"/>'
        '<inertia ixx="1e-3" ixy="0" ixz="0" iyy="1e-3" iyz="0" izz="1e-3"/></inertial></link></robot>')
    found = [f for f in check_model(read_urdf(tmp_path / "r.urdf")) if f.code == "mass-implausible"]
    assert len(found) == 1 and words in found[0].message
