"""A submission that loops, exits, raises, prints a traceback or allocates 10 GB: 0 points with
the reason, within the time limit + 10 s, and the grader goes on (exit status 0)."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import jsonschema
import pytest

from helpers import run_cli
from mexone.exercises import Limits, SubmissionFailed, find_exercise, grade, run_isolated

SCHEMA = json.loads((Path(__file__).parent.parent / "data" / "exercises" /
                     "gradescope_results.schema.json").read_text())

HOSTILE = {  # routine text: a piece of the reason it must get
    "loop": ("from mexone import rospy\nrospy.init_node('x')\nwhile True:\n    pass\n",
             "did not yield"),
    "os_exit": ("import os\nos._exit(3)\n", "os._exit(3)"),
    "posix_exit": ("import posix\nposix._exit(0)\n", "process ended (exit status 0)"),
    "raises": ("from mexone import rospy\nrospy.init_node('x')\nraise ValueError('boom')\n",
               "ValueError: boom"),
    "traceback": ("import traceback\ntry:\n    1 / 0\nexcept Exception:\n"
                  "    traceback.print_exc()\n", "printed a traceback"),
    "memory": ("x = bytearray(10 * 1024 ** 3)\nx[-1] = 1\n", "MemoryError"),
}


@pytest.mark.parametrize("name", sorted(HOSTILE))
def test_hostile_routine_scores_zero_with_reason(name, tmp_path):
    ex = find_exercise("arms_routine")
    path = tmp_path / "routine.py"
    path.write_text(HOSTILE[name][0])
    began = time.monotonic()
    code, out, err = run_cli(["exercise", "grade", "arms_routine", path, "--json",
                              tmp_path / "results.json"])
    assert time.monotonic() - began <= ex.limits.time + 10
    assert code == 0, err
    results = json.loads((tmp_path / "results.json").read_text())
    jsonschema.validate(results, SCHEMA)
    assert results["score"] == 0
    assert results["tests"][0]["name"] == "runs"
    assert HOSTILE[name][1] in results["tests"][0]["output"], results["tests"][0]["output"]
    assert "FAIL runs" in out


def _spin() -> None:
    while True:
        pass


def _sleep() -> None:
    time.sleep(60)


def _bye() -> None:
    os._exit(0)


def test_run_isolated_limits_cpu_and_wall_time():
    """The CPU limit ends a spinning run (not the 20 s wall limit), the wall limit a sleeping
    one within its grace, an os._exit is a failure, a good run returns its value."""
    from mexone.exercises.isolate import END_GRACE, prewarm

    prewarm()
    began = time.monotonic()
    with pytest.raises(SubmissionFailed, match="CPU time"):
        run_isolated(_spin, limits=Limits(time=20, cpu=1))
    assert time.monotonic() - began < 20
    began = time.monotonic()
    with pytest.raises(SubmissionFailed, match="time limit of 1 s"):
        run_isolated(_sleep, limits=Limits(time=1, cpu=10))
    assert time.monotonic() - began < 1 + END_GRACE + 10  # its grace, a loaded machine's start
    with pytest.raises(SubmissionFailed, match="ended the grading process"):
        run_isolated(_bye)
    assert run_isolated(sum, [1, 2, 3]) == 6  # and a good one returns its value


def test_gradescope_json_and_folder_csv(tmp_path):
    ex = find_exercise("home_hold")
    folder = tmp_path / "submissions"
    (folder / "ada").mkdir(parents=True)
    (folder / "ada" / "controllers.yaml").write_text(ex.solution.read_text())
    (folder / "bob.yaml").write_text(ex.starter.read_text())
    (folder / "eve.yaml").write_text("mex_rb: [unclosed\n")
    (folder / "cat.yml").write_text("mex_rb: [unclosed\n")  # .yml is a YAML file too
    (folder / "dan").mkdir()  # handed in nothing: a row all the same
    (folder / "dan" / "Controllers.yaml").write_text("mex_rb: {}\n")
    (folder / "notes.md").write_text("not a submission\n")
    code, out, err = run_cli(["exercise", "grade", "home_hold", folder, "--csv",
                              tmp_path / "grades.csv"])
    assert code == 0, err
    rows = (tmp_path / "grades.csv").read_text().splitlines()
    assert rows[0].startswith("student,score,max_score,passed,runs,stays upright")  # runs: eve's
    by_student = {row.split(",")[0]: row.split(",") for row in rows[1:]}
    assert set(by_student) == {"ada", "bob", "cat", "dan", "eve"}
    assert by_student["ada"][1:4] == ["10", "10", "yes"]
    assert by_student["bob"][3] == "no"
    assert by_student["eve"][1] == "0" and "runs" in by_student["eve"]
    assert by_student["cat"][1] == "0" and "cat.yml:2: malformed YAML" in rows[3]
    assert by_student["dan"][1] == "0" and "no controllers.yaml in" in rows[4] \
        and "it holds Controllers.yaml" in rows[4]
    (folder / "ada.yaml").write_text(ex.solution.read_text())
    code, _, err = run_cli(["exercise", "grade", "home_hold", folder, "--csv",
                            tmp_path / "again.csv"])
    assert code == 2 and "two submissions of ada" in err and not (tmp_path / "again.csv").exists()
    (folder / "ada.yaml").unlink()
    code, out, err = run_cli(["exercise", "grade", "home_hold", folder, "--csv",
                              tmp_path / "grades.csv"])
    assert code == 2 and "exists" in err  # nothing overwritten without --force
    code, out, err = run_cli(["exercise", "grade", "home_hold", folder, "--json"])
    assert code == 2 and "--json writes one submission" in err
    results = json.loads(run_cli(["exercise", "grade", "home_hold",
                                  folder / "ada" / "controllers.yaml", "--json"])[1])
    jsonschema.validate(results, SCHEMA)
    assert results["score"] == 10 == sum(t["max_score"] for t in results["tests"])
    assert {t["name"] for t in results["tests"]} == {"stays upright", "holds home",
                                                      "no oscillation"}


def test_start_new_and_bad_exercises(tmp_path):
    code, out, err = run_cli(["exercise", "start", "pid_spec", tmp_path / "st"])
    assert code == 0, err
    assert {p.name for p in (tmp_path / "st").iterdir()} == {"README.md", "controllers.yaml",
                                                             "check.py"}
    code, _, err = run_cli(["exercise", "start", "pid_spec", tmp_path / "st"])
    assert code == 2 and "exists" in err and err[-1] == "\n" and err.count("\n") == 1
    code, _, err = run_cli(["exercise", "new", "mine", tmp_path / "mine"])
    assert code == 0, err
    mine = find_exercise(tmp_path / "mine")
    assert grade(mine, mine.solution).score == mine.points
    assert not grade(mine, mine.starter).passed
    (tmp_path / "mine" / "exercise.yaml").write_text("name: mine\nsubmission: essay\n")
    code, _, err = run_cli(["exercise", "grade", tmp_path / "mine", mine.solution])
    assert code == 2 and "exercise.yaml" in err and "'submission' is 'essay'" in err
    code, _, err = run_cli(["exercise", "show", "no_such_exercise"])
    assert code == 2 and "no exercise 'no_such_exercise'" in err
    code, out, _ = run_cli(["exercise", "list"])
    assert code == 0 and all(n in out for n in ("model_checks", "home_hold", "pid_spec",
                                                 "arms_routine"))


def test_beside_puts_the_submission_next_to_the_graders_files(tmp_path):
    from mexone.exercises import GradeContext

    ex = find_exercise("arms_routine")
    law = tmp_path / "handed_in.py"
    law.write_text("class MyLaw: ...\n")
    ctx = GradeContext(ex, law, seed=1)
    folder = ctx.beside({"controllers.yaml": "mex_rb: {}\n"}, as_name="my_law.py")
    assert (folder / "my_law.py").read_text() == law.read_text()
    assert (folder / "controllers.yaml").read_text() == "mex_rb: {}\n"
    ctx.cleanup()
    assert not folder.exists() and law.exists()


def test_sigterm_stops_the_grading_and_the_submissions_processes(tmp_path):
    import signal
    import subprocess
    import sys

    from helpers import wait_until
    from mexone.routines import processes

    path = tmp_path / "routine.py"
    path.write_text("import time\ntime.sleep(60)\n")
    grader = subprocess.Popen([sys.executable, "-m", "mexone", "exercise", "grade",
                               "arms_routine", str(path)], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True)
    try:  # the fork server, the run's monitor, the run, the routine's own process
        assert wait_until(lambda: len(processes.descendants(grader.pid)) >= 4, timeout=30)
        below = set(processes.descendants(grader.pid))
        grader.send_signal(signal.SIGTERM)
        _, err = grader.communicate(timeout=15)
    finally:
        grader.kill()
    assert grader.returncode == 143 and "interrupted by SIGTERM" in err
    assert wait_until(lambda: not below & _running(), timeout=5)


def _running() -> set[int]:
    from mexone.routines import processes

    return {p.pid for p in processes.table().values() if p.running}


def test_a_killed_grader_takes_its_runs_with_it():
    """SIGKILL (the GUI's Exercises panel ends a self-check's process group so): the fork
    server, the run's monitor and a run sleeping for a minute end with the grader."""
    import signal
    import subprocess
    import sys

    from helpers import wait_until
    from mexone.routines import processes

    grader = subprocess.Popen([sys.executable, "-c", "import time\n"
                               "from mexone.exercises import run_isolated\n"
                               "run_isolated(time.sleep, 60)\n"])
    try:
        assert wait_until(lambda: len(processes.descendants(grader.pid)) >= 3, timeout=30)
        below = set(processes.descendants(grader.pid))
        grader.send_signal(signal.SIGKILL)
        grader.wait(timeout=5)
    finally:
        grader.kill()
    assert wait_until(lambda: not below & _running(), timeout=5)


