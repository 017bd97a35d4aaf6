"""`mexone check --controllers` finds what `mexone sim` refuses of a StateFeedback's YAML entry
(a missing design file, an update_rate that is not the design's sample rate): both ask the
class's own checks (StateFeedback.check_entry, the code configure runs), so check says it at
the YAML key's line with sim's words."""

from __future__ import annotations

import pytest

from helpers import run_cli
from mexone.errors import InputError
from mexone.lab import Lab

DESIGN = """\
K: [[20.0, 0.5]]
u0: [0.0]
joints: [l_elbow]
interface: effort
states: ["l_elbow:q", "l_elbow:dq"]
qpos: [0.0]
qvel: [0.0]
dt: 0.002
"""


def _yaml(folder, rate: str, design: str) -> str:
    path = folder / "controllers.yaml"
    path.write_text("mex_rb:\n"
                    "  elbow_lqr:\n"
                    "    type: mexone/StateFeedback\n"
                    "    joints: [l_elbow]\n"
                    f"    update_rate: {rate}\n"
                    f"    design_file: {design}\n")
    return path


@pytest.mark.parametrize("rate, design, line, says", [
    ("1000", "elbow.yaml", 5, "the design's period is 0.002 s but the controller runs at 1000 Hz "
                              "(set update_rate: 500)"),
    ("500", "missing.npz", 6, "missing.npz does not exist"),
], ids=["rate", "missing"])
def test_check_finds_what_sim_refuses_at_its_line(tmp_path, rate, design, line, says):
    (tmp_path / "elbow.yaml").write_text(DESIGN)
    path = _yaml(tmp_path, rate, design)
    code, out, _ = run_cli(["check", "--controllers", path])
    found = [row.strip() for row in out.splitlines() if "[controller-configure]" in row]
    assert code == 1 and "no problems found" not in out, out
    assert len(found) == 1 and found[0].startswith(
        f"{path}:{line}: error: controller \"elbow_lqr\": "), found
    assert says in found[0], found
    with pytest.raises(InputError) as sim:  # what `mexone sim --controllers` builds
        Lab.create(controllers=path)
    assert sim.value.what.removeprefix("controller 'elbow_lqr': ") in found[0], (sim.value, found)


def test_a_good_entry_is_not_a_finding(tmp_path):
    (tmp_path / "elbow.yaml").write_text(DESIGN)
    code, out, _ = run_cli(["check", "--controllers", _yaml(tmp_path, "500", "elbow.yaml")])
    assert "[controller-configure]" not in out, out
