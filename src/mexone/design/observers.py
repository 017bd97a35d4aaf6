"""Observers the lab runs (issue 38 item 2): a Kalman filter (steady-state or time-varying) and a
Luenberger observer on the robot's measured signals, deployed as controllers whose estimate is a
state interface other controllers read (chained controllers), and `lqg`, the observer and a
state feedback deployed as one controller.

Designs come from a plant `linearize` made with the sensors among its outputs
(`linearize(lab, point=..., outputs=["imu/gyro", "imu/acc", "pose:l_foot", "pose:torso"])`).
The measured signals, by name:

`<imu>/gyro`, `<imu>/acc`
    an IMU's angular velocity and proper acceleration (its frame), as controllers read them
    (`state.sensors["<imu>"]`, the sensor's noise included);
`<joint>:q`, `<joint>:dq`, `encoders`
    a joint's encoder (angle), its velocity; every joint's angle;
`pose:<frame>`
    a frame that does not move, a foot flat on the ground (leg odometry): it reads the point's
    pose, so the base's position, which nothing else measures, is observable.

The estimator runs in filter form at its own rate: x- = A x+ + B u (u: the torques the motors
applied over the last period, measured), then x+ = x- + M (y - y0 - C x- - D u), with M the
steady-state Kalman gain (`control.dlqe`'s Riccati solution), the time-varying one (the Riccati
recursion, every update) or a Luenberger gain (`control.place` on A - M C A). The estimate x+
is exported at once: a reader updated in the same cycle acts on it (no delay).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import control
import mujoco
import numpy as np

from mexone.control.hardware import set_actuator_state
from mexone.design.check import _run
from mexone.design.deploy import _Deployed, _design_path, _new_npz, _Point, _point_of, lqr
from mexone.errors import InputError
from mexone.files import replacing
from mexone.ranges import number_text

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure, SubFigure
    from numpy.typing import ArrayLike

    from mexone.control.student import State
    from mexone.lab import Lab
    from mexone.physics.simulation import Periodic, Simulation

__all__ = ["Estimator", "kalman", "luenberger", "lqg", "Observer", "Lqg", "LqgDesign",
           "EstimateRun", "compare_estimate", "plot_estimate", "save_estimator",
           "load_estimator", "rows_of"]

_IMU_FIELDS = {"gyro": "angular_velocity", "acc": "linear_acceleration"}


@dataclass(frozen=True)
class Estimator:
    """An observer's design: the plant (A, B, C, D at `period`), the measured signals (`labels`,
    one per row of C, grouped as `measured` names them; `y0` their values at the point), the
    gain M (filter form; None: time-varying, from `process` and `noise` covariances and `P0`),
    the `outputs` it exports (name -> rows on the state), and the plant's inputs and point."""

    kind: str  # "kalman" or "luenberger"
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    period: float
    measured: tuple[str, ...]
    labels: tuple[str, ...]
    y0: np.ndarray
    gain: np.ndarray | None
    process: np.ndarray | None
    noise: np.ndarray | None
    P0: np.ndarray | None
    outputs: dict[str, np.ndarray]
    inputs: tuple[str, ...]
    u0: np.ndarray
    point: _Point
    states: tuple[str, ...]
    joints: tuple[str, ...] = ()  # an observer drives no joint
    interface: str = "effort"

    @property
    def dt(self) -> float:
        """The estimator's sample period (s), as python-control names it."""
        return self.period

    @property
    def time_varying(self) -> bool:
        """Whether the gain is recomputed each step (a time-varying Kalman filter)."""
        return self.gain is None

    def initial(self) -> tuple[np.ndarray, np.ndarray | None]:
        """The estimate at the point, and its covariance (time-varying)."""
        n = self.A.shape[0]
        return np.zeros(n), None if self.P0 is None else self.P0.copy()

    def step(self, x: np.ndarray, P: np.ndarray | None, y: np.ndarray, u: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray | None]:
        """One update: the prior from the last estimate and the applied input u (deviation),
        then the correction by the measurement y (deviation from y0)."""
        prior = self.A @ x + self.B @ u
        innovation = y - self.C @ prior - self.D @ u
        if self.gain is not None:
            return prior + self.gain @ innovation, None
        assert P is not None and self.process is not None and self.noise is not None  # time-varying
        P = self.A @ P @ self.A.T + self.process
        S = self.C @ P @ self.C.T + self.noise
        M = np.linalg.solve(S, self.C @ P).T
        P = P - M @ self.C @ P
        return prior + M @ innovation, 0.5 * (P + P.T)

    def deployed(self, rate: float | None) -> tuple[type[Observer], Estimator, float, dict[str, int]]:
        """deploy's hook: (controller class, design, rate, exports)."""
        return Observer, self, _rate(self, rate), {k: v.shape[0] for k, v in self.outputs.items()}