SPY = '''"""Looks for the grader's state in its own process's memory and reports what it found."""
import gc
import os
import sys

from mexone import rospy

rospy.init_node("spy")
SUSPECTS = {"MjModel", "MjData", "MjSpec", "Variation", "Lab", "Simulation", "GradeContext",
            "Exercise", "Generator"}
found = sorted({type(o).__name__ for o in gc.get_objects() if type(o).__name__ in SUSPECTS})
found += [k for k, v in os.environ.items() if "teacher-secret" in v]
found += ["mujoco imported"] if "mujoco" in sys.modules else []
rospy.sleep(0.01)
raise RuntimeError("found: " + (", ".join(found) or "nothing"))
'''


def _spy_run(path: Path, own_process: bool) -> str:
    from mexone.exercises.isolate import run_trusted
    from mexone.exercises.sim import Variation, simulate

    run = run_trusted(simulate, 0.05, routine=path, variation=Variation(mass=1.2345),
                      raise_routine_errors=False, own_process=own_process)
    return run.error


def test_a_graded_routine_cannot_read_the_varied_model(tmp_path, monkeypatch):
    """The routine's process holds no model, no variation, no secret; the simulator, which
    holds them, refuses to run the spy in its own process (own_process=False): it runs no
    student code."""
    from mexone.exercises.grading import SECRET_ENV

    monkeypatch.setenv(SECRET_ENV, "teacher-secret-xyz")
    path = tmp_path / "spy.py"
    path.write_text(SPY)
    assert _spy_run(path, own_process=True).endswith("RuntimeError: found: nothing")
    inside = _spy_run(path, own_process=False)
    assert "UntrustedCode: the grader's simulator runs no student code, and spy.py (Python " \
        "code) is not the grader's" in inside, inside


