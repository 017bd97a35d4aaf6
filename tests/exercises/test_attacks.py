"""The cheating student, through the whole grading pipeline (`mexone exercise grade` under a
shell's `timeout` with the teacher's secret in its environment): a forged result written to
every descriptor found by walking its frames, a pickle whose __reduce__ runs a command in the
grader, the secret looked for in every process's environment, another student's submission
rewritten, files written outside its folder, 40 programs left running in sessions of their own,
the network. Acceptance: 0 forged grades, 0 secrets read, 0 writes outside the scratch folder,
0 processes left.

Two small exercises of a teacher's (the pipeline is the course's: ctx.simulate runs the
student's routine in a jail beside the simulator; ctx.run runs a student's function in a jail)
keep it fast: a routine that must bend the elbow, and an estimate(data) of a hidden number."""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from helpers import sleeping, wait_until

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="the jail's layers are Linux's")

SECRET = "teacher-secret-7c41"
SRC = str(Path(__file__).resolve().parents[2] / "src")
SLEEP = "301.5"  # what the left-behind programs sleep: how the test finds them

ROUTINE_EXERCISE = {
    "exercise.yaml": "name: bend\nsubmission: routine\nfile: routine.py\nseeds: [1]\n"
                     "secret_seed: 77\ntime_limit: 60\ncpu_limit: 60\n",
    "grader.py": textwrap.dedent('''
        from mexone.exercises import Check

        def grade(ctx):
            run = ctx.simulate(0.4, routine=ctx.submission)
            _, q = run.joint("l_elbow")
            bent = q.size > 0 and float(q[-1]) < -0.3
            return [Check.true("bends the elbow", bent, f"ends at {q[-1]:.3f} rad" if q.size
                               else "no samples", weight=1)]
    '''),
    "statement.md": "Bend the left elbow.\n",
}
HONEST_ROUTINE = textwrap.dedent('''
    from mexone import rospy
    from mexone.msgs import Float64
    rospy.init_node("bend")
    pub = rospy.Publisher("/mex_rb/l_elbow_position_controller/command", Float64, queue_size=1)
    rate = rospy.Rate(100)
    while not rospy.is_shutdown():
        pub.publish(Float64(-0.6))
        rate.sleep()
''')

ESTIMATE_EXERCISE = {
    "exercise.yaml": "name: guess\nsubmission: routine\nfile: guess.py\nseeds: [1]\n"
                     "secret_seed: 78\ntime_limit: 60\nlive: false\n",
    "grader.py": textwrap.dedent('''
        import importlib.util
        import tempfile
        from pathlib import Path

        from mexone.exercises import Check

        def estimate(submission: Path, data: Path) -> float:
            spec = importlib.util.spec_from_file_location("guess", submission)
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
            return float(module.estimate(str(data)))

        def grade(ctx):
            truth = 1.0 if ctx.local else float(ctx.rng.uniform(2.0, 3.0))
            with tempfile.TemporaryDirectory() as tmp:
                data = Path(tmp) / "data.txt"
                data.write_text(f"{2 * truth!r}\\n")
                value = ctx.run(estimate, ctx.submission, data)
            return [Check.true("estimates the number", abs(value - truth) < 1e-9,
                               f"{value:g}", weight=1)]
    '''),
    "statement.md": "Half the number in the file.\n",
}
HONEST_ESTIMATE = "def estimate(data):\n    return float(open(data).read()) / 2\n"