@dataclass(frozen=True)
class LqgDesign:
    """An LQG compensator: the state feedback `K` (u = u0 - K x+) on the estimate of
    `estimator`, deployed as one controller on the plant's input joints."""

    K: np.ndarray
    estimator: Estimator
    joints: tuple[str, ...]
    interface: str
    u0: np.ndarray

    @property
    def dt(self) -> float:
        """The LQG's sample period (s): its estimator's."""
        return self.estimator.period

    @property
    def point(self) -> _Point:
        """The operating point the LQG was designed at: its estimator's."""
        return self.estimator.point

    def deployed(self, rate: float | None) -> tuple[type[Lqg], LqgDesign, float, dict[str, int]]:
        """(controller class, design, rate, exports) for `deploy`: the LQG as one chained controller."""
        est = self.estimator
        return Lqg, self, _rate(est, rate), {k: v.shape[0] for k, v in est.outputs.items()}


def _rate(est: Estimator, rate: float | None) -> float:
    if rate is None:
        return 1.0 / est.period
    if abs(rate * est.period - 1.0) > 1e-6:
        raise InputError(f"the estimator's model has a period of {number_text(est.period)} s; "
                         f"rate {number_text(rate)} Hz runs it at {number_text(1 / rate)} s",
                         hint=f"rate={number_text(1 / est.period)}, or linearize at period=1/rate")
    return float(rate)


# ----- the measurement model --------------------------------------------------------------------
def rows_of(plant: control.StateSpace, labels: Sequence[str], rate: bool = False) -> np.ndarray:
    """Rows on the plant's state for some of its outputs or states (by label); rate=True: their
    time derivative, for outputs that are positions (a frame's pose, the centre of mass: C is
    [J, 0], the rate is [0, J])."""
    c = np.asarray(plant.C)
    outs, states = list(plant.output_labels), list(plant.state_labels)
    nv = plant.linearization.qvel.size
    rows = []
    for label in labels:
        if label in outs:
            row = c[outs.index(label)].copy()
        elif label in states:
            row = np.zeros(plant.nstates)
            row[states.index(label)] = 1.0
        else:
            raise InputError(f"{label!r} is neither an output nor a state of the plant",
                             hint="outputs: " + ", ".join(outs[:10]))
        if rate:
            if np.abs(row[nv:]).max(initial=0.0) > 0:
                raise InputError(f"{label!r} is not a position: it has no rate in this model")
            row = np.r_[np.zeros(nv), row[:nv], row[2 * nv:]]
        rows.append(row)
    return np.array(rows)


