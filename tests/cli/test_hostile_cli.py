"""Every verb with hostile arguments: one line `mexone: ...` naming the flag or file, exit 2, no
traceback, no hang, and no file of the user's touched.

The cases run in-process (the CLI's `main`), so the corpus costs one import, not one per case;
the few that could start the web GUI run as processes with a timeout.
"""

from __future__ import annotations

import logging
import subprocess
import sys
import time
from pathlib import Path

import pytest

from mexone import signals
from mexone.cli import main
from mexone.lab import Lab
from mexone.record.bag import BagRecorder
from mexone.robots import mex_one

SWEEP = ["sweep", "--joint", "l_elbow", "--p", "10", "--duration", "0.3", "--workers", "1"]
MINE = "mine"  # the content of every file the user already has

# (id, argv, what stderr must say); every case must exit 2 in under 10 s
CASES = [
    # --- numbers at the CLI edge ------------------------------------------------------------
    ("z-nan", ["sim", "--headless", "-z", "nan"], "argument -z: nan must be a finite number"),
    ("x-inf", ["sim", "--headless", "-x", "inf"], "argument -x: inf must be a finite number"),
    ("y-huge", ["sim", "--headless", "-y", "1e5"], "argument -y: 1e5 must be"),
    ("yaw-degrees", ["sim", "--headless", "-Y", "90"], "radians"),
    ("roll-text", ["sim", "--headless", "-R", "up"], "argument -R: 'up' is not a number"),
    ("rtf-nan", ["sim", "--headless", "--rtf", "nan"], "argument --rtf: nan must be"),
    ("rtf-negative", ["sim", "--headless", "--rtf", "-1"], "argument --rtf: -1 must be"),
    ("rtf-inf", ["sim", "--headless", "--rtf", "inf"], "0 runs as fast as possible"),
    ("rtf-huge", ["sim", "--headless", "--rtf", "200"], "argument --rtf: 200 must be a finite number >= 0 and <= 100"),
    ("duration-zero", ["sim", "--headless", "--duration", "0"], "argument --duration: 0 must be"),
    ("duration-nan", ["sim", "--headless", "--duration", "nan"], "argument --duration: nan"),
    ("duration-tiny", ["sim", "--headless", "--duration", "1e-300"], "argument --duration"),
    ("duration-inf", ["run", "home", "--duration", "inf"], "argument --duration: inf"),
    ("record-duration", ["record", "-o", "r.mcap", "--duration", "-5"], "argument --duration"),
    ("port-negative", ["sim", "--port", "-1"], "argument --port: -1 must be an integer >= 0"),
    ("port-huge", ["sim", "--port", "99999"], "argument --port: 99999 must be"),
    ("port-text", ["sim", "--port", "http"], "argument --port: 'http' is not an integer"),
    ("host-bad-ip", ["sim", "--host", "999.1.1.1"], "argument --host: '999.1.1.1' is not"),
    ("host-empty", ["sim", "--host", ""], "argument --host: '' is not"),
    ("host-option", ["sim", "--host=-x"], "argument --host: '-x' is not"),
    ("fps-zero", ["render", "arms", "-o", "r.mp4", "--fps", "0"], "argument --fps: 0 must be"),
    ("fps-huge", ["render", "arms", "-o", "r.mp4", "--fps", "1e9"], "argument --fps: 1e9"),
    ("fps-nan", ["render", "arms", "-o", "r.mp4", "--fps", "nan"], "argument --fps: nan"),
    ("size-zero", ["render", "arms", "-o", "r.mp4", "--size", "0x0"], "argument --size: 0x0"),
    ("size-huge", ["render", "arms", "-o", "r.mp4", "--size", "99999x2"], "from 16x16 to 3840x2160"),
    ("size-text", ["render", "arms", "-o", "r.mp4", "--size", "big"], "is not WIDTHxHEIGHT"),
    ("size-nan", ["render", "arms", "-o", "r.mp4", "--size", "nanxnan"], "argument --size"),
    ("camera-nan", ["render", "arms", "-o", "r.mp4", "--camera", "nan,nan,nan"],
     "argument --camera: 'nan,nan,nan': nan must be a finite number"),
    ("camera-two", ["render", "arms", "-o", "r.mp4", "--camera", "1,2"], "is not track, fixed"),
    ("camera-behind", ["render", "arms", "-o", "r.mp4", "--camera", "0,0,-5"], "distance (m)"),
    ("camera-elevation", ["render", "arms", "-o", "r.mp4", "--camera", "0,120,3"], "120 must be"),
    ("step-nan", [*SWEEP, "--step", "nan"], "argument --step: nan must be a finite number"),
    ("step-inf", [*SWEEP, "--step", "inf"], "argument --step: inf"),
    ("step-zero", [*SWEEP, "--step", "0"], "--step 0 moves nothing"),
    ("sweep-duration-nan", [*SWEEP, "--duration", "nan"], "argument --duration: nan"),
    ("sweep-duration-short", [*SWEEP, "--duration", "0.1"], "argument --duration: 0.1"),
    ("sweep-duration-huge", [*SWEEP, "--duration", "1e300"], "argument --duration: 1e300"),
    ("random-negative", [*SWEEP, "--random", "-3"], "argument --random: -3 must be an integer"),
    ("random-zero", [*SWEEP, "--random", "0"], "argument --random: 0"),
    ("random-float", [*SWEEP, "--random", "1e9"], "argument --random: '1e9' is not an integer"),
    ("random-huge", [*SWEEP, "--random", "100000000"], "argument --random: 100000000"),
    ("seed-negative", [*SWEEP, "--random", "2", "--seed", "-1"], "argument --seed: -1"),
    ("workers-zero", [*SWEEP, "--workers", "0"], "argument --workers: 0"),
    ("workers-huge", [*SWEEP, "--workers", "100000"], "argument --workers: 100000"),
    ("gain-count-huge", [*SWEEP, "--p", "10:20:100000000"], "the count must be 1 to 10000"),
    ("gain-count-zero", [*SWEEP, "--p", "1:2:0"], "the count must be 1 to 10000"),
    ("gain-nan", [*SWEEP, "--p", "nan"], "gains must be finite and >= 0"),
    ("gain-negative", [*SWEEP, "--p", "-1"], "gains must be finite and >= 0"),
    ("gain-huge", [*SWEEP, "--p", "1e300"], "--p '1e300': 1e+300 must be a finite number >= 0 and <= 100000"),
    ("grid-huge", [*SWEEP, "--p", "1:2:1000", "--d", "1:2:1000"], "more than 100000"),
    # --- what used to be tracebacks ------------------------------------------------------------
    ("param-unclosed", ["run", "home", "_joint:=[", "--duration", "0.1"],
     "'_joint:=[': "),
    ("param-python-tag", ["run", "home", '_joint:=!!python/object/apply:os.system ["true"]',
                          "--duration", "0.1"], "could not determine a constructor"),
    ("param-alias", ["record", "home", "-o", "r.mcap", "_a:=*x", "--duration", "0.1"],
     "undefined alias"),
    ("param-render", ["render", "arms", "-o", "r.mp4", "_a:={"], "'_a:={': "),
    ("record-into-folder", ["record", "-o", "dir.mcap", "--force", "--duration", "0.1"],
     "dir.mcap: is a folder, not a file"),
    ("sim-record-into-folder", ["sim", "--headless", "--duration", "0.1", "--record", "dir.mcap",
                                "--force"], "dir.mcap: is a folder"),
    ("record-unwritable", ["record", "-o", "/proc/mexone.mcap", "--duration", "0.1"],
     "/proc/mexone.mcap: cannot write"),
    ("render-missing-folder", ["render", "arms", "-o", "missing_dir/r.mp4", "--duration", "0.1"],
     "missing_dir/r.mp4: output folder does not exist"),
    ("plot-missing-folder", ["plot", "a.mcap", "-o", "missing_dir/p.png"],
     "missing_dir/p.png: output folder does not exist"),
    ("plot-into-folder", ["plot", "a.mcap", "-o", "dir.png", "--force"], "dir.png: is a folder"),
    ("convert-missing-folder", ["convert", "{model}", "-o", "missing_dir/x.urdf"],
     "output folder does not exist"),
    ("convert-into-folder", ["convert", "{model}", "-o", "dir.urdf", "--force"], "is a folder"),
    ("sweep-into-file", [*SWEEP, "-o", "exists.txt"], "exists.txt: is a file"),
    ("sweep-unknown-joint", ["sweep", "--joint", "l_wing", "--p", "10", "-o", "sw"],
     "no running controller moves joint l_wing"),
    ("sweep-unknown-routine", [*SWEEP, "--routine", "nope", "-o", "sw"], "no routine 'nope'"),
    ("sweep-unknown-model", [*SWEEP, "--model", "nope.urdf", "-o", "sw"], "nope.urdf: no such file"),
    ("record-no-output", ["record", "--duration", "0.1"], "record needs -o BAG"),
    ("recover-nothing", ["record", "--recover", "nope.mcap"], "nope.mcap: no such file"),
    ("recover-not-a-bag", ["record", "--recover", "notbag.mcap"], "not a bag (it starts with neither"),
    ("recover-text", ["record", "--recover", "exists.txt"], "cannot recover '.txt' files"),
    ("recover-with-routine", ["record", "arms", "--recover", "a.mcap"], "it runs no routine"),
    ("plot-not-a-bag", ["plot", "notbag.mcap", "-o", "p.png"], "not a bag (it starts with neither"),
    ("plot-missing-bag", ["plot", "nope.mcap", "-o", "p.png"], "nope.mcap: no such file"),
    ("record-name-too-long", ["record", "-o", "a" * 300 + ".mcap", "--duration", "0.1"],
     "cannot use this name: File name too long"),
    ("plot-name-too-long", ["plot", "a.mcap", "-o", "a" * 300 + ".png"], "File name too long"),
    ("sweep-name-too-long", [*SWEEP, "-o", "a" * 300], "File name too long"),
    ("recover-name-too-long", ["record", "--recover", "a" * 300 + ".mcap"], "File name too long"),
    ("record-active-name", ["record", "-o", "x.mcap.active", "--duration", "0.1"],
     "cannot record to '.active'"),
    ("param-deep", ["run", "home", "_x:=" + "[" * 3000, "--duration", "0.1"], "levels deep (the limit is 1000)"),
    ("ray-address-local", [*SWEEP, "--address", "10.0.0.5:6379"], "add --backend ray"),
    ("ray-address-form", [*SWEEP, "--backend", "ray", "--address", "cluster"], "is not HOST:PORT"),
    ("ray-address-closed", [*SWEEP, "--backend", "ray", "--address", "127.0.0.1:1"],
     "cannot reach the Ray cluster at 127.0.0.1:1"),
    ("grade-address-local", ["exercise", "grade", "home_hold", ".", "--address", "10.0.0.5:6379"],
     "add --backend ray"),
    ("grade-address-closed", ["exercise", "grade", "home_hold", ".", "--backend", "ray",
                              "--address", "127.0.0.1:1"], "cannot reach the Ray cluster"),
    # --- no verb overwrites a user's file without --force -----------------------------------------
    ("plot-over-file", ["plot", "a.mcap", "-o", "exists.png"], "exists.png: already exists"),
    ("plot-csv-over-file", ["plot", "a.mcap", "-o", "exists.csv"], "exists.csv: already exists"),
    ("convert-over-file", ["convert", "{model}", "-o", "exists.urdf"], "exists.urdf: already exists"),
    ("render-over-file", ["render", "arms", "-o", "exists.mp4"], "exists.mp4: already exists"),
    ("record-over-file", ["record", "-o", "exists.mcap", "--duration", "0.1"],
     "exists.mcap: already exists"),
    ("sim-record-over-file", ["sim", "--headless", "--duration", "0.1", "--record", "exists.bag"],
     "exists.bag: already exists"),
    ("run-record-over-file", ["run", "home", "--duration", "0.1", "--record", "exists.mcap"],
     "exists.mcap: already exists"),
    ("record-over-killed", ["record", "-o", "killed.mcap", "--duration", "0.1"],
     "a killed recording is still here"),
    ("recover-over-file", ["record", "--recover", "killed.mcap", "-o", "exists.mcap"],
     "exists.mcap: already exists"),
    ("sweep-over-json", [*SWEEP, "-o", "s_json"], "holds a sweep already (sweep.json)"),
    ("sweep-over-heatmap", [*SWEEP, "-o", "s_png"], "holds a sweep already (heatmap.png)"),
    ("sweep-over-best", [*SWEEP, "-o", "s_yaml"], "holds a sweep already (best_gains.yaml)"),
    ("sweep-resume-other", [*SWEEP, "-o", "s_json", "--resume"], "defined differently"),
]


