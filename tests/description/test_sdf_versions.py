"""SDF versions: known ones read by their number (1.10 comes after 1.9), unknown ones refused."""

from __future__ import annotations

import pytest

from mexone.description.sdf import read_sdf
from mexone.errors import InputError

MODEL = """<sdf version="{version}"><model name="m">
  <link name="base"><inertial><mass>1</mass></inertial></link>
  <link name="arm"><pose>0 0 1 1.5707963267948966 0 0</pose><inertial><mass>1</mass></inertial></link>
  <joint name="j" type="revolute"><parent>base</parent><child>arm</child>
    <axis><xyz>0 0 1</xyz><limit><lower>-1</lower><upper>1</upper><effort>5</effort><velocity>1</velocity></limit></axis>
  </joint></model></sdf>"""


def axis(tmp_path, version: str):
    path = tmp_path / f"v{version}.sdf"
    path.write_text(MODEL.format(version=version))
    return read_sdf(path).joints["j"].axis


def test_1_10_reads_axes_in_the_joint_frame_as_1_6_does(tmp_path):
    """float('1.10') < 1.5 made SDF 1.10 and 1.11 files read their axes the SDF 1.4 way."""
    assert axis(tmp_path, "1.10") == pytest.approx(axis(tmp_path, "1.6"))
    assert axis(tmp_path, "1.4") != pytest.approx(axis(tmp_path, "1.6"))  # 1.4: model frame


@pytest.mark.parametrize("version", ["9.9", "2.0", "1.13", "1", "one"])
def test_unknown_versions_are_refused(tmp_path, version):
    with pytest.raises(InputError, match=f"has version '{version}', which is not an SDFormat version"):
        axis(tmp_path, version)