def _measurement(plant: control.StateSpace, measured: Sequence[str]
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[str, ...],
                            tuple[tuple[str, str], ...]]:
    """(C, D, y0, labels, groups) of the measured signals (see the module's docstring)."""
    if isinstance(measured, str) or not measured:
        raise InputError("measured: give a list of signals (e.g. ['imu/gyro', 'imu/acc', "
                         "'encoders'])")
    lin = getattr(plant, "linearization", None)
    if lin is None:
        raise InputError("the plant is not a StateSpace made by mexone.design.linearize")
    outs, states = list(plant.output_labels), list(plant.state_labels)
    c_all, d_all = np.asarray(plant.C), np.asarray(plant.D)
    nv = lin.qvel.size
    rows_c: list[np.ndarray] = []
    rows_d: list[np.ndarray] = []
    y0: list[float] = []
    labels: list[str] = []
    groups: list[tuple[str, str]] = []
    sensed: Callable[[str, str], float] | None = None
    for name in measured:
        if name == "encoders":
            picked = [s for s in states[6 if states[0].startswith("base:") else 0:nv] if s.endswith(":q")]
            expanded = picked
        elif name.startswith("pose:"):
            frame = name[len("pose:"):]
            expanded = [f"{frame}:{a}" for a in ("x", "y", "z", "rx", "ry", "rz")]
        else:
            expanded = [name]
        for label in expanded:
            if label in states and label.endswith((":q", ":dq")):
                row = np.zeros(plant.nstates)
                i = states.index(label)
                row[i] = 1.0
                rows_c.append(row)
                rows_d.append(np.zeros(plant.ninputs))
                if label.endswith(":dq"):
                    value = lin.qvel[i - nv]
                else:
                    model = lin.source
                    joint = model.joint(label.rpartition(":")[0])
                    value = lin.qpos[_qpos_of(lin, int(model.jnt_qposadr[joint.id]))]
                y0.append(float(value))
                labels.append(label)
                groups.append(("state", label))
                continue
            prefix = label.replace(".", "_")
            picked = [o for o in outs if o == prefix or o.startswith(prefix + ":")]
            if not picked:
                raise InputError(f"measured signal {name!r} is not among the plant's outputs or "
                                 "states", hint="linearize with outputs=[...] naming it "
                                 "(outputs: " + ", ".join(outs[:8]) + ")")
            if sensed is None:
                sensed = _sensor_values(lin)
            for out in picked:
                i = outs.index(out)
                rows_c.append(c_all[i])
                rows_d.append(d_all[i])
                labels.append(out)
                if name.startswith("pose:"):
                    y0.append(0.0)
                    groups.append(("still", out))
                else:
                    sensor, _, axis = out.partition(":")
                    y0.append(sensed(sensor, axis))
                    groups.append(("imu", out))
    return (np.array(rows_c), np.array(rows_d), np.array(y0), tuple(labels), tuple(groups))


def _qpos_of(lin: Any, full_adr: int) -> int:  # lin: design.linear's Linearization
    index = np.asarray(lin.qpos_index)
    hit = np.flatnonzero(index == full_adr)
    return int(hit[0]) if hit.size else full_adr


def _sensor_values(lin: Any) -> Callable[[str, str], float]:  # lin: a Linearization
    """sensor name, axis -> its value at the point (the model as linearised, at rest)."""
    model = lin.model
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = lin.qpos, lin.qvel
    set_actuator_state(data, act=lin.act)
    if lin.ctrl is not None and lin.ctrl.shape == data.ctrl.shape:
        set_actuator_state(data, ctrl=lin.ctrl)
    flags = model.opt.disableflags
    model.opt.disableflags = flags & ~int(mujoco.mjtDisableBit.mjDSBL_SENSOR)
    try:
        mujoco.mj_forward(model, data)
    finally:
        model.opt.disableflags = flags

    def value(sensor: str, axis: str) -> float:
        sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, sensor)
        if sid < 0:
            raise InputError(f"no sensor {sensor!r} in the model")
        adr, dim = int(model.sensor_adr[sid]), int(model.sensor_dim[sid])
        k = 0 if dim == 1 else ("wxyz" if dim == 4 else "xyz").index(axis)
        return float(data.sensordata[adr + k])
    return value


def _outputs(plant: control.StateSpace, exports: Mapping[str, np.ndarray] | None) -> dict[str, np.ndarray]:
    if exports is None:
        return {"x": np.eye(plant.nstates)}
    out: dict[str, np.ndarray] = {}
    for name, rows in exports.items():
        rows = np.atleast_2d(np.asarray(rows, dtype=float))
        if not str(name).isidentifier():
            raise InputError(f"export {name!r} is not a name (letters, digits, _)")
        if rows.shape[1] != plant.nstates:
            raise InputError(f"export {name!r} has {rows.shape[1]} columns; the plant has "
                             f"{plant.nstates} states", hint="build its rows with rows_of(plant, ...)")
        out[str(name)] = rows
    return out


