"""A misspelt file stem in a controller's `type:` names the student's file beside the YAML, as a
misspelt shipped type names the shipped one."""

from __future__ import annotations

import pytest

from mexone.control import load_control_config
from mexone.errors import InputError

CTL = "from mexone.control import PythonController\n\n\nclass Arm(PythonController):\n    pass\n"


def test_a_misspelt_stem_suggests_the_file_beside_the_yaml(tmp_path):
    (tmp_path / "my_controller.py").write_text(CTL)
    (tmp_path / "other_law.py").write_text(CTL)
    path = tmp_path / "c.yaml"
    path.write_text("ns:\n  arm:\n    type: my_controler/Arm\n    joints: [a]\n")
    with pytest.raises(InputError) as info:
        load_control_config(path)
    text = info.value.one_line()
    assert text.startswith(f"{path}:3: controller 'arm': unknown controller type 'my_controler/Arm'")
    assert "(did you mean 'my_controller/Arm', the my_controller.py beside the YAML? shipped " \
           "types: " in text and "\n" not in text
    path.write_text("ns:\n  arm:\n    type: zzz/Arm\n    joints: [a]\n")
    with pytest.raises(InputError) as info:
        load_control_config(path)
    assert "did you mean" not in info.value.one_line()  # nothing close: no guess