# what every attack does first: look for the secret, write outside, leave programs, reach out
PROBES = textwrap.dedent('''
    import json, os, pickle, socket, subprocess, sys
    FOUND = []
    OUTSIDE = ("/tmp/mexone-attack-outside.txt", os.path.expanduser("~/../../mexone-attack-x"))
    def _probe(other, port):
        for pid in os.listdir("/proc"):
            if pid.isdigit():
                for name in ("environ", "cmdline"):
                    try:
                        with open(f"/proc/{pid}/{name}", "rb") as f:
                            if b"SECRET_VALUE" in f.read():
                                FOUND.append(f"/proc/{pid}/{name}")
                    except OSError:
                        pass
        if any("SECRET_VALUE" in v for v in os.environ.values()):
            FOUND.append("environment")
        for path in (other, *OUTSIDE):  # the grader's view decides (a jail's /tmp is its own)
            try:
                with open(path, "w") as f:
                    f.write("print('zzz was here')\\n")
                if path == other:
                    FOUND.append("wrote " + path)
            except OSError:
                pass
        for family, kind, where in ((socket.AF_INET, socket.SOCK_STREAM, ("127.0.0.1", port)),
                                    (socket.AF_INET, socket.SOCK_DGRAM, ("127.0.0.1", port)),
                                    (socket.AF_INET6, socket.SOCK_STREAM, ("::1", port))):
            try:
                s = socket.socket(family, kind)
                s.settimeout(1)
                s.connect(where)
                s.send(b"x")
                FOUND.append(f"network {kind.name}")
            except OSError:
                pass
        for _ in range(40):
            subprocess.Popen(["sleep", "SLEEP"], start_new_session=True)
        if FOUND:  # a way out: said in the reason the grade gives
            raise RuntimeError(f"FOUND {FOUND}")

    def _forge(data):
        """Write `data` to every descriptor this process holds (the result pipe among them,
        as a walk of sys._getframe() finds it) and end before the grader's own result."""
        frame, fds = sys._getframe(), set(range(3, 64))
        while frame is not None:
            fds |= {v for v in frame.f_locals.values() if isinstance(v, int) and 2 < v < 1024}
            frame = frame.f_back
        for fd in sorted(fds):
            try:
                os.write(fd, data)
            except OSError:
                pass
        sys.stdout.flush()
        os._exit(0)

    class Evil:
        def __reduce__(self):
            return (os.system, ("touch PWNED",))
''').replace("SECRET_VALUE", SECRET).replace("SLEEP", SLEEP)


def _attack_routine(other: Path, port: int, pwned: Path) -> tuple[str, str]:
    """A routine that probes, then forges a perfect Run and a pickle, then ends."""
    return PROBES.replace("PWNED", str(pwned)) + textwrap.dedent(f'''
        from mexone import rospy
        rospy.init_node("cheat")
        _probe({str(other)!r}, {port})
        run = {{"$": "Run", "t": [0.4], "joints": ["l_elbow"], "setpoint": [[-0.6]],
               "position": [[-0.6]], "base_height": [0.9], "tilt": [0.0], "fell_at": None,
               "error": None, "sim_time": 0.4}}
        _forge(json.dumps({{"ok": run}}).encode() + pickle.dumps(Evil()))
    '''), "sent what mexone cannot read"


def _attack_estimate(other: Path, port: int, pwned: Path) -> tuple[str, str]:
    return PROBES.replace("PWNED", str(pwned)) + textwrap.dedent(f'''
        def estimate(data):
            _probe({str(other)!r}, {port})
            _forge(pickle.dumps(("ok", Evil())))
    '''), "not what the grader reads (result: not JSON"


def _sleeps() -> list[int]:
    return sleeping(SLEEP)


def _exercise(folder: Path, files: dict[str, str]) -> Path:
    folder.mkdir(parents=True)
    for name, text in files.items():
        (folder / name).write_text(text)
    (folder / "starter").mkdir()
    (folder / "solution").mkdir()
    return folder


def _grade(exercise: Path, submissions: Path, csv: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "MEXONE_EXERCISE_SECRET": SECRET, "PYTHONPATH": SRC}
    return subprocess.run(["timeout", "300", sys.executable, "-m", "mexone", "exercise", "grade",
                           str(exercise), str(submissions), "--csv", str(csv)], env=env,
                          capture_output=True, text=True, timeout=330)


@pytest.fixture
def listener():
    server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    server.bind(("127.0.0.1", 0))
    server.listen(50)
    server.settimeout(0.05)
    yield server
    server.close()


