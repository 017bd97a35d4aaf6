"""What a grader runs inside the isolated child: a lab with the hidden variation applied, the
student's routine or controller YAML, and a report of plain numbers (picklable) back."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from mexone.errors import MexoneError, RoutineError
from mexone.lab import Lab
from mexone.physics.divergence import DivergenceError
from mexone.physics.monitor import has_fallen

__all__ = ["Variation", "simulate", "Run"]

SAMPLE_PERIOD = 0.005  # s between samples of the joints and the base


@dataclass(frozen=True)
class Variation:
    """The hidden model variant a grader draws from its secret seed: scales on every link's
    mass (and inertia), every joint's damping and every contact's sliding friction."""

    mass: float = 1.0
    damping: float = 1.0
    friction: float = 1.0

    def edit(self, spec: mujoco.MjSpec, _robot) -> None:
        """A SpecEdit: applied to the MuJoCo spec before it compiles."""
        for body in spec.bodies:
            if body.mass > 0:
                body.mass *= self.mass
                body.inertia = np.asarray(body.inertia) * self.mass
        for joint in spec.joints:
            joint.damping = np.asarray(joint.damping) * self.damping if np.ndim(joint.damping) \
                else joint.damping * self.damping
        for geom in spec.geoms:
            friction = np.array(geom.friction, dtype=float)
            friction[0] *= self.friction
            geom.friction = friction


@dataclass
class Run:
    """What one graded run measured (plain data: it crosses the process boundary)."""

    t: np.ndarray  # sample times, s
    joints: list[str]
    setpoint: np.ndarray  # (samples, joints), rad
    position: np.ndarray  # (samples, joints), rad
    base_height: np.ndarray  # (samples,), m
    tilt: np.ndarray  # (samples,), rad
    fell_at: float | None
    error: str | None  # the routine's error (its last line), None if it ran cleanly
    sim_time: float

    def joint(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """(setpoint, position) of one joint over the run."""
        k = self.joints.index(name)
        return self.setpoint[:, k], self.position[:, k]


def simulate(duration: float, routine: str | Path | None = None,
             controllers: str | Path | None = None, model: str | Path | None = None,
             variation: Variation = Variation(), params: dict | None = None,
             raise_routine_errors: bool = True, own_process: bool | None = None) -> Run:
    """Build the lab (the built-in Mex-One unless `model`; its controllers unless
    `controllers`), apply `variation`, run `routine` (a routine file or shipped name) for
    `duration` s of sim time (held to the end if it returns first), and sample every
    position-controlled joint and the base. Call it through GradeContext.run: in the child.

    own_process: the routine runs in a process of its own (routines.isolated: no lab, no model,
    the child's CPU and memory limits), talking to this one through mexone.rospy only; default:
    every routine but mexone's shipped ones (which need the lab's model)."""
    try:
        lab = Lab.create(model=model, controllers=controllers, edits=[variation.edit])
    except MexoneError as exc:
        raise _failed(exc.one_line()) from None
    sim = lab.sim
    start = sim.base_height
    rows: list[tuple] = []
    names: list[str] = []
    ctrls: list = []
    if lab.manager is not None:  # the joints TrackingRecorder follows
        ctrls = [c for c in lab.manager.controllers.values()
                 if c.running and c.tracks_position]
        names = [j for c in ctrls for j in c.joints]
    fell: list[float] = []

    def sample(s) -> None:
        sp, q = [], []
        for c in ctrls:
            sp.extend(float(v) for v in c.setpoint)
            q.extend(float(v) for v in c.hw.position(c.rows))
        rows.append((s.time, s.base_height, s.base_tilt, sp, q))
        if not fell and has_fallen(s, start):
            fell.append(s.time)

    sim.add_periodic(SAMPLE_PERIOD, sample)
    error = None
    try:
        if routine is not None:
            from mexone.routines.runner import RoutineRunner, shipped_routines

            if own_process is None:
                own_process = str(routine) not in shipped_routines()
            if own_process:
                from mexone.exercises.isolate import active_limits
                from mexone.routines.isolated import IsolatedRoutineRunner

                limits = active_limits()
                runner = IsolatedRoutineRunner(lab, routine, params or {}, cpu=limits.cpu,
                                               memory_mb=limits.memory_mb)
            else:
                runner = RoutineRunner(lab, routine, params or {})
            runner.run(duration, hold=True)
        else:
            sim.run(duration)
    except RoutineError as exc:
        error = exc.one_line()
        if raise_routine_errors:
            raise _failed(f"the routine failed: {error}") from None
    except DivergenceError as exc:
        error = exc.one_line()
    t = np.array([r[0] for r in rows])
    return Run(t, names, np.array([r[3] for r in rows]).reshape(len(rows), len(names)),
               np.array([r[4] for r in rows]).reshape(len(rows), len(names)),
               np.array([r[1] for r in rows]), np.array([r[2] for r in rows]),
               fell[0] if fell else None, error, float(sim.time))


def _failed(reason: str):
    from mexone.exercises.isolate import SubmissionFailed

    return SubmissionFailed(reason)
