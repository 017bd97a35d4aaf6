"""What the design tests share: the one-foot LQR of examples/control_design/one_foot_lqr.py,
designed once a session (its lab is only read: linearize puts the model back)."""

import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "control_design"


@pytest.fixture(scope="session")
def designed():
    """(lab, operating point on the left foot, the design: K, the plant, its poles)."""
    if str(EXAMPLES) not in sys.path:
        sys.path.insert(0, str(EXAMPLES))
    import one_foot_lqr as lq

    from mexone.lab import Lab

    lab = Lab.create()
    lq.setup(lab)
    point = lq.one_foot_pose(lab)
    return lab, point, lq.design(lab, point)
