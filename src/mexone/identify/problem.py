"""The identification as a `mujoco.sysid` problem, and its solution.

The unknowns are `sysid.Parameter`s (bounds, scaled values, spec modifiers); `sysid.optimize`
fits them with MuJoCo's bounded Levenberg-Marquardt and finite-difference Jacobians;
`sysid.calculate_intervals` turns the Jacobian at the optimum into 95% intervals. The residual --
simulated minus recorded joint position (rad) at every recorded sample of every bag -- has
sysid's signature but is ours: sysid's own (`sysid.residual`) maps one control to each actuator,
and mexone's motors take three (setpoint, velocity reference, feed-forward: MuJoCo 4 ctrlspec).

A candidate is simulated by `mujoco.rollout` in chunks of time: a 63-parameter Jacobian of a 20 s
bag is 64 rollouts of 20 000 steps, whose whole state arrays would take 1.5 GB; per chunk only
the sensor rows around the recorded samples are kept. A robot on a stand and a standing one are
different models of the same robot: each bag keeps its own, all fitted together.
"""

from __future__ import annotations

import logging
import math
import os
import time
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass, field, replace

import mujoco
import numpy as np
from mujoco import rollout as mj_rollout
from mujoco import sysid

from mexone import signals
from mexone.identify.parameters import Unknown, apply_to_model, parameter_dict
from mexone.identify.replay import SENSOR_SUFFIX, Experiment

__all__ = ["Problem", "Fit", "Progress", "Prediction", "FD_STEP", "CHUNK_STEPS",
           "MAX_ITERATIONS"]

FD_STEP = 1e-4  # finite-difference step in scaled units (1e-4 of a typical value): well above
# the constraint solver's tolerance, well below any change that matters
CHUNK_STEPS = 1000  # steps per rollout call: bounds memory, keeps Ctrl-C responsive
MAX_ITERATIONS = 30
X_TOLERANCE = 1e-5  # relative step at which the fit stops


@dataclass
class Progress:
    """What the optimiser reports as it goes (for a progress bar)."""

    iteration: int = 0
    evaluations: int = 0
    rollouts: int = 0
    best_rms: float = math.inf
    start_rms: float = math.inf


@dataclass
class Fit:
    unknowns: list[Unknown]
    nominal: np.ndarray  # physical units
    values: np.ndarray
    halfwidth: np.ndarray | None  # 95% interval half-widths; None if not computed
    correlation: np.ndarray | None
    iterations: int
    evaluations: int
    seconds: float
    interrupted: bool = False
    scaled: np.ndarray = field(default_factory=lambda: np.zeros(0))  # the optimiser's values

    def value(self, name: str) -> float:
        return float(self.values[[u.name for u in self.unknowns].index(name)])


@dataclass
class Prediction:
    """One experiment simulated with one set of values: positions at the recorded samples."""

    experiment: Experiment
    q: np.ndarray  # like experiment.measured

    @property
    def error(self) -> np.ndarray:
        return self.q - self.experiment.measured

    def rms(self) -> float:
        return float(np.sqrt(np.nanmean(self.error**2)))

    def rms_per_joint(self) -> dict[str, float]:
        e = self.error
        return {j: float(np.sqrt(np.nanmean(e[:, i] ** 2)))
                for i, j in enumerate(self.experiment.joints)}


class _Discard:
    def write(self, _text: str) -> int:
        return 0

    def flush(self) -> None:
        pass


@contextmanager
def _quiet_absl():
    """sysid logs through absl (a warning for a parameter starting at its bound, a comparison
    table); mexone reports for itself."""
    logger = logging.getLogger("absl")
    level = logger.level
    logger.setLevel(logging.ERROR)
    try:
        yield
    finally:
        logger.setLevel(level)


