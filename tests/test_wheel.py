"""The wheel a user gets from `pip install .`, not this checkout: it holds every file git has
under src/ (with the executable bits ROS needs), and installed into a fresh venv it runs every
shipped routine, every example and each verb's smallest real use from a folder outside the
source tree (the rest of the suite tests the editable install, which hid a missing walk.yaml).

One venv for the session, shared with tests/test_docs_commands.py (tests/wheelenv.py; pip's
cache makes the dependencies quick); the commands run two at a time (or one per core) as soon as it is ready, and each test waits for and checks its own, so a
failure names what broke.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import zipfile
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import pytest

import wheelenv
from wheelenv import Venv

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = sorted(p.stem for p in (ROOT / "src/mexone/robots/mex_one/routines").glob("*.py")
                 if p.stem != "__init__")
EXAMPLES = sorted((ROOT / "examples").glob("[0-9][0-9]_*.py"))
TIMES = wheelenv.TIMES  # what building and installing cost, for the report


@pytest.fixture(scope="module")
def installed(venv) -> Path:
    """The installed mexone package folder (in the venv's site-packages)."""
    out = venv.run("python", "-c", "import mexone, pathlib; print(pathlib.Path(mexone.__file__).parent)")
    return Path(out.stdout.strip())


ROS_ENV_SCRIPT = (
    'eval "$(mexone ros-env)" && rospack find mex_rb && rossrv md5 gazebo_msgs/SpawnModel && '
    '/usr/bin/python3 -c "from control_msgs.msg import JointControllerState as m; print(m._md5sum)" && '
    'roslaunch --args /routine mex_rb control.launch && '
    'roslaunch --args /routine mex_rb control.launch routine:=arms_node.py')


def _jobs(venv: Venv, urdf: Path, jobs: dict[str, Future]) -> dict[str, object]:
    """Each test's commands, in the order they start: the routines and examples first, the
    benchmark last and alone (its parallel rows take every core). A job that needs an earlier
    one's output waits on its future in `jobs` (the pool is FIFO: no deadlock)."""
    def after_the_rest():  # every earlier job (submitted before this one: no deadlock)
        for name, job in list(jobs.items()):
            if name != "test_bench_quick":
                job.exception()

    table: dict[str, object] = {}
    for example in reversed(EXAMPLES):  # 04_walk is the longest
        folder = venv.work / example.stem
        table[f"test_example_runs[{example.stem}]"] = lambda e=example, f=folder: (
            f.mkdir(), venv.run("python", shutil.copy(e, f), str(f), cwd=f))
    for routine in SHIPPED:
        table[f"test_shipped_routine_runs[{routine}]"] = lambda r=routine: venv.run(
            "mexone", "run", r, "--duration", "1", "--json")
    table |= {
        "recorded": lambda: venv.run("mexone", "record", "excitation", "--duration", "0.5",
                                     "-o", "run.mcap"),
        "test_identify": lambda: (jobs["recorded"].result(), venv.run(
            "mexone", "identify", "run.mcap", "--params", "damping", "--joints", "l_elbow",
            "--max-iterations", "2", "-o", "identified"))[-1],
        "test_plot": lambda: (jobs["recorded"].result(),
                              venv.run("mexone", "plot", "run.mcap", "-o", "run.png"))[-1],
        "test_convert_to_sdf_and_mjcf": lambda: (
            venv.run("mexone", "convert", str(urdf), "-o", "mex_rb.sdf"),
            (venv.work / "mjcf").mkdir(),
            venv.run("mexone", "convert", str(urdf), "-o", "mjcf/mex_rb.xml"),
            venv.run("mexone", "sim", "mex_rb.sdf", "--headless", "--duration", "0.05")),  # read back
        "test_controllers": lambda: (
            venv.run("mexone", "controllers", str(urdf), "-o", "auto.yaml"),
            venv.run("mexone", "sim", "--controllers", "auto.yaml", "--headless", "--duration",
                     "0.2", "--json")),
        "test_render": lambda: venv.run("mexone", "render", "home", "--duration", "0.2", "--size",
                                        "64x48", "--fps", "10", "-o", "home.gif"),
        "test_check": lambda: venv.run("mexone", "check"),
        "test_sim": lambda: venv.run("mexone", "sim", "--headless", "--duration", "0.2", "--json"),
        "test_ros_env_puts_an_unactivated_venvs_mexone_on_path": lambda: venv.run(
            "bash", "-c", f'PATH=/usr/bin:/bin; eval "$({venv.bin}/mexone ros-env)" && '
                          'command -v mexone && command -v python3'),
        "test_ros_env_finds_the_installed_packages": lambda: (
            venv.run("bash", "-c", ROS_ENV_SCRIPT) if shutil.which("roslaunch") else None),
        "test_bench_quick": lambda: (after_the_rest(), venv.run("mexone", "bench", "--quick", "--json"))[-1],
    }
    return table


@pytest.fixture(scope="module")
def jobs(venv, installed, request):
    """Every selected test's commands, started at once on a pool: name -> Future."""
    selected = {item.name for item in request.session.items if item.module is request.module}
    futures: dict[str, Future] = {}
    pool = ThreadPoolExecutor(max_workers=max(2, os.cpu_count() or 1))
    table = _jobs(venv, installed / "robots/mex_one/urdf/mex_rb.urdf", futures)
    for name, job in table.items():
        if name in selected or (name == "recorded" and selected & {"test_record", "test_plot",
                                                                    "test_identify"}):
            futures[name] = pool.submit(job)
    yield futures
    pool.shutdown(cancel_futures=True)


def test_the_venv_runs_the_wheels_mexone(venv, installed):
    assert installed.is_relative_to(venv.bin.parent), installed
    print("\n" + ", ".join(f"{k} {v:.1f} s" for k, v in TIMES.items()))


# ----- what the wheel holds ---------------------------------------------------------------------
def test_the_wheel_holds_every_file_git_has_under_src(wheel):
    """Code and data alike (urdf, meshes, launch files, ROS packages, routines' YAML): a new data
    file the packaging misses fails here, not on a user's machine."""
    tracked = {line.split("\t", 1)[1].removeprefix("src/")
               for line in wheelenv.git("ls-files", "-s", "src").splitlines()}
    with zipfile.ZipFile(wheel) as z:
        shipped = {n for n in z.namelist() if ".dist-info/" not in n}
    assert sorted(tracked - shipped) == []
    assert sorted(shipped - tracked) == []


def test_the_wheel_keeps_the_executable_bits(wheel):
    """roslaunch and rosrun start a node only if its file is executable (scripts/*.py too)."""
    executable = {line.split("\t", 1)[1].removeprefix("src/")
                  for line in wheelenv.git("ls-files", "-s", "src").splitlines() if line.startswith("100755")}
    assert {"mexone/robots/mex_one/scripts/arms_node.py",
            "mexone/robots/mex_one/scripts/joint_steps_node.py"} <= executable
    with zipfile.ZipFile(wheel) as z:
        modes = {i.filename: i.external_attr >> 16 for i in z.infolist()}
    assert sorted(n for n in executable if not modes[n] & 0o111) == []


def test_the_installed_files_keep_the_executable_bits(installed):
    scripts = installed / "robots" / "mex_one" / "scripts"
    for name in ("arms_node.py", "joint_steps_node.py", "mexone_node"):
        assert os.access(scripts / name, os.X_OK), name
    assert os.access(installed / "ros1/share/controller_manager/scripts/spawner", os.X_OK)


def test_the_wheel_holds_no_reference_solution(wheel, venv):
    """The shipped course's answers are in the teacher's pack (teacher/), never in the wheel: no
    solution/ folder but the template's, no file with an answer's bytes (a copy scored 10/10),
    and the installed mexone says where they are instead of handing one out."""
    pack = ROOT / "teacher" / "mexone_teacher" / "solutions"
    answers = {p.read_bytes(): p.relative_to(pack) for p in pack.rglob("*") if p.is_file()}
    assert len(answers) >= 10
    with zipfile.ZipFile(wheel) as z:
        names = [n for n in z.namelist() if not n.endswith("/")]
        assert [n for n in names if "/solution/" in n and "/template/" not in n] == []
        # two exercises' answers are the shipped robot itself (its URDF, its gains): those files
        # are mexone's, not answers written for the exercise
        robot = {z.read(n) for n in ("mexone/robots/mex_one/urdf/mex_rb.urdf",
                                     "mexone/robots/mex_one/config/controllers.yaml")}
        copies = [(n, answers[z.read(n)]) for n in names
                  if z.read(n) in answers and z.read(n) not in robot]
    assert copies == []
    out = subprocess.run([str(venv.bin / "python"), "-c",
                          "from mexone.exercises import find_exercise\n"
                          "find_exercise('gravity_compensation').solution"],
                         capture_output=True, text=True, env=venv.env, cwd=venv.work, timeout=120)
    assert out.returncode == 1 and "in the teacher's pack, not in mexone" in out.stderr, out.stderr


def test_the_teacher_pack_builds_with_every_answer(tmp_path_factory):
    """What CI and a teacher install from a clone (`pip install ./teacher`, scripts/test.sh) is a
    wheel of its own holding every solution git has, byte for byte, and the entry point mexone
    finds them by: a solution in a folder its package data misses would be lost there only."""
    pack = wheelenv.build_wheel(tmp_path_factory, "teacher", "mexone_teacher")
    tracked = wheelenv.git("ls-files", "teacher/mexone_teacher").splitlines()
    assert len(tracked) > 10
    with zipfile.ZipFile(pack) as z:
        names = set(z.namelist())
        missing = [n for n in tracked if n.removeprefix("teacher/") not in names
                   or z.read(n.removeprefix("teacher/")) != (ROOT / n).read_bytes()]
        (points,) = [n for n in z.namelist() if n.endswith(".dist-info/entry_points.txt")]
        assert "[mexone.solutions]\ncourse = mexone_teacher:solutions" in z.read(points).decode()
        assert not any(n.startswith("mexone/") for n in z.namelist())  # not a second mexone
    assert missing == []


# ----- every shipped routine, every example -----------------------------------------------------
@pytest.mark.parametrize("routine", SHIPPED)
def test_shipped_routine_runs(jobs, request, routine):
    out = jobs[request.node.name].result()
    assert json.loads(out.stdout)["sim_time"] == pytest.approx(1.0, abs=0.01)


@pytest.mark.parametrize("example", EXAMPLES, ids=[e.stem for e in EXAMPLES])
def test_example_runs(jobs, request, venv, example):
    jobs[request.node.name].result()
    folder = venv.work / example.stem
    assert sorted(folder.iterdir()) != [folder / example.name] or "01_" in example.name  # outputs


# ----- each verb's smallest real use ------------------------------------------------------------
def test_sim(jobs):
    summary = json.loads(jobs["test_sim"].result().stdout)
    assert summary["sim_time"] == pytest.approx(0.2) and not summary["diverged"]
    assert summary["base_height"] > 0.55  # the built-in robot stands on its controllers


def test_check(jobs):
    assert "no problems found" in jobs["test_check"].result().stdout


def test_convert_to_sdf_and_mjcf(jobs, venv):
    import mujoco

    jobs["test_convert_to_sdf_and_mjcf"].result()
    model = mujoco.MjModel.from_xml_path(str(venv.work / "mjcf/mex_rb.xml"))  # plain MuJoCo
    driven = {int(j) for j, kind in zip(model.actuator_trnid[:, 0], model.actuator_trntype, strict=True)
              if kind == mujoco.mjtTrn.mjTRN_JOINT}
    assert len(driven) == 21 and model.nmesh > 0  # the controllers' actuators, the meshes


def test_controllers(jobs):
    _, sim = jobs["test_controllers"].result()
    assert json.loads(sim.stdout)["base_height"] > 0.55


def test_record(jobs, venv):
    from mcap.reader import make_reader  # an independent reader

    jobs["recorded"].result()
    with open(venv.work / "run.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
    topics = {summary.channels[c].topic: n
              for c, n in summary.statistics.channel_message_counts.items()}
    assert topics.get("/mex_rb/joint_states", 0) >= 20  # 50 Hz for 0.5 s


def test_plot(jobs, venv):
    from PIL import Image

    jobs["test_plot"].result()
    with Image.open(venv.work / "run.png") as image:
        assert min(image.size) > 100


def test_render(jobs, venv):
    from PIL import Image

    jobs["test_render"].result()
    with Image.open(venv.work / "home.gif") as gif:
        assert gif.size == (64, 48) and gif.n_frames == 2


def test_identify(jobs, venv):
    jobs["test_identify"].result()
    result = json.loads((venv.work / "identified/identify.json").read_text())
    assert result["params"]["damping"]["l_elbow"] > 0
    assert (venv.work / "identified/mex_rb.urdf").is_file()


def test_bench_quick(jobs):
    report = json.loads(jobs["test_bench_quick"].result().stdout)
    assert report["overhead"]["ratio"] > 0 and report["cold_start_s"] > 0
    assert report["pybullet"] is None  # the [peers] extra is not installed: that row is left out


# ----- ROS 1 from the wheel ---------------------------------------------------------------------
def test_ros_env_finds_the_installed_packages(jobs, installed):
    """After eval "$(mexone ros-env)": ROS's tools find mexone's packages inside site-packages,
    and roslaunch can start control.launch's routine nodes (their files are executable)."""
    out = jobs["test_ros_env_finds_the_installed_packages"].result()
    if out is None:
        pytest.skip("Debian ROS 1 is not installed (ros-core)")
    lines = out.stdout.splitlines()
    assert lines[0] == str(installed / "robots" / "mex_one")
    assert lines[1:3] == ["9ed9c82c96abe1a00c3e8cdaeee24413", "987ad85e4756f3aef7f1e5e7fe0595d1"]
    scripts = installed / "robots" / "mex_one" / "scripts"
    assert lines[3].endswith(f"{scripts}/joint_steps_node.py __name:=routine")
    assert lines[4].endswith(f"{scripts}/arms_node.py __name:=routine")


def test_ros_env_puts_an_unactivated_venvs_mexone_on_path(jobs, venv):
    """roslaunch mex_rb model.launch runs `mexone sim --ros` by name: it must find this one,
    and the venv must not shadow the system's python3 that ROS's nodes run on."""
    found = jobs["test_ros_env_puts_an_unactivated_venvs_mexone_on_path"].result().stdout.split()
    assert found == [str(venv.bin / "mexone"), "/usr/bin/python3"]