def _covariance(value: ArrayLike, n: int, what: str) -> np.ndarray:
    m = np.atleast_1d(np.asarray(value, dtype=float))
    if m.ndim == 1:
        m = np.diag(np.broadcast_to(m, (n,)) if m.size in (1, n) else m)
    if m.shape != (n, n):
        raise InputError(f"{what} has shape {m.shape}; it needs ({n}, {n}) (or {n} variances)")
    if not np.all(np.isfinite(m)) or not np.allclose(m, m.T):
        raise InputError(f"{what} is not a finite symmetric matrix")
    if float(np.linalg.eigvalsh(m).min()) < -1e-12:
        raise InputError(f"{what} is not positive semidefinite")
    return m


def _base(plant: control.StateSpace, measured: Sequence[str], exports: Mapping[str, np.ndarray] | None
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[str, ...], tuple[tuple[str, str], ...],
                     _Point, Any, dict[str, np.ndarray]]:
    if plant.dt in (0, None, True):
        raise InputError("the plant is continuous: an observer runs on the discrete model",
                         hint="linearize(..., period=1/rate)")
    c, d, y0, labels, groups = _measurement(plant, measured)
    point, lin = _point_of(plant, "observer")
    return c, d, y0, labels, groups, point, lin, _outputs(plant, exports)


def kalman(plant: control.StateSpace, measured: Sequence[str], W: ArrayLike, V: ArrayLike, *,
           time_varying: bool = False, P0: ArrayLike | None = None,
           exports: Mapping[str, np.ndarray] | None = None) -> Estimator:
    """A Kalman filter for `plant` (from linearize, with the sensors among its outputs) on the
    `measured` signals. W: the process noise covariance, on the inputs (m x m, or m variances:
    a torque disturbance, G = B) or on the state (n x n); V: the measurement noise covariance
    (p x p, or p variances, or one). time_varying: run the Riccati recursion every update from
    P0 (default W's steady state), not the steady-state gain. exports: name -> rows on the state
    (default {"x": the whole estimate})."""
    c, d, y0, labels, groups, point, lin = _base(plant, measured, exports)[:7]
    outputs = _outputs(plant, exports)
    a, b = np.asarray(plant.A), np.asarray(plant.B)
    n, m, p = a.shape[0], b.shape[1], c.shape[0]
    w = np.atleast_1d(np.asarray(W, dtype=float))
    on_inputs = (w.ndim == 1 and w.size == m and m != n) or (w.ndim == 2 and w.shape == (m, m) and m != n)
    process = b @ _covariance(W, m, "W") @ b.T if on_inputs else _covariance(W, n, "W")
    process = process + 1e-12 * np.eye(n)
    noise = _covariance(V, p, "V")
    try:
        _, prior, _ = control.dlqe(a, np.eye(n), c, process, noise, method="scipy")  # not SLICOT's
    except (ValueError, np.linalg.LinAlgError, control.ControlArgument) as exc:
        raise InputError(f"kalman: no steady-state filter: {str(exc).splitlines()[0]}",
                         hint="the measured signals must see every mode that does not decay (the "
                              "base's position and heading: measure pose:<foot> as leg "
                              "odometry)") from None
    prior = np.asarray(prior)
    gain = np.linalg.solve(c @ prior @ c.T + noise, c @ prior).T
    start = None
    if time_varying:
        start = prior.copy() if P0 is None else _covariance(P0, n, "P0")
    return Estimator("kalman", a, b, c, d, float(plant.dt), tuple(measured), labels, y0,
                     None if time_varying else gain, process, noise, start, outputs,
                     tuple(plant.input_labels), np.asarray(lin.u0, float), point,
                     tuple(plant.state_labels))


def luenberger(plant: control.StateSpace, measured: Sequence[str], poles: Sequence[complex], *,
               exports: Mapping[str, np.ndarray] | None = None) -> Estimator:
    """A Luenberger observer: the gain M that puts the estimation error's poles (the
    eigenvalues of A - M C A, discrete z; use exp(s dt) for continuous ones) at `poles`."""
    c, d, y0, labels, groups, point, lin, outputs = _base(plant, measured, exports)
    a, b = np.asarray(plant.A), np.asarray(plant.B)
    placed = np.asarray(poles, dtype=complex).reshape(-1)
    if placed.size != a.shape[0]:
        raise InputError(f"luenberger: {placed.size} poles for a plant of {a.shape[0]} states")
    if np.any(np.abs(placed) >= 1):
        raise InputError("luenberger: the poles are discrete (|z| < 1 is stable): use "
                         "np.exp(s * dt) for continuous ones")
    try:
        gain = np.asarray(control.place(a.T, (c @ a).T, placed)).T
    except (ValueError, np.linalg.LinAlgError) as exc:
        raise InputError(f"luenberger: the poles cannot be placed: {str(exc).splitlines()[0]}",
                         hint="is every mode observable from the measured signals? (a pole can "
                              "be repeated at most as often as there are measurements)") from None
    return Estimator("luenberger", a, b, c, d, float(plant.dt), tuple(measured), labels, y0, gain,
                     None, None, None, outputs, tuple(plant.input_labels),
                     np.asarray(lin.u0, float), point, tuple(plant.state_labels))