@dataclass
class Problem:
    experiments: list[Experiment]
    unknowns: list[Unknown]
    threads: int = field(default_factory=lambda: os.cpu_count() or 1)
    on_progress: Callable[[Progress], None] | None = None
    progress: Progress = field(default_factory=Progress)

    def __post_init__(self) -> None:
        self.params = parameter_dict(self.unknowns)
        self._threads = max(1, self.threads)
        self._pool = mj_rollout.Rollout(nthread=self._threads if self._threads > 1 else 0)
        self._best: tuple[float, np.ndarray] = (math.inf, self.params.as_vector())
        self._fitting = False  # solve() is running: signals stop it (_stop_point)
        self.groups = independent_groups(self.experiments, self.unknowns)
        names = [e.name for e in self.experiments]
        self._delay = {names.index(u.target): u for u in self.unknowns
                       if u.nuisance and u.target in names}

    def delays(self, params: sysid.ParameterDict, experiments: list[Experiment]) -> list[float]:
        """Each experiment's command delay (s): fitted, or 0 for a held-out bag."""
        out = []
        for e in experiments:
            index = next((i for i, f in enumerate(self.experiments) if f is e), None)
            u = self._delay.get(index) if index is not None else None
            out.append(float(params[u.name].value[0]) * u.scale if u is not None else 0.0)
        return out

    def close(self) -> None:
        self._pool.close()

    # ----- the residual, with sysid's signature ------------------------------------------------
    def models(self, params: sysid.ParameterDict,
               experiments: list[Experiment] | None = None) -> list[mujoco.MjModel]:
        """Each experiment's model with the values in params: the spec edited by the parameters'
        modifiers, compiled, the controllers' gains restored, then the model-side unknowns."""
        out = []
        for e in experiments or self.experiments:
            model = e.compile(sysid.apply_param_modifiers_spec(params, e.spec))
            apply_to_model(self.unknowns, params, model)
            out.append(model)
        return out

    def residual(self, x: np.ndarray, params: sysid.ParameterDict):
        """x: one point (n,) or finite-difference columns (n, k); returns sysid's triple with one
        residual per experiment, (samples,) or (samples, k)."""
        columns = np.asarray(x, dtype=float).reshape(len(x), -1)
        per_column, delays = [], []
        for c in range(columns.shape[1]):
            self._stop_point()  # compiling a Jacobian's dozens of models takes seconds
            params.update_from_vector(columns[:, c])
            per_column.append(self.models(params))
            delays.append(self.delays(params, self.experiments))
        residuals = []
        for i, e in enumerate(self.experiments):
            q = self.simulate(e, [models[i] for models in per_column],
                              np.array([d[i] for d in delays]))
            mask = np.isfinite(e.measured)
            r = np.stack([(qc - np.nan_to_num(e.measured))[mask] for qc in q], axis=1)
            residuals.append(r[:, 0] if np.ndim(x) == 1 else r)
        return residuals, None, None

    # ----- simulation -------------------------------------------------------------------------
    def simulate(self, experiment: Experiment, models: list[mujoco.MjModel],
                 delays: np.ndarray | None = None) -> np.ndarray:
        """Every model rolled out on the experiment's controls (each delayed by its `delays`, s):
        joint positions at the recorded sample times, shape (len(models), samples, joints).
        Sensor row k is the position at k * timestep (MuJoCo computes sensors before it
        integrates)."""
        e = experiment
        delays = np.zeros(len(models)) if delays is None else np.asarray(delays, dtype=float)
        datas = [mujoco.MjData(models[0]) for _ in range(self._threads)]
        columns = np.array([models[0].sensor(j + SENSOR_SUFFIX).adr[0] for j in e.joints])
        u = e.times / e.timestep
        lo = np.clip(np.floor(u).astype(int), 0, e.steps - 2)
        hi = lo + 1
        frac = (u - lo)[None, :, None]
        out = np.empty((len(models), len(e.times), len(e.joints)))
        state = np.tile(e.initial_state, (len(models), 1))
        previous = None  # the sensor row of the step before the chunk
        for start in range(0, e.steps, CHUNK_STEPS):
            self._stop_point()
            stop = min(start + CHUNK_STEPS, e.steps)
            states, sensed = self._pool.rollout(models, datas, state,
                                                _delayed(e.ctrl, start, stop, delays / e.timestep))
            sensed = sensed[:, :, columns]
            rows = sensed if previous is None else np.concatenate([previous[:, None], sensed], 1)
            offset = start if previous is None else start - 1  # the step rows[:, 0] holds
            pick = (hi >= start) & (hi < stop)  # then lo = hi - 1 >= offset (hi >= 1 always)
            if pick.any():
                a, b = rows[:, lo[pick] - offset], rows[:, hi[pick] - offset]
                out[:, pick] = a + (b - a) * frac[:, pick]
            previous, state = sensed[:, -1], states[:, -1]
            self.progress.rollouts += len(models)
        return out

    def predict(self, experiments: list[Experiment], scaled: np.ndarray) -> list[Prediction]:
        """Experiments (fitted or held out) simulated with these scaled values."""
        params = self.params.copy()
        params.update_from_vector(np.asarray(scaled, dtype=float))
        models = self.models(params, experiments)
        delays = self.delays(params, experiments)
        return [Prediction(e, self.simulate(e, [m], np.array([d]))[0])
                for e, m, d in zip(experiments, models, delays, strict=True)]

    # ----- the Jacobian ---------------------------------------------------------------------
    def jacobian(self, x: np.ndarray, r: np.ndarray) -> np.ndarray:
        """Forward differences as `mujoco.minimize.jacobian_fd` takes them (step FD_STEP, away
        from the nearer bound), but one rollout perturbs one unknown of every independent group
        at once: on a stand, a leg's joints cannot move the other leg or the arms, so the rows
        of each group's joints tell its unknown's column apart. Mex-One on a stand: 27 rollouts
        per Jacobian instead of 63."""
        x = np.asarray(x, dtype=float).reshape(-1)
        r = np.asarray(r, dtype=float).reshape(-1)
        lower, upper = self.params.get_bounds()
        step = np.where(x > 0.5 * (lower + upper), -FD_STEP, FD_STEP) * np.maximum(1.0, np.abs(x))
        step = np.clip(x + step, lower, upper) - x
        unknown_group, row_group = self.groups
        members = [np.flatnonzero(unknown_group == g) for g in np.unique(unknown_group) if g >= 0]
        width = max((len(m) for m in members), default=0)
        alone = np.flatnonzero(unknown_group < 0)  # moves every row (a bag's delay): own column
        columns = np.tile(x[:, None], (1, width + len(alone)))
        for m in members:
            columns[m, np.arange(len(m))] += step[m]
        columns[alone, width + np.arange(len(alone))] += step[alone]
        residuals, _, _ = self._tracked(columns, self.params.copy())
        delta = np.concatenate(residuals) - r[:, None]
        jac = np.zeros((r.size, x.size))
        for m in members:
            for c, i in enumerate(m):
                rows = row_group == unknown_group[i]
                jac[rows, i] = delta[rows, c] / step[i]
        for c, i in enumerate(alone):
            jac[:, i] = delta[:, width + c] / step[i]
        return jac

    # ----- fitting ----------------------------------------------------------------------------
    def _stop_point(self) -> None:
        """While fitting, a signal (Ctrl-C, SIGTERM) stops the fit here: signals.Stop, a
        KeyboardInterrupt raised by this code between two rollout chunks or model compilations,
        which solve() turns into the best point so far. Predictions after the fit run on."""
        if self._fitting:
            signals.check()

    def _tracked(self, x, params):
        """The residual, remembering the best single point evaluated (Ctrl-C keeps it)."""
        result = self.residual(x, params)
        p = self.progress
        p.evaluations += 1
        if np.ndim(x) == 1 or np.shape(x)[1] == 1:  # one point (the optimiser passes (n, 1))
            r = np.concatenate(result[0])
            rms = float(np.sqrt(np.mean(r**2))) if r.size else 0.0
            if not math.isfinite(p.start_rms):
                p.start_rms = rms
            if rms < self._best[0]:
                self._best = (rms, np.array(x, dtype=float).reshape(-1))  # (n,) or (n, 1)
                p.best_rms = rms
        if self.on_progress:
            self.on_progress(p)
        return result

    def _on_iteration(self, trace) -> None:
        """sysid's mujoco backend keeps every iteration's Jacobian; only the last is needed."""
        for i, log in enumerate(trace[:-1]):
            if log.jacobian is not None:
                trace[i] = replace(log, jacobian=None, residual=None)
        self.progress.iteration = len(trace)
        if self.on_progress:
            self.on_progress(self.progress)

    def solve(self, max_iterations: int = MAX_ITERATIONS, intervals: bool = True) -> Fit:
        """Fit; Ctrl-C returns the best point evaluated so far (without intervals)."""
        start = time.perf_counter()
        x0 = self.params.as_vector()
        interrupted, jac = False, None
        with _quiet_absl():
            try:
                self._fitting = True
                fitted, result = sysid.optimize(
                    self.params, self._tracked, optimizer="mujoco", verbose=False,
                    max_iters=max_iterations, eps=FD_STEP, xtol=X_TOLERANCE,
                    jacobian=self.jacobian if self.groups is not None else None,
                    iter_callback=self._on_iteration, output=_Discard())
                x = fitted.as_vector()  # the last accepted step, the best point evaluated
                jac = result.jac
            except KeyboardInterrupt:
                interrupted, x = True, np.asarray(self._best[1], dtype=float).reshape(-1)
            finally:
                self._fitting = False
        halfwidth = correlation = None
        scale = np.array([u.scale for u in self.unknowns])
        if intervals and not interrupted and jac is not None and x.size:
            residuals, _, _ = self.residual(x, self.params.copy())
            covariance, half = sysid.calculate_intervals(residuals, np.asarray(jac))
            halfwidth = half * scale
            sd = np.sqrt(np.clip(np.diag(covariance), 1e-300, None))
            correlation = covariance / np.outer(sd, sd)
        return Fit(self.unknowns, x0 * scale, np.asarray(x) * scale, halfwidth, correlation,
                   self.progress.iteration, self.progress.evaluations,
                   time.perf_counter() - start, interrupted, np.asarray(x, dtype=float))