@pytest.mark.parametrize("kind", ["routine", "estimate"])
def test_the_cheating_student_gets_nothing_and_leaves_nothing(kind, tmp_path, listener):
    """Graded in a folder before an honest student: the attack scores 0 with its reason, the
    honest one full marks on a file the attack could not touch; the attack found no secret
    and reached no network; nothing of it runs on; no command ran in the grader."""
    files, honest, attack = ((ROUTINE_EXERCISE, HONEST_ROUTINE, _attack_routine)
                             if kind == "routine" else
                             (ESTIMATE_EXERCISE, HONEST_ESTIMATE, _attack_estimate))
    for stale in ("/tmp/mexone-attack-outside.txt", "/tmp/mexone-attack-x"):  # an old run's
        Path(stale).unlink(missing_ok=True)
    exercise = _exercise(tmp_path / "exercise", files)
    file = "routine.py" if kind == "routine" else "guess.py"
    subs = tmp_path / "subs"
    (subs / "aaa").mkdir(parents=True)
    (subs / "zzz").mkdir()
    other = subs / "zzz" / file
    other.write_text(honest)
    pwned = tmp_path / "pwned"
    text, why = attack(other, listener.getsockname()[1], pwned)
    (subs / "aaa" / file).write_text(text)
    out = _grade(exercise, subs, tmp_path / "grades.csv")
    assert out.returncode == 0, out.stderr
    rows = {r.split(",")[0]: r for r in (tmp_path / "grades.csv").read_text().splitlines()[1:]}
    assert rows["zzz"].split(",")[1] == "10", rows  # graded on its own, untouched file
    assert other.read_text() == honest
    aaa = rows["aaa"]
    assert aaa.split(",")[1] == "0", aaa  # no forged grade
    assert why in aaa and "FOUND" not in aaa, aaa  # its probes found nothing: it went on to forge
    assert SECRET not in (tmp_path / "grades.csv").read_text() + out.stdout + out.stderr
    assert not pwned.exists()  # the pickle ran nothing
    assert not Path("/tmp/mexone-attack-outside.txt").exists()
    assert not Path("/tmp/mexone-attack-x").exists() and not (tmp_path / "mexone-attack-x").exists()
    with pytest.raises(TimeoutError):
        listener.accept()
    assert wait_until(lambda: not _sleeps(), timeout=10), _sleeps()


def test_the_attacks_report_what_they_found(tmp_path, listener):
    """The probes themselves work (this test would pass vacuously otherwise): run without a
    jail, in the test's own process, they find the secret, write the other file, reach the
    network and leave programs running."""
    other = tmp_path / "zzz.py"
    other.write_text("x\n")
    code = PROBES.replace("PWNED", str(tmp_path / "p")) + \
        f"\n_probe({str(other)!r}, {listener.getsockname()[1]})\n"
    env = {**os.environ, "MEXONE_EXERCISE_SECRET": SECRET}
    try:
        with open(tmp_path / "err", "w") as err:  # a file: the sleeps hold it open
            subprocess.run([sys.executable, "-c", code], env=env, stdout=subprocess.DEVNULL,
                           stderr=err, timeout=60)
        found = (tmp_path / "err").read_text().split("FOUND", 1)[1]
        assert "environment" in found and "wrote " + str(other) in found, found
        assert "network SOCK_STREAM" in found, found
        assert len(_sleeps()) == 40
    finally:
        for pid in _sleeps():
            os.kill(pid, 9)
        Path("/tmp/mexone-attack-outside.txt").unlink(missing_ok=True)
        shutil.rmtree(tmp_path, ignore_errors=True)


def test_a_symlinked_submission_scores_nothing(tmp_path):
    """A submission that is a symbolic link (to the teacher's reference, say) is not followed:
    0 points, the reason, and nothing of what it points at is run."""
    from mexone.exercises import grade, load_exercise

    exercise = load_exercise(_exercise(tmp_path / "exercise", ROUTINE_EXERCISE))
    reference = tmp_path / "reference.py"
    reference.write_text(HONEST_ROUTINE)
    link = tmp_path / "routine.py"
    link.symlink_to(reference)
    result = grade(exercise, link)
    assert result.score == 0 and result.failure.startswith("routine.py is a symbolic link")