def _load(path: str | Path) -> str:
    from mexone.description.loader import load_model
    from mexone.errors import MexoneError

    try:
        load_model(path)
    except MexoneError as exc:
        return exc.one_line()
    return "loaded"


def test_the_simulator_expands_no_students_xacro(tmp_path):
    """xacro's expressions are Python: the simulator refuses a student's (a grader expands
    one with ctx.run, in a jail); the robots mexone ships expand as ever."""
    from mexone.exercises.isolate import run_jailed, run_trusted

    path = tmp_path / "robot.urdf.xacro"
    path.write_text('<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro">'
                    '<link name="${\'base\'}"/></robot>\n')
    with pytest.raises(SubmissionFailed, match=r"UntrustedCode: the grader's simulator runs no "
                       r"student code, and robot.urdf.xacro \(a xacro file"):
        run_trusted(_load, str(path))
    assert run_jailed(_load, path) == "loaded"  # a copy of it, in the jail


def _scan_for_grader_state() -> list[str]:
    """In the isolated child: what of the grading process's state a controller could find."""
    import gc

    from mexone.exercises.grading import SECRET_ENV

    names = {"GradeContext", "Exercise", "Generator", "Result"}
    found = sorted({type(o).__name__ for o in gc.get_objects() if type(o).__name__ in names})
    found += [f"{SECRET_ENV} in the environment"] if SECRET_ENV in os.environ else []
    found += [f"the secret seed {o!r}" for o in gc.get_objects()
              if isinstance(o, dict) and isinstance(o.get("secret_seed"), int)]
    return found


