"""`mexone example-robot DIR` writes a robot package every verb takes, and MJCF that `mexone
convert --controllers` writes (of it and of Mex-One) is read back by every verb that reads MJCF."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from mexone.description.loader import load_model
from mexone.robots import mex_one

XACRO, YAML, POSE = "urdf/biped.urdf.xacro", "config/controllers.yaml", "config/standing.yaml"


def mexone(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "mexone", *map(str, args)], capture_output=True,
                          text=True, cwd=cwd, timeout=120)


@pytest.fixture(scope="module")
def package(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("ws") / "biped_description"
    out = mexone("example-robot", folder)
    assert out.returncode == 0, out.stderr
    return folder


def test_the_package_is_a_ros_package_with_its_files(package):
    names = sorted(p.relative_to(package).as_posix() for p in package.rglob("*") if p.is_file())
    assert names == ["CMakeLists.txt", "config/controllers.yaml",
                     "config/controllers_transmissions.xacro", "config/standing.yaml",
                     "package.xml", "urdf/biped.urdf", "urdf/biped.urdf.xacro"]
    robot = load_model(package / XACRO)  # $(find biped_description) found through package.xml
    assert len(robot.actuated_joints) == 10 and robot.gazebo_links["l_foot"].mu1 == 1.0


def test_an_existing_package_is_not_replaced_without_force(package):
    mine = package / "urdf" / "biped.urdf"
    shipped = mine.read_text()
    mine.write_text("<robot name='mine'/>")
    try:
        out = mexone("example-robot", package)
        assert out.returncode == 2 and out.stderr.count("\n") == 1 and "--force" in out.stderr
        assert mine.read_text() == "<robot name='mine'/>"  # the refusal changed nothing
        assert mexone("example-robot", package, "--force").returncode == 0
        assert mine.read_text() == shipped
    finally:
        mine.write_text(shipped)


def test_check_finds_nothing_and_sim_stands(package):
    out = mexone("check", XACRO, "--controllers", YAML, cwd=package)
    assert out.returncode == 0 and "(10 actuated)" in out.stdout and "no problems found" in out.stdout
    out = mexone("sim", XACRO, "--controllers", YAML, "--pose", POSE, "--headless", "--duration", 2,
                 cwd=package)
    assert out.returncode == 0, out.stderr
    height = float(out.stdout.split("base height ")[1].split()[0])
    assert 0.38 < height < 0.42  # standing on bent knees (0.42 m straight)


def test_controllers_of_the_urdf_are_the_shipped_ones(package, tmp_path):
    """The shipped YAML and transmissions are what `mexone controllers` writes today."""
    folder = package / "config"
    out = mexone("controllers", package / "urdf/biped.urdf", "-o", folder / "again.yaml",
                 "--pose", package / POSE)
    try:
        assert out.returncode == 0, out.stderr
        assert (folder / "again.yaml").read_text() == (package / YAML).read_text()
        again = (folder / "again_transmissions.xacro").read_text().replace(
            "again_transmissions.xacro", "controllers_transmissions.xacro").replace(
            "again.yaml", "controllers.yaml")
        assert again == (folder / "controllers_transmissions.xacro").read_text()
    finally:
        for name in ("again.yaml", "again_transmissions.xacro"):
            (folder / name).unlink(missing_ok=True)


def test_the_transmissions_header_names_an_include_that_works(package, tmp_path):
    header = (package / "config/controllers_transmissions.xacro").read_text().splitlines()[2]
    include = header.split('filename="')[1].split('"')[0]
    assert include == "$(find biped_description)/config/controllers_transmissions.xacro"
    wrapper = package / "urdf" / "wrapper.urdf.xacro"
    wrapper.write_text('<robot name="biped" xmlns:xacro="http://www.ros.org/wiki/xacro">\n'
                       '  <xacro:include filename="$(find biped_description)/urdf/biped.urdf"/>\n'
                       f'  <xacro:include filename="{include}"/>\n</robot>\n')
    try:
        assert len(load_model(wrapper).transmissions) == 10
    finally:
        wrapper.unlink()


ROBOTS = {"mex_one": lambda pkg: (mex_one.urdf_path(), mex_one.controllers_path()),
          "sample": lambda pkg: (pkg / XACRO, pkg / YAML)}


@pytest.mark.parametrize("name", list(ROBOTS))
def test_mjcf_written_with_controllers_is_read_by_every_verb(name, package, tmp_path):
    source, yaml = ROBOTS[name](package)
    actuated = sorted(j.name for j in load_model(source).actuated_joints)
    mjcf = tmp_path / "robot.xml"
    out = mexone("convert", source, "-o", mjcf, "--controllers", yaml)
    assert out.returncode == 0, out.stderr
    assert sorted(j.name for j in load_model(mjcf).actuated_joints) == actuated
    out = mexone("check", mjcf)
    assert out.returncode in (0, 1) and "Traceback" not in out.stderr, out.stderr
    assert f"({len(actuated)} actuated)" in out.stdout
    out = mexone("sim", mjcf, "--controllers", yaml, "--headless", "--duration", 0.2)
    assert out.returncode == 0 and "0.200 s simulated" in out.stdout, out.stderr
    out = mexone("convert", mjcf, "-o", tmp_path / "back.urdf")
    assert out.returncode == 0, out.stderr
    assert sorted(j.name for j in load_model(tmp_path / "back.urdf").actuated_joints) == actuated