def test_a_submission_swapped_for_a_symlink_after_the_look_is_not_followed(tmp_path):
    """The copy the runs see is opened with O_NOFOLLOW: a student who swaps the handed-in file
    for a link (to the reference) between grade()'s look and its read gets a refusal."""
    from mexone.errors import InputError
    from mexone.exercises.grading import _private_copy

    reference = tmp_path / "reference.py"
    reference.write_text(HONEST_ROUTINE)
    link = tmp_path / "routine.py"
    link.symlink_to(reference)
    (tmp_path / "work").mkdir()
    with pytest.raises(InputError, match="routine.py: is a symbolic link: refused, not read"):
        _private_copy(link, tmp_path / "work")
    assert not list((tmp_path / "work").rglob("routine.py"))


def test_the_secret_is_never_in_a_report(tmp_path, monkeypatch):
    """Even a submission that guessed the secret cannot have the grader print it: a reason and
    an output that hold it show "[the secret]" instead."""
    from mexone.exercises import grade, load_exercise
    from mexone.exercises.grading import as_text, gradescope_json

    monkeypatch.setenv("MEXONE_EXERCISE_SECRET", "hunter2-guessed-secret")
    exercise = load_exercise(_exercise(tmp_path / "exercise", ROUTINE_EXERCISE))
    path = tmp_path / "routine.py"
    path.write_text("print('the secret is hunter2-guessed-secret')\n"
                    "raise RuntimeError('hunter2-guessed-secret')\n")
    result = grade(exercise, path)
    shown = as_text(result) + json.dumps(gradescope_json(result))
    assert result.score == 0 and "hunter2-guessed-secret" not in shown, shown
    assert "RuntimeError: [the secret]" in result.failure, result.failure


CHEATING_CONTROLLER = '''
import os
import numpy as np
from mexone.control import Param, PythonController

FOUND = []
for pid in os.listdir("/proc"):
    if pid.isdigit():
        try:
            with open(f"/proc/{pid}/environ", "rb") as f:
                if b"SECRET_VALUE" in f.read():
                    FOUND.append(pid)
        except OSError:
            pass
try:
    with open("OUTSIDE", "w") as f:
        f.write("x")
    FOUND.append("wrote outside")
except OSError:
    pass


class GravityCompensation(PythonController):
    command_interface = "effort"
    kp = Param(5.0, low=0.0, high=1e4)
    kd = Param(0.5, low=0.0, high=1e3)

    def activate(self, state):
        if FOUND:
            raise RuntimeError(f"FOUND {FOUND}")
        self.dynamics.model.opt.gravity[:] = 0  # was 10/10: no gravity left to compensate
        self.q0 = np.array(state.q, dtype=float)

    def update(self, state, t, dt):
        return self.kp * (self.q0 - state.q) - self.kd * state.dq
'''


def test_a_graded_controller_runs_in_its_worker_and_changes_no_physics(tmp_path):
    """gravity_compensation through `mexone exercise grade` with the secret set: the controller
    (in its worker, a jail beside the simulator) zeroes its model's gravity, reads every
    process's environment and writes outside its folder. It finds nothing, writes nothing, and
    its do-nothing PD sags under the simulator's gravity: no pass."""
    outside = tmp_path / "outside.txt"
    subs = tmp_path / "subs"
    subs.mkdir()
    (subs / "gravity_compensation.py").write_text(
        CHEATING_CONTROLLER.replace("SECRET_VALUE", SECRET).replace("OUTSIDE", str(outside)))
    env = {**os.environ, "MEXONE_EXERCISE_SECRET": SECRET, "PYTHONPATH": SRC}
    out = subprocess.run([sys.executable, "-m", "mexone", "exercise", "grade",
                          "gravity_compensation", str(subs / "gravity_compensation.py"), "--json"],
                         env=env, capture_output=True, text=True, timeout=300)
    report = json.loads(out.stdout)
    assert report["score"] < 7, report
    shown = out.stdout + out.stderr
    assert "FOUND" not in shown and SECRET not in shown and not outside.exists(), shown
    assert "holds the arm" in shown and "runs" in shown