def _delayed(ctrl: np.ndarray, start: int, stop: int, shift: np.ndarray) -> np.ndarray:
    """Rows start..stop of ctrl as each model sees it, `shift` steps later (fractional: linear
    between rows, so the residual is smooth in the delay), shape (len(shift), stop - start, nu).
    Before the first row the first row holds (the controllers held the start pose)."""
    if not np.any(shift):
        return ctrl[None, start:stop]
    u = np.arange(start, stop)[None, :] - shift[:, None]
    lo = np.floor(u).astype(int)
    frac = (u - lo)[:, :, None]
    a = ctrl[np.clip(lo, 0, len(ctrl) - 1)]
    b = ctrl[np.clip(lo + 1, 0, len(ctrl) - 1)]
    return a + (b - a) * frac


def independent_groups(experiments: list[Experiment], unknowns: list[Unknown]
                       ) -> tuple[np.ndarray, np.ndarray] | None:
    """(group of each unknown, group of each residual row) when every bag was recorded on a
    stand: a group is one subtree hanging from the welded base, whose motion no other subtree
    can change (while they do not touch). None when any bag had a free base: then everything
    moves everything. Rows and columns in the order of `Problem.residual`; a bag's delay moves
    every joint: group -1."""
    if not experiments or not all(e.fixed_base for e in experiments):
        return None
    model = experiments[0].model
    base = int(model.body(experiments[0].base_link).id)

    def group_of_body(body: int) -> int:
        while model.body_parentid[body] not in (base, 0) and body != base:
            body = int(model.body_parentid[body])
        return body

    def group_of_joint(joint: str) -> int:
        return group_of_body(int(model.jnt_bodyid[model.joint(joint).id]))

    unknown_group = np.array([-1 if u.nuisance else group_of_body(int(model.body(u.target).id))
                              if u.kind in ("mass", "com") else group_of_joint(u.target)
                              for u in unknowns])
    rows = []
    for e in experiments:
        _, column = np.nonzero(np.isfinite(e.measured))
        joint_group = np.array([group_of_joint(j) for j in e.joints])
        rows.append(joint_group[column])
    return unknown_group, np.concatenate(rows)
