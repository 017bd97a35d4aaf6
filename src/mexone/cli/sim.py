"""`mexone sim`: run a robot (the built-in Mex-One by default) in a world."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from mexone import signals
from mexone.cli.common import (
    DURATION,
    PORT,
    RTF,
    add_model_options,
    add_record_options,
    check_can_serve,
    folder,
    host,
    lab_from_args,
    options_from_args,
    recording,
)
from mexone.cli.ros import add_ros_options, connect_bridges, urdf_text
from mexone.errors import InputError
from mexone.physics import GAZEBO_MAPPING, DivergenceError, Simulation
from mexone.physics.monitor import RunMonitor

HELP = """\
Simulate a robot on MuJoCo the way Gazebo 7 + gazebo_ros_control would: gravity, contacts
with friction (mu1/mu2) and stiffness (kp/kd), joint damping and friction, self-collision
where <gazebo selfCollide> says so, 1 ms steps, and the ros_control controllers of the YAML
(the built-in Mex-One loads its own and holds its home pose; --no-controllers lets it fall).

Without --headless it serves the web GUI at http://127.0.0.1:8080 (--host, --port): the robot
live in 3D, play/pause/step/reset, the real-time factor, Gazebo's View overlays (centre of mass,
inertia, joints, collisions, contacts, transparent, wireframe), a slider per controller with
editable PID gains, live plots, routines and physics settings. It keeps real time (--rtf 1)
until Ctrl-C or --duration.