def lqg(plant: control.StateSpace, Q: ArrayLike, R: ArrayLike, W: ArrayLike, V: ArrayLike,
        measured: Sequence[str], *, time_varying: bool = False,
        exports: Mapping[str, np.ndarray] | None = None) -> LqgDesign:
    """The LQG compensator: K from `lqr(plant, Q, R)` on the Kalman filter's estimate
    (`kalman(plant, measured, W, V)`); `deploy(lab, lqg(...))` runs it as one controller."""
    K, _, _ = lqr(plant, Q, R)
    est = kalman(plant, measured, W, V, time_varying=time_varying, exports=exports)
    joints = tuple(label.rpartition(":")[0] for label in plant.input_labels)
    kinds = {label.rpartition(":")[2] for label in plant.input_labels}
    return LqgDesign(np.asarray(K, float), est, joints, kinds.pop(), est.u0.copy())


# ----- design files ------------------------------------------------------------------------------
def save_estimator(path: str | Path, est: Estimator) -> Path:
    """An estimator as a .npz beside a controllers YAML (`design_file:` of an Observer);
    never overwritten."""
    path = _new_npz(path, "save_estimator")
    p = est.point
    names = list(est.outputs)
    with replacing(path, force=False) as temporary:
        np.savez(temporary, kind=est.kind, A=est.A, B=est.B, C=est.C, D=est.D, period=est.period,
                 measured=np.array(est.measured), labels=np.array(est.labels), y0=est.y0,
                 gain=np.zeros((0, 0)) if est.gain is None else est.gain,
                 process=np.zeros((0, 0)) if est.process is None else est.process,
                 noise=np.zeros((0, 0)) if est.noise is None else est.noise,
                 P0=np.zeros((0, 0)) if est.P0 is None else est.P0,
                 output_names=np.array(names, dtype=str),
                 output_sizes=np.array([est.outputs[k].shape[0] for k in names], dtype=int),
                 output_rows=np.vstack([est.outputs[k] for k in names]) if names else np.zeros((0, 0)),
                 inputs=np.array(est.inputs), u0=est.u0, states=np.array(est.states),
                 qpos=p.qpos, qvel=p.qvel, qpos_index=p.qpos_index, qvel_index=p.qvel_index)
    return path


def load_estimator(path: str | Path) -> Estimator:
    """An estimator written by save_estimator (one line for a file that is not one)."""
    from mexone.design.deploy import _Point

    path = Path(path)
    if not path.is_file():
        raise InputError(f"estimator file {path} does not exist", file=str(path))
    try:
        with np.load(path, allow_pickle=False) as f:
            raw = {k: f[k] for k in f.files}
        optional = {k: (None if raw[k].size == 0 else np.asarray(raw[k], float))
                    for k in ("gain", "process", "noise", "P0")}
        sizes = np.asarray(raw["output_sizes"], int)
        rows = np.asarray(raw["output_rows"], float)
        outputs: dict[str, np.ndarray] = {}
        at = 0
        for name, size in zip(raw["output_names"], sizes, strict=True):
            outputs[str(name)] = rows[at:at + size]
            at += size
        states = tuple(str(s) for s in raw["states"])
        point = _Point(np.asarray(raw["qpos"], float), np.asarray(raw["qvel"], float),
                       np.asarray(raw["qpos_index"], int), np.asarray(raw["qvel_index"], int),
                       states)
        est = Estimator(str(raw["kind"]), raw["A"], raw["B"], raw["C"], raw["D"],
                        float(raw["period"]), tuple(str(s) for s in raw["measured"]),
                        tuple(str(s) for s in raw["labels"]), raw["y0"], optional["gain"],
                        optional["process"], optional["noise"], optional["P0"], outputs,
                        tuple(str(s) for s in raw["inputs"]), raw["u0"], point, states)
    except KeyError as exc:
        raise InputError(f"estimator file {path} has no {exc.args[0]!r}", file=str(path),
                         hint="write it with mexone.design.save_estimator(path, estimator)") from None
    except (ValueError, TypeError, OSError) as exc:
        raise InputError(f"estimator file {path} cannot be read: {str(exc).splitlines()[0]}",
                         file=str(path)) from None
    n = est.A.shape[0]
    if est.A.shape != (n, n) or est.C.shape[1] != n or est.C.shape[0] != len(est.labels):
        raise InputError(f"estimator file {path}: its matrices do not fit together", file=str(path))
    return est