@pytest.fixture(scope="module")
def workspace(tmp_path_factory) -> Path:
    """A folder with what a user has lying around: files of every kind, folders named like files,
    a recording, a killed recording and the leftovers of three sweeps."""
    home = tmp_path_factory.mktemp("hostile")
    for name in ("exists.txt", "exists.png", "exists.csv", "exists.urdf", "exists.mp4",
                 "exists.mcap", "exists.bag", "notbag.mcap", "s_json/sweep.json",
                 "s_png/heatmap.png", "s_yaml/best_gains.yaml"):
        (home / name).parent.mkdir(exist_ok=True)
        (home / name).write_text(MINE)
    for name in ("dir.mcap", "dir.png", "dir.urdf"):
        (home / name).mkdir()
    lab = Lab.create()
    recorder = BagRecorder(lab, home / "a.mcap")
    lab.sim.run(0.3)
    recorder.close()
    (home / "killed.mcap.active").write_bytes((home / "a.mcap").read_bytes()[:20000])
    return home


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def run_cli(argv: list[str], capsys, monkeypatch) -> tuple[int, str]:
    """`mexone ARGV` in this process: the exit code and stderr."""
    monkeypatch.setattr(signals, "stop_on_signals", lambda: None)  # pytest keeps its handlers
    monkeypatch.setattr("mexone.cli.render.ensure_gl_backend", _no_render)
    logging.getLogger("mexone").handlers.clear()  # log to this test's captured stderr
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    return code, capsys.readouterr().err


