"""A student's slips caught where they are made: a misspelt file stem in a controller's `type:`
names the student's file beside the YAML (as a misspelt shipped type names the shipped one), and
a Param whose own default breaks its declaration is refused when the class is defined."""

from __future__ import annotations

import pytest

from mexone.control import Param, load_control_config
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


@pytest.mark.parametrize("args, kwargs, message", [
    ((50.0,), {"low": 0.0, "high": 10.0}, "Param default 50 is not a finite number >= 0 and <= 10"),
    ((float("nan"),), {}, "Param default NaN is not a finite number"),
    ((-1,), {"low": 0}, "Param default -1 is not a whole number >= 0"),
    (("x",), {"choices": ("a", "b")}, "Param default 'x' is not one of a, b"),
])
def test_a_param_default_outside_its_own_declaration_is_refused(args, kwargs, message):
    # was: accepted, and a YAML that does not set it ran the controller with it
    with pytest.raises(TypeError, match=message):
        Param(*args, **kwargs)
    assert Param(3, low=0, high=10).default == 3 and Param("a", choices=("a", "b")).default == "a"


def test_a_param_named_like_a_yaml_key_is_located_at_the_type_line(tmp_path):
    (tmp_path / "law.py").write_text("from mexone.control import Param, PythonController\n\n\n"
                                     "class Arm(PythonController):\n    joints = Param(1.0)\n")
    path = tmp_path / "c.yaml"
    path.write_text("ns:\n  arm:\n    type: law/Arm\n    joints: [a]\n")
    with pytest.raises(InputError) as info:  # was: no file, no line, no controller
        load_control_config(path)
    assert info.value.one_line() == (f"{path}:3: controller 'arm': Arm declares parameter 'joints', "
                                     "a name the YAML uses for itself (rename the Param)")
