"""The routine parameters' parity with Debian's rospy: `python3 node.py _x:=v` (as rosrun runs
it) against a real master puts ~x where tests/routines/test_params.py's `mexone run` cases do:
under init_node's name (anonymous's, `__name:=`'s), not the file's."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
sys.path.insert(0, str(Path(__file__).parents[1] / "routines"))
from test_bridge import ros_env  # noqa: E402
from test_params import CASES, expected, routine_text, seen  # noqa: E402


@pytest.mark.parametrize("args,anonymous", CASES)
def test_rospy_puts_private_params_where_mexone_does(ros_master, tmp_path, args, anonymous):
    _, port = ros_master
    path = tmp_path / "params_file.py"
    path.write_text(routine_text(anonymous, "import rospy", "def report(text):\n    print(text)\n"))
    out = subprocess.run(["/usr/bin/python3", str(path), *args], env=ros_env(port),
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout.strip().splitlines()[-1])
    if "g:=global" in args:  # `g:=v` is a remapping to rosrun, not a parameter: mexone's own
        assert got[4] is None
        got[4] = "global"
    assert seen(got, anonymous) == expected(args, anonymous)