# ----- the controllers ---------------------------------------------------------------------------
class Observer(_Deployed):
    """An estimator in the loop: it drives no joint (`joints: []`) and exports its estimate
    (the design's outputs: `x`, or names such as `tilt`), written every update, for other
    controllers to read (`inputs: {tilt: <observer>/tilt}`). From Python:
    `deploy(lab, kalman(...), name=...)`; from a YAML: a subclass of yours declaring `exports`
    to match the design file's outputs, `design_file: kf.npz` (save_estimator).
    `extra_noise` (signal group -> std, e.g. {"encoders": 1e-4}) adds noise to what it reads,
    to try it under sensors noisier than the simulated ones."""

    command_interface = "effort"
    exports: Any = {}

    @classmethod
    def _load(cls, name: str, design_file: str, yaml_dir: Path | None,  # type: ignore[override]
              robot: Any = None) -> Estimator:  # an observer's design: an Estimator (see design)
        path = _design_path(name, design_file, yaml_dir, "save_estimator")
        est = load_estimator(path)
        declared = dict(getattr(cls, "exports", {}) or {})
        sizes = {k: v.shape[0] for k, v in est.outputs.items()}
        if declared != sizes:
            raise InputError(f"controller '{name}': the class exports {declared or 'nothing'}, the "
                             f"design file {path.name} gives {sizes}",
                             hint="declare exports = " + repr(sizes))
        return est

    @classmethod
    def _design_of(cls, name: str, design_file: str, yaml_dir: Path | None,  # type: ignore[override]
                   robot: Any = None) -> Estimator | LqgDesign:
        return cls._given if cls._given is not None else cls._load(name, design_file, yaml_dir)

    def configure(self) -> None:
        super().configure()
        est = self._estimator
        model = self._sim.model
        self._readers: list[tuple[str, str, str, int]] = []  # kind, imu, its field, index
        for kind, label in self._groups():
            if kind == "imu":
                sensor, _, axis = label.partition(":")
                imu, _, what = sensor.rpartition("/")
                if what not in _IMU_FIELDS:
                    raise InputError(f"controller '{self.name}': measured signal {sensor!r} is not "
                                     "an IMU's gyro or acc", hint="measure <imu>/gyro, <imu>/acc, "
                                     "<joint>:q, <joint>:dq, encoders, pose:<frame>")
                self._readers.append(("imu", imu, _IMU_FIELDS[what], "xyz".index(axis)))
            elif kind == "still":
                self._readers.append(("still", "", "", 0))
            else:
                joint, _, what = label.rpartition(":")
                jid = model.joint(joint).id
                adr = model.jnt_qposadr[jid] if what == "q" else model.jnt_dofadr[jid]
                self._readers.append((what, "", "", int(adr)))
        joints = [label.rpartition(":")[0] for label in est.inputs]
        kinds = {label.rpartition(":")[2] for label in est.inputs}
        self._effort_inputs = (kinds.pop() if len(kinds) == 1 else "effort") == "effort"
        ids = [model.joint(j).id for j in joints]
        self._input_dofs = np.array([model.jnt_dofadr[i] for i in ids], dtype=int)
        motors = [model.actuator(j).id for j in joints]
        self._input_ctrl = np.array([model.actuator_ctrladr[m] for m in motors], dtype=int)
        self._gear = np.array([model.actuator_gear[m, 0] for m in motors])

    @property
    def _estimator(self) -> Estimator:
        # _Deployed.design is typed for the state-feedback designs; an Observer's holds an
        # Estimator (its _design_of), an Lqg's an LqgDesign
        return cast(Estimator, self.design)

    def _groups(self) -> list[tuple[str, str]]:
        est = self._estimator
        out = []
        for label in est.labels:
            if label.endswith((":q", ":dq")) and label in est.states:
                out.append(("state", label))
            elif any(label.startswith(f"{n[5:]}:") for n in est.measured if n.startswith("pose:")):
                out.append(("still", label))
            else:
                out.append(("imu", label))
        return out

    def reset(self) -> None:
        self.x, self.P = self._estimator.initial()
        self._started = False
        if not hasattr(self, "extra_noise"):
            self.extra_noise: dict[str, float] = {}

    def _noise_std(self) -> np.ndarray:
        """Per measured signal: the std of the noise `extra_noise` adds (encoders have none in
        the simulation; an IMU has its URDF noise already)."""
        est = self._estimator
        std = np.zeros(len(est.labels))
        for group, value in self.extra_noise.items():
            hits = [i for i, label in enumerate(est.labels)
                    if (group == "encoders" and label.endswith(":q")) or label == group
                    or label.startswith(group + ":")]
            if not hits:
                raise InputError(f"extra_noise names {group!r}, not a measured signal",
                                 hint=", ".join(est.measured))
            std[hits] = float(value)
        return std

    def activate(self, state: State) -> None:
        self.reset()

    def measure(self, state: State) -> np.ndarray:
        """The measured signals' deviations from the point (y - y0)."""
        data = self._sim.data
        est = self._estimator
        y = np.zeros(len(self._readers))
        sensors = None
        for i, (kind, imu, field_name, index) in enumerate(self._readers):
            if kind == "imu":
                sensors = sensors if sensors is not None else state.sensors
                y[i] = getattr(sensors[imu], field_name)[index]
            elif kind == "q":
                y[i] = data.qpos[index]
            elif kind == "dq":
                y[i] = data.qvel[index]
            else:
                y[i] = est.y0[i]
        if self.extra_noise:
            if getattr(self, "_rng", None) is None:
                self._rng, self._std = np.random.default_rng(38), self._noise_std()
            y += self._std * self._rng.standard_normal(y.size)
        return y - est.y0

    def applied(self) -> np.ndarray:
        """The plant's inputs as applied over the last period (deviations from u0): the motors'
        torques (effort inputs) or the PIDs' setpoints (position inputs)."""
        data = self._sim.data
        if self._effort_inputs:
            u = data.qfrc_actuator[self._input_dofs]
        else:
            u = data.ctrl[self._input_ctrl] / self._gear
        return u - self._estimator.u0

    def estimate(self, state: State) -> np.ndarray:
        """Run one update of the estimator and export its outputs; returns the estimate."""
        est = self._estimator
        y = self.measure(state)
        u = self.applied()
        if not self._started:  # the first: the prior is the point itself
            self._started = True
        self.x, self.P = est.step(self.x, self.P, y, u)
        if not np.all(np.isfinite(self.x)):
            raise FloatingPointError("the estimate diverged (NaN)")
        for name, rows in est.outputs.items():
            self.exports[name][:] = rows @ self.x
        return self.x

    def update(self, state: State, t: float, dt: float) -> np.ndarray | None:
        x = self.estimate(state)
        if self.trace is not None:
            self._record(t, self.deviation(), x.copy())
        return None