def test_the_isolated_child_holds_no_seed_nor_secret(monkeypatch, tmp_path):
    """A controller runs in the isolated child with the varied model; the secret seed, the
    episode's seed and the teacher's secret stay in the grading process."""
    from mexone.exercises import GradeContext
    from mexone.exercises.grading import SECRET_ENV

    monkeypatch.setenv(SECRET_ENV, "teacher-secret-xyz")
    ctx = GradeContext(find_exercise("balance_under_pushes"), tmp_path / "balance.py", seed=1)
    assert ctx.rng.random() >= 0 and ctx.exercise.secret_seed is not None
    assert run_isolated(_scan_for_grader_state) == []


def test_a_controller_that_fails_to_import_is_named_as_the_student_knows_it(tmp_path):
    """Its file by its name, not the grader's temporary copy; no hint about the GUI's Reload."""
    path = tmp_path / "handed_in.py"
    path.write_text("raise SystemExit(0)\n")
    result = grade(find_exercise("gravity_compensation"), path)
    assert result.score == 0 and "gravity_compensation.py:1: SystemExit: 0" in result.failure
    assert "/tmp" not in result.failure and "Reload" not in result.failure, result.failure


def test_a_run_after_the_fork_server_died_starts_a_new_one():
    from mexone.exercises import isolate

    assert run_isolated(sum, [1, 2]) == 3
    server = isolate._server()
    server.process.kill()
    server.process.wait()
    assert run_isolated(sum, [3, 4]) == 7 and isolate._server() is not server


def test_which_routines_get_a_process_of_their_own():
    """The submission always (even the reference, which lies in the exercise's folder); a
    routine file of the exercise's own (the teacher's) and mexone's shipped ones do not."""
    from mexone.exercises import GradeContext

    ex = find_exercise("pid_spec")
    ctx = GradeContext(ex, ex.folder / "step.py", seed=1)
    calls = []
    ctx.measure = lambda target, *args, **kwargs: calls.append(kwargs.get("own_process"))
    ctx.simulate(1.0, routine=ctx.submission)
    ctx.simulate(1.0, routine=ex.folder / "step.py", controllers=ex.solution)
    ctx.submission = ex.solution
    ctx.simulate(1.0, routine=ex.folder / "step.py")
    assert calls == [None, None, False]  # None: simulate's default, own process unless shipped


def test_runs_at_once_share_nothing():
    """Several graded runs at once (issue 37's --workers): each its own fork, jail and uid;
    every result is its own call's."""
    from concurrent.futures import ThreadPoolExecutor

    from mexone.exercises.isolate import run_jailed, run_trusted

    with ThreadPoolExecutor(6) as pool:
        futures = [pool.submit(run_jailed if k % 2 else run_trusted, abs, -k) for k in range(12)]
        assert [f.result() for f in futures] == list(range(12))