def _no_render(_argv) -> None:
    raise AssertionError("a hostile render got as far as rendering")


@pytest.mark.parametrize("argv,expected", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_hostile_argument_is_one_line(argv, expected, workspace, capsys, monkeypatch):
    monkeypatch.chdir(workspace)
    argv = [a.replace("{model}", str(mex_one.urdf_path())) for a in argv]
    before = snapshot(workspace)
    start = time.monotonic()
    code, err = run_cli(argv, capsys, monkeypatch)
    assert time.monotonic() - start < 10
    assert code == 2, err
    assert err.startswith("mexone: ") and err.count("\n") == 1, err
    assert expected in err
    assert "Traceback" not in err
    assert snapshot(workspace) == before  # nothing written, nothing replaced


def test_case_ids_are_unique():
    assert len({c[0] for c in CASES}) == len(CASES) >= 90


def mexone(*args, timeout=30, **kw):
    return subprocess.run([sys.executable, "-m", "mexone", *args], capture_output=True,
                          text=True, timeout=timeout, **kw)


def test_gui_on_an_address_this_machine_lacks_is_refused_before_viser():
    start = time.monotonic()
    out = mexone("sim", "--host", "192.0.2.1", "--duration", "0.1", timeout=10)  # TEST-NET-1
    assert time.monotonic() - start < 10
    assert out.returncode == 2
    assert out.stderr.startswith("mexone: cannot serve the GUI on --host 192.0.2.1")
    assert out.stderr.count("\n") == 1 and "Traceback" not in out.stderr


def test_port_0_serves_on_a_free_port_and_says_which():
    out = mexone("sim", "--port", "0", "--duration", "0.05", timeout=60)
    assert out.returncode == 0, out.stderr
    line = next(x for x in out.stderr.splitlines() if "http://127.0.0.1:" in x)
    port = int(line.split("http://127.0.0.1:")[1].split()[0])
    assert 0 < port < 65536 and "was taken" not in line


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs Linux /dev/full")
def test_a_full_disk_on_stdout_is_one_line():
    with open("/dev/full", "w") as full:
        out = subprocess.run([sys.executable, "-m", "mexone", "check"], stdout=full,
                             stderr=subprocess.PIPE, text=True, timeout=60)
    assert (out.returncode, out.stderr) == (2, "mexone: No space left on device\n")