With --headless the run is unpaced (as fast as the machine allows) and ends with a summary:
sim time, wall time, real-time factor, base height, the fastest link speed seen, and whether
the robot came to rest; with --json also, under "controllers", the report() of each running
Python controller that defines one (the worked controllers' measurements) and each one's
real-time "budget" (ms per update, mean and worst, its deadline, deadline misses).

A simulation that diverges (NaN, or links faster than physics allows) stops with the link and
the likely cause instead of a robot flying apart: exit 1. Bad input: exit 2. Stopped by Ctrl-C or
SIGTERM: 130/143 (headless: after the summary)."""


def add_parser(sub) -> None:
    p = sub.add_parser("sim", help="simulate a robot (default: the built-in Mex-One)",
                       description=HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("model", nargs="?", type=Path,
                   help="URDF, .urdf.xacro, SDF (file or Gazebo model folder) or MJCF robot "
                        "(default: the built-in Mex-One)")
    p.add_argument("--headless", action="store_true",
                   help="no web GUI and no pacing: run, then print a summary")
    p.add_argument("--port", type=PORT, default=8080,
                   help="web GUI port (default 8080; 0 picks a free one)")
    p.add_argument("--host", type=host, default="127.0.0.1",
                   help="web GUI address (default 127.0.0.1, this machine only; 0.0.0.0 to share)")
    p.add_argument("--routines", type=folder, action="append", metavar="DIR",
                   help="a folder whose .py files the page may start as routines (repeatable; "
                        "default: the current folder). The page picks a name from a list; it "
                        "never sends a path")
    p.add_argument("--duration", type=DURATION, metavar="S",
                   help="seconds of sim time to run (default: 5 headless, else until Ctrl-C)")
    p.add_argument("--rtf", type=RTF, metavar="R",
                   help="target real-time factor (default 1, or unlimited with --headless; "
                        "0 = unlimited)")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.add_argument("--exercise", metavar="NAME_OR_DIR",
                   help="an Exercises panel on the page: the statement, your file and Check "
                        "(a folder `mexone exercise start` wrote, or an exercise's name; "
                        "docs/exercises.md)")
    p.add_argument("--paused", action="store_true",
                   help="the GUI starts paused (and pauses after each reset): watch a fall from t = 0")
    add_ros_options(p)
    p.add_argument("--explain", action="store_true",
                   help="print how each Gazebo property maps to MuJoCo, then exit")
    add_model_options(p, model_positional=True)
    add_record_options(p)
    p.set_defaults(run=run)


def _serve_gui(args: argparse.Namespace, rtf: float, duration: float | None, bridge) -> int:
    from mexone.gui.app import GuiApp

    exercise = None
    if args.exercise is not None:
        from mexone.gui.exercises import open_exercise

        exercise = open_exercise(args.exercise)
    try:
        app = GuiApp(lambda options: lab_from_args(args, options=options), options_from_args(args),
                     host=args.host, port=args.port, target_rtf=rtf,
                     routine_dirs=args.routines, paused=args.paused,
                     exercise=exercise)
        if bridge is not None:
            bridge.attach(app.lab, urdf_text(args, app.lab.sim.robot))
            app.tick_hooks.append(lambda _sim: bridge.pump())
    except OSError as exc:
        raise InputError(f"cannot serve the GUI on {args.host}:{args.port}: {exc.strerror}",
                         hint="pick another --port") from None
    port = app.server.get_port()  # viser moves on to the next free port if this one is taken
    note = "" if port == args.port or args.port == 0 else f" (port {args.port} was taken)"
    url = app.access.page_url(args.host, port)  # in a JupyterHub: through its proxy, with the key
    print(f"mexone: {app.lab.sim.robot.name} at {url}{note}  (Ctrl-C stops)", file=sys.stderr)
    if bridge is not None:
        print(f"mexone: {app.lab.sim.robot.name} is on {bridge.where()}", file=sys.stderr)
        for note in bridge.notes():
            print(f"mexone: {note}", file=sys.stderr)
    if exercise is not None:
        ex = exercise.exercise
        print(f"mexone: Exercises panel: {ex.title} ({ex.name}); Check grades "
              + (str(exercise.submission) if exercise.folder else
                 f"nothing yet (mexone exercise start {ex.name} DIR, then --exercise DIR)"),
              file=sys.stderr)
    try:
        with recording(app.lab, args.record, args.force):
            app.serve_forever(duration)  # until a signal asks it to stop (signals.requested)
    finally:
        app.stop()
    return 0


def run(args: argparse.Namespace) -> int:
    if args.explain:
        for gazebo, mujoco_name, how in GAZEBO_MAPPING:
            print(f"{gazebo}\n    -> {mujoco_name}" + (f": {how}" if how else ""))
        return 0
    headless = args.headless or args.json
    joined = args.ros or args.ros2 or args.foxglove is not None
    forever = not headless or joined
    duration = args.duration if args.duration is not None else (None if forever else 5.0)
    rtf = args.rtf if args.rtf is not None else (0.0 if headless and not joined else 1.0)
    if headless and args.exercise is not None:
        raise InputError("--exercise is a panel of the page: not with --headless or --json",
                         hint="without a page: mexone exercise grade NAME FILE --local")
    if not headless:
        check_can_serve(args.host)
    bridge = connect_bridges(args)
    try:
        if not headless:
            return _serve_gui(args, rtf, duration, bridge)
        return _run_headless(args, rtf, duration, bridge)
    finally:
        if bridge is not None:
            bridge.shutdown()


def _plain(value):
    """numpy numbers and arrays as JSON's; anything else as its text."""
    tolist = getattr(value, "tolist", None)
    return tolist() if callable(tolist) else str(value)


def _strict(value):
    """A report's NaN and infinities as null: `json.dumps` would print NaN/Infinity, which is
    not JSON (jq and JSON.parse refuse the whole summary)."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _strict(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_strict(v) for v in value]
    return value


def controller_reports(lab) -> dict:
    """`report()` of every Python controller that defines one (the worked controllers' figures),
    and every Python controller's real-time `budget` (ms per update, deadline misses), by
    controller name; a report that raises is its one-line error, not the end of the run. A
    controller a fault stopped is there with `"fault"`, its one line: a script reading the
    summary must not take a run whose controller died at t = 0.5 s for a clean one."""
    from mexone.control.controllers import PythonRunner
    from mexone.control.worker import StudentFault

    out: dict = {}
    for name, ctrl in (lab.manager.controllers.items() if lab.manager else ()):
        if not isinstance(ctrl, PythonRunner):
            continue
        fault = ctrl.fault
        if ctrl.reports and (ctrl.running or fault):
            try:
                report = ctrl.report()
                if report is not None:
                    out[name] = _strict(json.loads(json.dumps(report, default=_plain)))
            except StudentFault as exc:  # in its own process: its one line (file:line)
                out[name] = {"error": str(exc)}
            except Exception as exc:  # noqa: BLE001 - the student's code: said, the summary goes on
                out[name] = {"error": f"report() raised {type(exc).__name__}: {_said(exc)}"}
        if fault:  # first, and not hidden by a report's own "fault"
            report = out.get(name, {})
            out[name] = {"fault": fault} | (report if isinstance(report, dict) else
                                            {"report": report}) | {"fault": fault}
        budget = getattr(ctrl, "budget", None)  # the real-time budget meter (Python controllers)
        if callable(budget) and (ctrl.running or fault):
            entry = out.get(name, {})
            out[name] = (entry if isinstance(entry, dict) else {"report": entry}) | {"budget": budget()}
    return out


def _said(exc: BaseException) -> str:
    try:
        return str(exc).splitlines()[0] if str(exc) else ""
    except Exception:  # noqa: BLE001 - an exception whose __str__ raises
        return "(its message cannot be shown)"


def faulted(lab) -> list[str]:
    """The Python controllers a fault stopped during the run."""
    manager = lab.manager
    return [name for name, ctrl in (manager.controllers.items() if manager else ())
            if getattr(ctrl, "fault", None)]


def _run_headless(args: argparse.Namespace, rtf: float, duration: float | None, bridge) -> int:
    lab = lab_from_args(args, target_rtf=rtf or None)
    sim, robot = lab.sim, lab.sim.robot
    if bridge is not None:
        bridge.attach(lab, urdf_text(args, robot))
        print(f"mexone: {robot.name} is on {bridge.where()} (namespace {lab.namespace}); "
              "Ctrl-C stops", file=sys.stderr)
        for note in bridge.notes():
            print(f"mexone: {note}", file=sys.stderr)
    monitor = RunMonitor(sim)  # after joining ROS: the summary's wall time is the run's

    def tick(s: Simulation) -> None:
        monitor.tick(s)
        if bridge is not None:
            bridge.pump()

    with recording(lab, args.record, args.force):
        try:  # paced: pace every 2 ms of sim time, so /clock flows evenly
            sim.run(duration if duration is not None else float("inf"), on_tick=tick,
                    tick=0.002 if bridge is not None and rtf else 0.01, until=signals.requested)
        except DivergenceError as exc:
            monitor.error = exc.one_line()
    summary = monitor.summary()
    faults = faulted(lab)
    if args.json:
        reports = controller_reports(lab)
        print(json.dumps({k: v for k, v in summary.as_json().items() if k != "rest_time"}
                         | ({"error": summary.error} if summary.error else {})
                         | ({"controllers": reports} if reports else {}), indent=2))
    else:
        print(f"{robot.name}: {summary.sim_time:.3f} s simulated in {summary.wall_time:.2f} s "
              f"(real-time factor {summary.rtf:.2f})")
        if summary.error:
            print(f"mexone: {summary.error}", file=sys.stderr)
        else:
            rest = f"yes, since t = {summary.rest_time:.2f} s" if summary.at_rest else "no"
            print(f"base height {summary.base_height:.3f} m, fastest link {summary.max_link_speed:.2f}"
                  f" m/s, at rest: {rest}")
    if lab.manager is not None:  # ros_control stops its controllers at the end; each
        lab.manager.close()  # worker says what its student left running, then ends
    if faults and signals.requested():  # stopped by a signal: its status says so (130/143)
        faults = []
    if faults and not summary.error:
        print(f"mexone: the run went on, but {len(faults)} controller"
              f"{'s' if len(faults) > 1 else ''} stopped on a fault ({', '.join(faults)}): "
              "exit status 1", file=sys.stderr)
    return 1 if summary.diverged or faults else 0
