"""Inputs that used to hang, exhaust memory or crash mexone, generated here (never committed):
each must end within 10 s with its exact one-line error (exit 2), or be read correctly."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from mexone.robots import mex_one

ENV = {k: v for k, v in os.environ.items() if k != "ROS_PACKAGE_PATH"}


def mexone(*args: str, cwd: Path, env: dict | None = None, limit: float = 10.0):
    start = time.monotonic()
    out = subprocess.run([sys.executable, "-m", "mexone", *args], cwd=cwd, capture_output=True,
                         text=True, timeout=60, env={**ENV, **(env or {})})
    took = time.monotonic() - start
    assert took < limit, f"{args} took {took:.1f} s"
    assert "Traceback" not in out.stderr
    return out


def one_line_error(out) -> str:
    assert out.returncode == 2, (out.returncode, out.stderr)
    assert out.stderr.count("\n") == 1, out.stderr
    return out.stderr.strip()


def test_fifo_named_urdf_is_refused(tmp_path):
    os.mkfifo(tmp_path / "robot.urdf")  # reading it would block for ever
    assert one_line_error(mexone("check", "robot.urdf", cwd=tmp_path)) == \
        "mexone: robot.urdf: is a FIFO (named pipe), not a regular file (name the model or config file itself)"


def test_dev_zero_named_urdf_is_refused(tmp_path):
    (tmp_path / "robot.urdf").symlink_to("/dev/zero")  # reading it never ends
    assert one_line_error(mexone("check", "robot.urdf", cwd=tmp_path)) == \
        "mexone: robot.urdf: is a character device, not a regular file (name the model or config file itself)"


def test_fifo_as_controllers_and_world(tmp_path):
    os.mkfifo(tmp_path / "c.yaml")
    os.mkfifo(tmp_path / "w.world")
    assert one_line_error(mexone("check", "--controllers", "c.yaml", cwd=tmp_path)) == \
        "mexone: c.yaml: is a FIFO (named pipe), not a regular file (name the model or config file itself)"
    assert one_line_error(mexone("sim", "--headless", "--world", "w.world", cwd=tmp_path)) == \
        "mexone: w.world: is a FIFO (named pipe), not a regular file (name the model or config file itself)"


def test_directory_named_urdf_is_refused(tmp_path):
    (tmp_path / "robot.urdf").mkdir()
    assert one_line_error(mexone("check", "robot.urdf", cwd=tmp_path)) == \
        "mexone: robot.urdf: is a directory, not a regular file (name the model or config file itself)"


def test_50_mb_yaml_is_refused_quickly(tmp_path):
    text = mex_one.controllers_path().read_text()
    big = tmp_path / "big.yaml"
    with big.open("w") as out:  # 50 MB took PyYAML 84 s
        out.write(text)
        out.write(("  # " + "x" * 96 + "\n") * 500_000)
    assert one_line_error(mexone("check", "--controllers", "big.yaml", cwd=tmp_path)) == \
        "mexone: big.yaml: is 50.5 MB, over the 4 MB limit for input files (if it is meant to be " \
        "this big, pass --max-input-mb 51 or set MEXONE_MAX_INPUT_MB=51)"


def test_the_size_cap_can_be_lifted(tmp_path):
    urdf = mex_one.urdf_path().read_text()
    padded = urdf.replace("<robot name", "<!--" + "x" * 5_000_000 + "-->\n<robot name", 1)
    (tmp_path / "big.urdf").write_text(padded)
    env = {"ROS_PACKAGE_PATH": str(mex_one.package_dir())}
    assert one_line_error(mexone("check", "big.urdf", cwd=tmp_path, env=env)).startswith(
        "mexone: big.urdf: is 5.0 MB, over the 4 MB limit for input files")
    assert mexone("check", "big.urdf", "--max-input-mb", "6", cwd=tmp_path, env=env).returncode == 0
    assert mexone("check", "big.urdf", cwd=tmp_path, env={**env, "MEXONE_MAX_INPUT_MB": "6"}).returncode == 0


def test_xacro_runaway_expression_is_stopped(tmp_path):
    (tmp_path / "pow.urdf.xacro").write_text(
        '<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro"><link name="a"><inertial>'
        '<mass value="${9**9**9}"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/>'
        "</inertial></link></robot>")
    out = mexone("check", "pow.urdf.xacro", cwd=tmp_path, env={"MEXONE_XACRO_TIMEOUT": "2"})
    assert one_line_error(out) == (
        "mexone: pow.urdf.xacro: xacro did not finish within 2 s (a runaway expression such as "
        "${9**9**9} or a recursive macro? if it is only slow, set MEXONE_XACRO_TIMEOUT=<seconds>)")


def test_xacro_memory_bomb_is_stopped(tmp_path):
    (tmp_path / "mem.urdf.xacro").write_text(
        '<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro">'
        '<xacro:property name="big" value="${\'x\' * 10**10}"/><link name="${big[0]}"/></robot>')
    assert one_line_error(mexone("check", "mem.urdf.xacro", cwd=tmp_path)) == (
        "mexone: mem.urdf.xacro: xacro: ran out of memory (2 GB) (a runaway expression or macro? fix "
        "the xacro source)")


def _package(root: Path, name: str) -> Path:
    folder = root / name
    (folder / "urdf").mkdir(parents=True)
    (folder / "package.xml").write_text(f"<package format='2'><name>{name}</name></package>")
    (folder / "urdf" / "parts.xacro").write_text(
        '<robot xmlns:xacro="http://www.ros.org/wiki/xacro"><link name="part"><inertial><mass value="1"/>'
        '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link></robot>')
    return folder


@pytest.mark.parametrize("where", ["ros_package_path", "above_the_file", "sibling_package"])
def test_xacro_find_resolves_packages(tmp_path, where):
    ws = tmp_path / "ws" / "src"
    parts = _package(ws, "parts_description")
    robot = _package(ws, "robot_description") if where == "sibling_package" else parts
    (robot / "urdf" / "robot.urdf.xacro").write_text(
        '<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro">'
        '<xacro:include filename="$(find parts_description)/urdf/parts.xacro"/></robot>')
    env = {"ROS_PACKAGE_PATH": str(tmp_path / "ws")} if where == "ros_package_path" else {}
    out = mexone("check", "robot.urdf.xacro", cwd=robot / "urdf", env=env)
    assert out.returncode == 0, out.stderr
    assert "root Link: part has 0 child(ren)" in out.stdout


def test_xacro_finds_mexones_own_robot(tmp_path):
    (tmp_path / "head.urdf.xacro").write_text(
        '<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro"><link name="head">'
        '<inertial><mass value="0.5"/><inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" '
        'izz="0.001"/></inertial><visual><geometry><mesh filename="$(find mex_rb)/meshes/head.stl" '
        'scale="0.001 0.001 0.001"/></geometry></visual></link></robot>')
    out = mexone("check", "head.urdf.xacro", cwd=tmp_path)
    assert out.returncode != 2 and out.stderr == ""
    assert "mesh-missing" not in out.stdout


# ----- deep trees ------------------------------------------------------------------------------
def chain_urdf(links: int, lying: bool = False) -> str:
    """A serial chain of 5 x 5 x 10 cm boxes (0.1 kg); standing, or lying on the ground."""
    size, axis, step = ("0.1 0.05 0.05", "0 0 1", "0.1 0 0") if lying else ("0.05 0.05 0.1", "0 1 0", "0 0 0.1")
    centre = "0.05 0 0" if lying else "0 0 0.05"
    m = 0.1
    ixx, izz = m * (0.05**2 + 0.1**2) / 12, m * (2 * 0.05**2) / 12
    moments = (f'ixx="{izz}" iyy="{ixx}" izz="{ixx}"' if lying else f'ixx="{ixx}" iyy="{ixx}" izz="{izz}"')
    parts = ['<robot name="chain">']
    for i in range(links):
        parts.append(f'<link name="l{i}"><inertial><origin xyz="{centre}"/><mass value="{m}"/>'
                     f'<inertia {moments} ixy="0" ixz="0" iyz="0"/></inertial>'
                     f'<collision><origin xyz="{centre}"/><geometry><box size="{size}"/></geometry>'
                     "</collision></link>")
        if i:
            parts.append(f'<joint name="j{i}" type="revolute"><parent link="l{i - 1}"/>'
                         f'<child link="l{i}"/><origin xyz="{step}"/><axis xyz="{axis}"/>'
                         '<limit lower="-1" upper="1" effort="10" velocity="5"/></joint>')
    parts.append("</robot>")
    return "\n".join(parts)


def test_check_on_a_1200_link_chain_matches_check_urdf(tmp_path):
    """check used to die with RecursionError past ~1000 links; its tree is check_urdf's, and it
    says what sim will say: MuJoCo cannot nest that deep."""
    (tmp_path / "chain.urdf").write_text(chain_urdf(1200))
    out = mexone("check", "chain.urdf", cwd=tmp_path)
    assert out.returncode == 1
    assert out.stdout.rstrip().splitlines()[-2:] == [
        '  error: robot "chain": a chain of 1200 links: MuJoCo nests at most 1023 bodies, so mexone sim '
        "refuses it; weld links together with fewer, longer ones [tree-too-deep]",
        "1 error(s), 0 warning(s)"]
    sim = mexone("sim", "--headless", "chain.urdf", cwd=tmp_path)  # MuJoCo took 20 s to say so
    assert one_line_error(sim) == ("mexone: chain.urdf: 'chain' has a chain of 1200 links; MuJoCo nests at "
                                   "most 1023 bodies (weld links together with fewer, longer ones)")
    real = subprocess.run(["check_urdf", "chain.urdf"], cwd=tmp_path, capture_output=True, text=True)
    if real.returncode != 0 and not os.environ.get("MEXONE_CI"):
        pytest.skip("check_urdf is not installed")
    ours = out.stdout.split("\n\nphysics lint")[0].splitlines()
    assert ours == real.stdout.strip().splitlines()


def test_sdf_frames_chained_1200_deep(tmp_path):
    """Poses relative_to the previous link, 1200 deep: resolved without recursion."""
    links = ['<link name="l0"><inertial><mass>1</mass></inertial></link>']
    joints = []
    for i in range(1, 1200):
        links.append(f'<link name="l{i}"><pose relative_to="l{i - 1}">0 0 0.1 0 0 0</pose>'
                     "<inertial><mass>1</mass></inertial></link>")
        joints.append(f'<joint name="j{i}" type="fixed"><parent>l{i - 1}</parent><child>l{i}</child></joint>')
    (tmp_path / "chain.sdf").write_text(f'<sdf version="1.8"><model name="chain">{"".join(links)}'
                                        f'{"".join(joints)}</model></sdf>')
    out = mexone("convert", "chain.sdf", "-o", "chain.urdf", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert 'xyz="0 0 0.1"' in (tmp_path / "chain.urdf").read_text()


def test_check_on_a_1000_link_chain_is_clean(tmp_path):
    (tmp_path / "chain.urdf").write_text(chain_urdf(1000))
    out = mexone("check", "chain.urdf", cwd=tmp_path)
    assert (out.returncode, out.stdout.rstrip().splitlines()[-1]) == (0, "no problems found")


def test_a_300_link_chain_lying_on_the_ground_simulates(tmp_path):
    """1200 contacts on 306 dofs: Newton took 167 ms a step here; CG (DECISIONS.md) 50 ms."""
    (tmp_path / "chain.urdf").write_text(chain_urdf(300, lying=True))
    out = mexone("sim", "--headless", "--duration", "0.02", "chain.urdf", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("chain: 0.020 s simulated")


def test_a_900_link_chain_on_the_ground_does_not_abort_mujoco(tmp_path):
    """3600 contacts on 906 dofs overflowed MuJoCo's default arena: a FatalError, no way back."""
    import mujoco

    from mexone.description.urdf import read_urdf
    from mexone.physics.compile import compile_model

    (tmp_path / "chain.urdf").write_text(chain_urdf(900, lying=True))
    compiled = compile_model(read_urdf(tmp_path / "chain.urdf"))
    assert compiled.model.opt.solver == mujoco.mjtSolver.mjSOL_CG
    data = mujoco.MjData(compiled.model)
    mujoco.mj_step(compiled.model, data)
    assert data.ncon >= 3600 and abs(data.qvel).max() < 0.1