class Lqg(Observer):
    """The LQG compensator as one controller on the plant's input joints: u = u0 - K x+, with
    x+ the Kalman filter's estimate of this update (exported too)."""

    @property
    def _estimator(self) -> Estimator:
        return self._lqg.estimator

    @property
    def _lqg(self) -> LqgDesign:
        return cast(LqgDesign, self.design)  # an Lqg's design (see Observer._estimator)

    def update(self, state: State, t: float, dt: float) -> np.ndarray:
        x = self.estimate(state)
        u = self._lqg.u0 - self._lqg.K @ x
        if self.trace is not None:
            self._record(t, self.deviation(), x.copy())
        return u


# ----- the estimate against the true state -------------------------------------------------------
@dataclass(frozen=True)
class EstimateRun:
    """A run of an observer: `t` (s), the true state deviation and the estimate (len(t) x n,
    the plant's `states`), each export's true and estimated values, and their RMS errors after
    `settle` s (`rms`: export -> per component)."""

    t: np.ndarray
    true: np.ndarray
    estimate: np.ndarray
    states: tuple[str, ...]
    outputs: dict[str, tuple[np.ndarray, np.ndarray]]
    rms: dict[str, np.ndarray]
    settle: float = 0.0
    pushes: tuple[tuple[float, str, Sequence[float]], ...] = field(default=())

    def error(self, name: str) -> float:
        """The RMS error of an export over its components (sqrt of the mean square)."""
        return float(np.sqrt(np.mean(self.rms[name] ** 2)))


