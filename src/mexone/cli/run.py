"""`mexone run ROUTINE`: run a control routine against the robot headless and report tracking."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from mexone import signals
from mexone.cli.common import (
    DURATION,
    RTF,
    add_model_options,
    add_record_options,
    lab_from_args,
    recording,
)
from mexone.cli.ros import add_ros_options, connect_bridges, urdf_text
from mexone.control.metrics import TrackingRecorder
from mexone.control.worker import end_all as end_workers
from mexone.errors import InputError, RoutineError
from mexone.physics.divergence import DivergenceError
from mexone.physics.monitor import has_fallen
from mexone.routines import supervisor
from mexone.routines.runner import RoutineRunner, parse_param_args, shipped_routines

TRACK_PERIOD = 0.02  # s between samples of the base's pose (for the routine's phases)

HELP = """\
Run a control routine (a Python file using `from mexone import rospy`, or a shipped routine:
joint_steps, arms, home) against the robot with its controllers, headless and as fast as the physics
allows, in lockstep with sim time. Then print per-joint tracking of every position-controlled
joint: RMS and max error (rad), and the worst overshoot and settling time of the moves its
setpoint made, and whether the robot stayed standing (or when it fell: any time in the run,
which lasts its duration even when the routine ends first). A move is a setpoint change, with
the changes in the same direction that came before the joint settled (a staircase the joint
cannot follow step by step is one move): overshoot is a % of the move, settling the time from
its last change to within 2% of it (or 5 mrad); '> T' when the next change (or the run's end)
came T s after it, before the joint settled.

Routine parameters are given ROS-style: `_joint:=r_elbow` sets the routine's ~joint (under
the name its init_node gives, as rosrun; `__name:=n` renames it).