def compare_estimate(lab: Lab, observer: Observer, duration: float = 2.0, settle: float = 0.2,
                     pushes: Sequence[tuple[float, str, Sequence[float]]] = (),
                     push_seconds: float = 0.1) -> EstimateRun:
    """Run `duration` s with the observer in the loop (from where the lab is), the pushes
    (time s from now, link, impulse N s over `push_seconds`, world frame) applied, and compare
    its estimate with the true state the simulator has."""
    if not isinstance(observer, Observer):
        raise InputError("compare_estimate: give the observer deploy() returned")
    if not np.isfinite(duration) or duration <= 0:
        raise InputError(f"duration {duration} is not a positive number of seconds")
    sim = lab.sim

    def start() -> None:
        observer.trace_full.clear()
        observer.trace_length = max(2, round(duration * observer.rate))
        observer.trace = []
        for at, link, impulse in pushes:
            force = np.asarray(impulse, dtype=float) / push_seconds
            handle: list[Periodic] = []

            def kick(s: Simulation, force: np.ndarray = force, link: str = link,
                     handle: list[Periodic] = handle) -> None:
                s.remove_periodic(handle[0])
                s.apply_wrench(link, force, (0.0, 0.0, 0.0), duration=push_seconds)
            handle.append(sim.add_periodic(float(at), kick))
    sim.work.call(start) if sim.loop_elsewhere() else start()
    trace = _run(lab, observer, duration)
    est = observer._estimator
    t = np.array([row[0] for row in trace])
    t = t - t[0]
    true = np.array([row[1] for row in trace])
    estimate = np.array([row[2] for row in trace])
    keep = t >= settle
    outputs: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    rms: dict[str, np.ndarray] = {}
    for name, rows in est.outputs.items():
        a, b = true @ rows.T, estimate @ rows.T
        outputs[name] = (a, b)
        rms[name] = np.sqrt(np.mean((b[keep] - a[keep]) ** 2, axis=0))
    return EstimateRun(t, true, estimate, est.states, outputs, rms, settle, tuple(pushes))


def plot_estimate(run: EstimateRun, name: str | None = None, ax: Axes | None = None
                  ) -> Figure | SubFigure:
    """The true value (solid) and the estimate (dashed) of one export (default the first), with
    its RMS error in the title; returns the Figure."""
    import matplotlib.pyplot as plt

    name = name or next(iter(run.outputs))
    if name not in run.outputs:
        raise InputError(f"no export named {name!r}", hint=", ".join(run.outputs))
    true, est = run.outputs[name]
    fig: Figure | SubFigure
    if ax is None:
        fig, ax = plt.subplots(figsize=(7, 3.5))
    else:
        fig = ax.figure
    for i in range(true.shape[1]):
        (line,) = ax.plot(run.t, true[:, i], label=f"{name}[{i}] true")
        ax.plot(run.t, est[:, i], "--", color=line.get_color(), label=f"{name}[{i}] estimate")
    for at, _, _ in run.pushes:
        ax.axvline(at, color="grey", lw=0.6)
    ax.set_xlabel("t (s)")
    ax.set_title(f"{name}: RMS error {number_text(run.error(name))} after {run.settle:g} s")
    ax.legend(fontsize="x-small", ncol=2)
    ax.grid(True)
    return fig