With --ros the robot also joins the ROS 1 graph, as `mexone sim --ros` does, and the run keeps
real time (--rtf): ROS nodes command the routine (walk_cmd_vel follows /<ns>/cmd_vel,
reach_goals the /<ns>/<frame>/goal poses) and see what it publishes (the walk's plan).

The run is a child process in its own process group: whatever the routine starts (a program,
a fork) is stopped when the run ends, and a routine that ends the process itself (os._exit, exec,
a crash) gets one line and exit 1, not a silent 0. sys.exit(0) in a routine ends it as returning
does; sys.exit(n) is its error.

exit status: 0 ok, 1 the routine failed (its exception, sys.exit(n), a thread of its own that
raised, a fork, a program it left running, ending the process) or the simulation diverged,
2 bad input, 130/143 stopped by Ctrl-C/SIGTERM (the report up to then is printed, a --record
bag closed)"""


def add_parser(sub) -> None:
    p = sub.add_parser("run", help="run a control routine and report tracking metrics",
                       description=HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("routine", help="routine file, or one of: " + ", ".join(shipped_routines()))
    p.add_argument("params", nargs="*", metavar="name:=value", help="routine parameters")
    p.add_argument("--duration", type=DURATION, default=None, metavar="S",
                   help="seconds of sim time (default: the routine's ~duration if it sets one, "
                        "else 10); a routine that ends earlier leaves its last commands held "
                        "to the end, so a fall it set off shows; one that fails ends the run")
    p.add_argument("--json", action="store_true",
                   help="print the report as one JSON object on stdout (the routine's log goes "
                        "to stderr)")
    p.add_argument("--quiet", action="store_true", help="do not print the routine's log")
    p.add_argument("--rtf", type=RTF, metavar="R",
                   help="target real-time factor (default: unlimited, or 1 with --ros)")
    add_ros_options(p)
    add_model_options(p)
    add_record_options(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    params = parse_param_args(args.params)
    if supervisor.available():  # the run goes on in a child; this process only supervises it
        status = supervisor.fork_run()
        if status is not None:
            supervisor.leave(status)
            return status
    bridge = connect_bridges(args)
    try:
        status = _run(args, params, bridge)
    finally:
        if bridge is not None:
            bridge.shutdown()
        supervisor.ended()
    end_workers()  # the Python controllers' processes (leave's os._exit skips atexit)
    supervisor.leave(signals.final_status(status))  # the run's process ends here, its report out
    return status


def _run(args: argparse.Namespace, params: dict, bridge) -> int:
    rtf = args.rtf if args.rtf is not None else (1.0 if bridge is not None else 0.0)
    lab = lab_from_args(args, target_rtf=rtf or None)
    if lab.manager is None:
        raise InputError("the robot has no controllers to command",
                         hint="give --controllers YAML (the built-in Mex-One has its own)")
    sim = lab.sim
    start_height = sim.base_height
    start_pose = _base_xy_yaw(sim)
    recorder = TrackingRecorder(sim, lab.manager)
    log_stream = sys.stderr if args.json else sys.stdout  # stdout: the JSON alone, for scripts

    def log(level: str, text: str) -> None:
        if not args.quiet:
            print(f"[{level}] [{sim.time:.3f}]: {text}", file=log_stream)

    runner = RoutineRunner(lab, args.routine, params, log)
    on_tick, tick = None, 0.05
    if bridge is not None:
        bridge.attach(lab, urdf_text(args, sim.robot))
        print(f"mexone: {sim.robot.name} is on {bridge.where()} (namespace {lab.namespace}); "
              "Ctrl-C stops",
              file=sys.stderr)
        for note in bridge.notes():
            print(f"mexone: {note}", file=sys.stderr)
        on_tick, tick = (lambda _sim: bridge.pump()), 0.002  # /clock every 2 ms, as sim --ros
    marks = PhaseMarks(np.array([0.0, *start_pose]))  # the base at the routine's phase bounds
    fell_at: list[float] = []  # when it first fell, if it did: a fall is one even if it gets up

    def watch(s) -> None:
        marks.add(runner.param("phases"), np.array([s.time, *_base_xy_yaw(s)]))
        if not fell_at and has_fallen(s, start_height):
            fell_at.append(s.time)

    sim.add_periodic(TRACK_PERIOD, watch)
    diverged = None
    with recording(lab, args.record, args.force):
        try:
            runner.run(args.duration, on_tick=on_tick, tick=tick, hold=True)
        except RoutineError:
            pass  # runner.error: reported with the run's report below, exit 1
        except DivergenceError as exc:
            diverged = exc.one_line()
            runner.stop()
    tilt, height = sim.base_tilt, sim.base_height
    if not fell_at and has_fallen(sim, start_height):
        fell_at.append(sim.time)
    fell = bool(fell_at)
    metrics = recorder.metrics()
    x, y, yaw = _base_xy_yaw(sim) - start_pose
    phases = _phases(runner.param("phases"), marks)
    report = {
        "routine": str(Path(runner.path).stem), "sim_time": round(sim.time, 6),
        "fell": fell, "fell_at": round(fell_at[0], 3) if fell else None,
        "base_height": round(height, 6), "tilt": round(tilt, 6),
        "error": runner.error or diverged,
        "notices": runner.notices,
        # where the base went (walking): along and across its starting heading, turn in degrees
        "distance_x": round(float(x * np.cos(start_pose[2]) + y * np.sin(start_pose[2])), 4),
        "drift_y": round(float(-x * np.sin(start_pose[2]) + y * np.cos(start_pose[2])), 4),
        "yaw": round(float(np.degrees((yaw + np.pi) % (2 * np.pi) - np.pi)), 2),
        # a routine's phases (walk: its course's legs): the first's speed, else the average
        "speed": phases[0]["speed"] if phases else
        (round(float(np.hypot(x, y) / sim.time), 4) if sim.time > 0 else 0.0),
        "phases": phases,
        "joints": {name: m.as_json() for name, m in sorted(metrics.items())},
    }
    if args.quiet:  # echoed with the routine's log otherwise
        for notice in runner.notices:
            print(f"mexone: warning: {notice}", file=sys.stderr)
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        _print_table(metrics)
        for p in phases:
            print(f"{p['leg']:<10} {p['seconds']:6.2f} s: {p['distance_x']:+.3f} m ahead, "
                  f"{p['drift_y']:+.3f} m aside, turned {p['yaw']:+.1f} deg, {p['speed']:.3f} m/s")
        verdict = f"fell over at {fell_at[0]:.2f} s" if fell else "stayed standing"
        print(f"{verdict}: base height {height:.3f} m, tilt {np.degrees(tilt):.1f} deg after "
              f"{sim.time:.2f} s")
        if runner.error:
            print(runner.error, file=sys.stderr)
        if diverged:
            print(f"mexone: {diverged}", file=sys.stderr)
    return 1 if runner.error or diverged else 0


def _bounds(declared) -> list[tuple[str, float, float]]:
    """The well-formed [name, start s, end s] items of a routine's ~phases parameter."""
    if not isinstance(declared, list):
        return []
    out = []
    for item in declared:
        if not (isinstance(item, list | tuple) and len(item) == 3):
            continue
        name, start, end = item
        if isinstance(start, int | float) and isinstance(end, int | float) and end > start:
            out.append((name, start, end))
    return out


class PhaseMarks:
    """The base's samples (t, x, y, yaw) nearest each start and end time the routine's ~phases
    declare, kept as the run goes rather than every sample (a long run's track grew without
    bound). A time is matched among the samples from when it was first declared (the shipped
    walks declare their legs before walking them)."""

    def __init__(self, first: np.ndarray):
        self.first, self.last = first, first
        self.best: dict[float, np.ndarray] = {}

    def add(self, declared, sample: np.ndarray) -> None:
        for _, start, end in _bounds(declared):
            for when in (start, end):
                best = self.best.setdefault(when, self.first)
                if abs(sample[0] - when) < abs(best[0] - when):  # the first of equals, as argmin
                    self.best[when] = sample
        self.last = sample

    def nearest(self, when: float) -> np.ndarray:
        return self.best.get(when, self.first)


def _phases(declared, marks: PhaseMarks) -> list[dict]:
    """Where the base went in each phase a routine declared in its ~phases parameter
    ([[name, start s, end s], ...]): along and across its heading at the phase's start."""
    if marks.last is marks.first:
        return []
    out = []
    for name, start, end in _bounds(declared):
        if start > marks.last[0]:
            break  # the run ended first
        a, b = marks.nearest(start), marks.nearest(end)
        dx, dy = b[1:3] - a[1:3]
        c, s = np.cos(a[3]), np.sin(a[3])
        turn = (b[3] - a[3] + np.pi) % (2 * np.pi) - np.pi
        seconds = float(b[0] - a[0])
        out.append({"leg": str(name), "start": round(float(a[0]), 3), "seconds": round(seconds, 3),
                    "distance_x": round(float(c * dx + s * dy), 4),
                    "drift_y": round(float(-s * dx + c * dy), 4),
                    "yaw": round(float(np.degrees(turn)), 2),
                    "speed": round(float(np.hypot(dx, dy) / seconds), 4) if seconds > 0 else 0.0})
    return out


def _base_xy_yaw(sim) -> np.ndarray:
    """The base's ground position and heading (rad)."""
    rot = sim.data.xmat[sim.compiled.root_body].reshape(3, 3)
    x, y = sim.data.xpos[sim.compiled.root_body][:2]
    return np.array([x, y, np.arctan2(rot[1, 0], rot[0, 0])])


def _print_table(metrics) -> None:
    moving = {k: m for k, m in metrics.items() if m.steps}
    shown = moving or metrics
    print(f"{'joint':<18} {'RMS err':>9} {'max err':>9} {'steps':>6} {'moves':>6} "
          f"{'overshoot':>10} {'settling':>10}")
    for name, m in sorted(shown.items()):
        print(f"{name:<18} {m.rms_error:9.4f} {m.max_error:9.4f} {m.steps:6d} {m.moves:6d} "
              f"{m.overshoot * 100:9.1f}% {m.settling_text:>10}")
    if moving and len(moving) < len(metrics):
        print(f"({len(metrics) - len(moving)} more joints held still; --json lists all)")
    if moving:
        print("(errors in rad; a move: a setpoint step, or the steps in one direction that came "
              "before the joint settled; overshoot: % of the move; settling: from its last step "
              "to within 2% or 5 mrad, '> T': the next step came T s after, unsettled)")
