"""Deploying a design into the 1 kHz loop (issue 32 item 3): a gain matrix or a python-control
system becomes a running PythonController.

Two controller types, named for what they compute (a YAML names them `mexone/StateFeedback` and
`mexone/LinearController`, found as `mexone.<Class>`, or dotted `mexone.design.StateFeedback`):

StateFeedback
    u = u0 - K (dx - dx_ref): dx the measured state's deviation from the design's operating point
    in the linear model's coordinates (`state_deviation`: `mj_differentiatePos` for a floating
    base), u0 the inputs' values there (the torques that hold the pose). `dx_ref` is 0 unless a
    reference is set (`controller.reference`).
LinearController
    a discrete linear system C on named measured signals (`<joint>:q`, `<joint>:dq`, or any state
    of the plant's model): the unity-feedback loop of the course's block diagram, u = u0 + C(r - y)
    with r the reference (0: hold the point). A continuous C is discretised at the controller's
    rate by `method` (python-control's `sample_system`: zoh, foh, tustin, matched, ...); a
    discrete one must have the controller's period. What `control.create_statefbk_iosystem`
    returns (inputs xd, ud, then the plant's outputs) is fed the references and the measured
    states directly: u = u0 + ud - K (x - xd).

Every check of a design (K's shape, NaN, a rate that does not match, a system the rate cannot
discretise) is one InputError line, raised before the lab is touched; from a YAML the load fails
with that line and the lab runs on.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, TypeAlias, cast

import control
import mujoco
import numpy as np
from numpy.typing import ArrayLike

from mexone.control.hardware import INTEGRAL_SUFFIX
from mexone.control.student import Param, PythonController
from mexone.design.design_file import check_on_robot, read_design
from mexone.errors import ArgumentTypeError, InputError, printable
from mexone.files import replacing
from mexone.ranges import UPDATE_RATE, number_text

if TYPE_CHECKING:
    from mexone.control.resolve import Plugin
    from mexone.control.spec import PidGains
    from mexone.control.student import State
    from mexone.lab import Lab

StateSpace: TypeAlias = Any  # control.StateSpace: python-control has no type information

__all__ = ["StateFeedback", "LinearController", "deploy", "save_design", "load_design",
           "lqr", "METHODS", "GainDesign", "SystemDesign", "install"]

#: how a continuous controller is discretised (python-control's sample_system methods)
METHODS = ("zoh", "foh", "tustin", "bilinear", "matched", "impulse", "euler", "backward_diff")
_INTERFACES = ("effort", "position", "velocity")


# ----- designs: what a deployed controller runs ------------------------------------------------
@dataclass(frozen=True)
class _Point:
    """The operating point in the simulation's coordinates (from `sys.linearization`)."""

    qpos: np.ndarray  # the model's qpos (reduced models: their own entries)
    qvel: np.ndarray
    qpos_index: np.ndarray  # their entries in the live qpos / qvel
    qvel_index: np.ndarray
    states: tuple[str, ...]  # the model's state labels, in order
    act: np.ndarray = field(default_factory=lambda: np.zeros(0))  # act entries kept as states
    act_index: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))  # in live act

    def deviation(self, model: mujoco.MjModel, data: mujoco.MjData, scratch: np.ndarray,
                  dq: np.ndarray) -> np.ndarray:
        """dx of the live state (`scratch`: an nq buffer, `dq`: an nv buffer)."""
        scratch[:] = data.qpos
        scratch[self.qpos_index] = self.qpos
        mujoco.mj_differentiatePos(model, dq, 1.0, scratch, data.qpos)
        parts = [dq[self.qvel_index], data.qvel[self.qvel_index] - self.qvel]
        if self.act_index.size:
            parts.append(data.act[self.act_index] - self.act)
        return np.concatenate(parts)


@dataclass(frozen=True)
class GainDesign:
    """u = u0 - K (dx - dx_ref) on `joints` through `interface`; `dt` the period it was designed
    for (None: any rate, a continuous design's K)."""

    K: np.ndarray
    u0: np.ndarray
    joints: tuple[str, ...]
    interface: str
    point: _Point
    dt: float | None


@dataclass(frozen=True)
class SystemDesign:
    """A discrete controller (A, B, C, D) at period `dt` on measured `signals` (the rows of the
    plant's state it reads, or absolute joint readings), writing `joints`."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    dt: float
    inputs: tuple[str, ...]  # the controller's input labels
    joints: tuple[str, ...]
    interface: str
    u0: np.ndarray
    point: _Point | None  # deviations from it; None: absolute readings
    direct: bool  # inputs fed the measurement itself (create_statefbk_iosystem), not r - y


def _fail(message: str, hint: str | None = None) -> InputError:
    return InputError(message, hint=hint)


def _shape(shape: tuple[int, ...]) -> str:
    return "(" + ", ".join(str(n) for n in shape) + ")"


def _point_of(plant: StateSpace, who: str) -> tuple[_Point, Any]:
    point = getattr(plant, "linearization", None)
    if point is None:
        raise _fail(f"{who}: the plant is not a StateSpace made by mexone.design.linearize "
                    "(its operating point is unknown)",
                    hint="pass the StateSpace linearize returned (python-control's "
                         "transformations drop .linearization)")
    model = point.source
    act_index = []
    for row in point.act_rows:  # an act entry of the model -> the same actuator's in the live model
        starts, counts = model.actuator_actadr, np.maximum(model.actuator_actnum, 1)
        actuator = next(i for i in range(model.nactuator) if starts[i] <= row < starts[i] + counts[i])
        act_index.append((model.actuator(actuator).name, int(row - model.actuator_actadr[actuator])))
    return _Point(np.asarray(point.qpos, float), np.asarray(point.qvel, float),
                  np.asarray(point.qpos_index, int), np.asarray(point.qvel_index, int),
                  tuple(plant.state_labels), np.asarray(point.act, float)[point.act_rows],
                  np.asarray(act_index, dtype=object)), point


def _joints_of(labels: Sequence[str], who: str) -> tuple[tuple[str, ...], str]:
    """`<joint>:<interface>` labels -> joints and the one interface."""
    joints, kinds = [], set()
    for label in labels:
        joint, _, kind = str(label).rpartition(":")
        if kind not in _INTERFACES or not joint:
            raise _fail(f"{who}: output {label!r} is not '<joint>:effort' (or :position, :velocity)",
                        hint="name the outputs after the joints they drive, as linearize names its inputs")
        joints.append(joint)
        kinds.add(kind)
    if len(kinds) != 1:
        raise _fail(f"{who}: outputs mix interfaces ({', '.join(sorted(kinds))}): a controller "
                    "claims one")
    return tuple(joints), kinds.pop()


def _finite(name: str, values: np.ndarray, who: str) -> None:
    if not np.all(np.isfinite(values)):
        bad = np.argwhere(~np.isfinite(values))[0]
        raise _fail(f"{who}: {name} has a NaN or inf (at {tuple(int(i) for i in bad)})")


def gain_design(K: ArrayLike, plant: StateSpace, who: str = "deploy") -> GainDesign:
    """K checked against the plant from linearize: (inputs x states), finite."""
    point, lin = _point_of(plant, who)
    try:
        gains = np.atleast_2d(np.asarray(K, dtype=float))
    except (TypeError, ValueError):
        raise _fail(f"{who}: K is not a matrix of numbers") from None
    expected = (plant.ninputs, plant.nstates)
    if gains.shape != expected:
        raise _fail(f"{who}: K has shape {_shape(gains.shape)}; this plant needs {_shape(expected)} "
                    f"({plant.ninputs} inputs x {plant.nstates} states)",
                    hint="K from control.dlqr(plant, Q, R) or control.place(plant.A, plant.B, poles)")
    _finite("K", gains, who)
    joints, kind = _joints_of(plant.input_labels, who)
    dt = None if plant.dt in (0, None, True) else float(plant.dt)
    return GainDesign(gains, np.asarray(lin.u0, float), joints, kind, point, dt)


def system_design(system: Any, plant: StateSpace | None = None, rate: float | None = None,
                  method: str = "zoh",
                  u0: Sequence[float] | None = None, who: str = "deploy") -> SystemDesign:
    """A python-control controller checked and discretised at `rate` (Hz)."""
    if isinstance(system, tuple):  # create_statefbk_iosystem's (controller, closed loop)
        system = system[0]
    if isinstance(system, control.TransferFunction):
        try:
            system = control.ss(system, inputs=system.input_labels, outputs=system.output_labels)
        except ValueError as exc:
            raise _fail(f"{who}: the controller cannot be discretised or run: "
                        f"{str(exc).splitlines()[0]}",
                        hint="a non-proper transfer function (a pure derivative s) needs a "
                             "filter: kd s / (1 + s / N)") from None
    if not isinstance(system, control.StateSpace):
        raise ArgumentTypeError(f"{who}: a design is a gain matrix K (with the plant), a python-control "
                                f"StateSpace or TransferFunction, or what create_statefbk_iosystem "
                                f"returns; not {type(system).__name__}")
    for name in ("A", "B", "C", "D"):
        _finite(f"the controller's {name}", np.asarray(getattr(system, name)), who)
    if method not in METHODS:
        raise _fail(f"{who}: method {method!r} is not one of {', '.join(METHODS)}")
    static = system.dt is None  # python-control's static gain (tf(20, 1)): fits any timebase
    continuous = system.dt == 0 or static
    if rate is None:
        if continuous:
            what = "static gain" if static else "continuous controller"
            raise _fail(f"{who}: a {what} needs the rate to run at",
                        hint="pass rate=<Hz>, or update_rate: in the YAML")
        rate = 1.0 / float(system.dt) if system.dt not in (None, True) else None
        if rate is None:
            raise _fail(f"{who}: the discrete controller has no sampling time (dt=True)",
                        hint="give it dt, or pass rate=<Hz>")
    period = 1.0 / rate
    if continuous:
        poles = np.linalg.eigvals(system.A) if system.nstates else np.zeros(0)
        fastest = float(np.abs(poles).max(initial=0.0))
        if fastest * period > np.pi:
            raise _fail(f"{who}: the continuous controller's fastest pole ({number_text(fastest)} rad/s) "
                        f"is beyond the Nyquist frequency of its rate {number_text(rate)} Hz "
                        f"(pi * rate = {number_text(np.pi * rate)} rad/s): {method} cannot discretise it",
                        hint="slow the pole down (filter the derivative less) or raise update_rate")
        try:
            system = control.sample_system(system, period, method=method)
        except (ValueError, np.linalg.LinAlgError) as exc:
            raise _fail(f"{who}: {method} cannot discretise the controller at {number_text(rate)} Hz: "
                        f"{str(exc).splitlines()[0]}") from None
        _finite("the discretised controller", system.A, who)
    elif abs(float(system.dt) - period) > 1e-9 * period:
        raise _fail(f"{who}: the discrete controller has dt = {number_text(float(system.dt))} s but "
                    f"runs at {number_text(rate)} Hz (period {number_text(period)} s)",
                    hint="design it at the controller's period, or run it at 1/dt")
    inputs = tuple(system.input_labels)
    direct = any(s.startswith(("xd[", "ud[")) for s in inputs)
    point = None
    if plant is not None:
        point, lin = _point_of(plant, who)
        if direct:  # create_statefbk_iosystem names the plant's outputs y[i]
            inputs = tuple(plant.output_labels[int(s[2:-1])] if s.startswith("y[") else s
                           for s in inputs)
    joints, kind = _joints_of(system.output_labels, who)
    if u0 is None:
        offsets = np.zeros(len(joints))
        if plant is not None:
            names = list(plant.input_labels)
            for i, label in enumerate(system.output_labels):
                if label in names:
                    offsets[i] = lin.u0[names.index(label)]
    else:
        offsets = np.asarray(u0, dtype=float).reshape(-1)
    if offsets.shape != (len(joints),):
        raise _fail(f"{who}: u0 has {offsets.size} values; the controller has {len(joints)} outputs")
    _finite("u0", offsets, who)
    for label in inputs:
        if direct and label.startswith(("xd[", "ud[")):
            continue
        if point is not None and label in point.states:
            continue
        joint, _, what = label.rpartition(":")
        if what not in ("q", "dq") or not joint:
            known = f"the plant's states ({', '.join(point.states[:6])}, ...)" if point else \
                "'<joint>:q' or '<joint>:dq'"
            raise _fail(f"{who}: the controller's input {label!r} is not a measured signal",
                        hint=f"name its inputs after {known}")
    return SystemDesign(np.asarray(system.A, float), np.asarray(system.B, float),
                        np.asarray(system.C, float), np.asarray(system.D, float), period, inputs,
                        joints, kind, offsets, point, direct)


def lqr(plant: StateSpace, Q: ArrayLike, R: ArrayLike) -> Any:
    """`control.dlqr` (discrete plant) or `control.lqr`, with Q and R checked first: one line for
    a shape that does not fit, a NaN, a Q that is not positive semidefinite or an R that is not
    positive definite (singular). Returns K, S, E as python-control does."""
    if not isinstance(plant, control.StateSpace):
        raise _fail(f"lqr: the plant is {printable(type(plant).__name__, 40)}, not a StateSpace",
                    hint="pass the StateSpace linearize returned")
    nx, nu = plant.nstates, plant.ninputs
    mats = {}
    for name, value, n in (("Q", Q, nx), ("R", R, nu)):
        try:
            m = np.atleast_2d(np.asarray(value, dtype=float))
        except (TypeError, ValueError):
            raise _fail(f"lqr: {name} is not a matrix of numbers ({printable(value, 60)})",
                        hint=f"a ({n}, {n}) array, or its diagonal") from None
        if m.shape == (1, n) or m.shape == (n, 1) and n > 1:
            m = np.diag(m.ravel())
        if m.shape != (n, n):
            raise _fail(f"lqr: {name} has shape {_shape(m.shape)}; this plant needs {_shape((n, n))}")
        _finite(name, m, "lqr")
        if not np.allclose(m, m.T):
            raise _fail(f"lqr: {name} is not symmetric")
        mats[name] = m
    low = float(np.linalg.eigvalsh(mats["R"]).min())
    if low <= 1e-12 * max(1.0, float(np.abs(mats["R"]).max())):
        raise _fail(f"lqr: R is singular or not positive definite (smallest eigenvalue "
                    f"{number_text(low)})", hint="weight every input: R = r * I with r > 0")
    if float(np.linalg.eigvalsh(mats["Q"]).min()) < -1e-9:
        raise _fail("lqr: Q is not positive semidefinite")
    solve = control.lqr if plant.dt == 0 else control.dlqr
    try:
        # SciPy's Riccati solver: with slycot installed python-control would take SLICOT's,
        # which refuses the robot's models (modes on the unit circle: docs/DECISIONS.md)
        return solve(plant, mats["Q"], mats["R"], method="scipy")
    except (ValueError, np.linalg.LinAlgError, control.ControlArgument) as exc:
        raise _fail(f"lqr: no stabilising solution: {str(exc).splitlines()[0]}",
                    hint="is the plant stabilisable? weight the unstable states in Q") from None


# ----- files beside a YAML -----------------------------------------------------------------------
def _design_path(name: str, design_file: str, yaml_dir: Path | None, writer: str) -> Path:
    """A controller's `design_file:` (relative to its YAML's folder), or the one line saying to
    set it (written by mexone.design's `writer`)."""
    if not design_file:
        raise InputError(f"controller '{name}': no design: set design_file: <file.npz> "
                         "beside the YAML", hint=f"write one with mexone.design.{writer}")
    path = Path(design_file)
    return yaml_dir / path if not path.is_absolute() and yaml_dir is not None else path


def _new_npz(path: str | Path, what: str) -> Path:
    """`path` if it names a .npz file that does not exist yet, else the one line why not."""
    path = Path(path)
    if path.suffix != ".npz":
        raise _fail(f"{what}: {path} is not a .npz file")
    if path.exists():
        raise _fail(f"{what}: {path} exists", hint="remove it first, or choose another name")
    return path


def save_design(path: str | Path, K: ArrayLike, plant: StateSpace) -> Path:
    """Write K and the plant's operating point (what StateFeedback needs) to a .npz, for a YAML's
    `design:` entry. Nothing is overwritten without the caller removing it first."""
    design = gain_design(K, plant, "save_design")
    path = _new_npz(path, "save_design")
    p = design.point
    with replacing(path, force=False) as temporary:  # its folder checked; never half-written
        _save_npz(temporary, design, p)
    return path


def _save_npz(path: Path, design: GainDesign, p: _Point) -> None:
    period: dict[str, Any] = {} if design.dt is None else {"dt": design.dt}  # no dt: continuous
    np.savez(path, K=design.K, u0=design.u0, joints=np.array(design.joints),
             interface=design.interface, qpos=p.qpos, qvel=p.qvel, qpos_index=p.qpos_index,
             qvel_index=p.qvel_index, states=np.array(p.states), act=p.act,
             act_actuators=np.array([a for a, _ in p.act_index] if p.act_index.size else [], dtype=str),
             act_offsets=np.array([o for _, o in p.act_index] if p.act_index.size else [], dtype=int),
             **period)


def load_design(path: str | Path) -> GainDesign:
    """A gain design from a .npz written by save_design, or a .yaml with K, u0, joints,
    interface, states, qpos, qvel (and qpos_index/qvel_index for a reduced model), dt (left out:
    a continuous design's gain, any rate). A file a student hands in: design_file.read_design
    checks every field (one InputError line naming the file)."""
    raw = read_design(path)
    acts = np.empty(len(raw.act_actuators), dtype=object)
    acts[:] = list(zip(raw.act_actuators, raw.act_offsets.tolist(), strict=True))
    point = _Point(raw.qpos, raw.qvel, raw.qpos_index, raw.qvel_index, raw.states, raw.act, acts)
    return GainDesign(raw.K, raw.u0, raw.joints, raw.interface, point, raw.dt)


# ----- the controllers ---------------------------------------------------------------------------
class _Deployed(PythonController):
    """What both controllers share: the design (given from Python, or the YAML's `design:` file
    beside it), the rate check, the reference, an optional excitation and a trace."""

    design_file = Param("", doc="the design file next to the YAML (.npz or .yaml)")
    _given: ClassVar[Any] = None  # set on a per-deploy subclass by `deploy`
    reference: np.ndarray  # r: the set point, in the design's reference signals (reset())
    design: GainDesign | SystemDesign  # checked in configure()
    _kinds: list[str]  # a LinearController's inputs: what feeds each ("x", "xd", "ud", ...)

    def configure(self) -> None:
        binding = self.__dict__["_mexone_binding"]
        self._sim = binding.ctx.sim
        self.rate = binding.plugin.update_rate or 1.0 / self._sim.model.opt.timestep
        model = self._sim.model
        acting = {model.actuator(i).name for i in range(model.nactuator) if model.actuator_actnum[i]}
        self.design = self._checked_design(self.name, tuple(self.joints), self.design_file,
                                           binding.plugin.yaml_dir, self.rate,
                                           (model.nq, model.nv, acting))
        self._scratch, self._dq = np.zeros(model.nq), np.zeros(model.nv)
        point = self.design.point
        if point is not None and point.act_index.size and point.act_index.dtype == object:
            live = [int(model.actuator_actadr[model.actuator(n).id]) + int(o) for n, o in point.act_index]
            self.design = replace(self.design, point=replace(point, act_index=np.asarray(live, int)))
        self.excitation: Callable[[float], np.ndarray] | None = None
        self.trace: list[tuple[Any, ...]] | None = None
        self.trace_full = threading.Event()  # set when `trace` holds `trace_length` rows
        self.trace_length = 0
        self.reset()

    @classmethod
    def check_entry(cls, name: str, joints: tuple[str, ...], plugin: Plugin, timestep: float,
                    robot: Any = None) -> None:
        """`mexone check --controllers`: what configure() refuses, from the YAML and the robot
        (the same checks: a missing or unreadable design file, a rate that is not the design's,
        other joints, indices or actuators the robot cannot have), at the line of the YAML key
        it concerns."""
        lines = plugin.lines
        sizes = None
        if robot is not None:  # at most: a floating base, every moving joint one entry
            moving = sum(1 for j in robot.joints.values() if j.moving)
            sizes = (7 + moving, 6 + moving,
                     {j.name + INTEGRAL_SUFFIX for j in robot.actuated_joints})
        try:
            design = cls._design_of(name, plugin.params.get("design_file", ""), plugin.yaml_dir,
                                    sizes)
        except InputError as exc:
            exc.line = lines.get("design_file")
            raise
        try:
            cls._check_design(name, joints, design, plugin.update_rate or 1.0 / timestep)
        except InputError as exc:
            exc.line = lines.get("update_rate") if "period" in exc.what \
                else lines.get("joints", lines.get("joint"))
            raise

    @classmethod
    def _checked_design(cls, name: str, joints: tuple[str, ...], design_file: str,
                        yaml_dir: Path | None, rate: float, robot: Any = None
                        ) -> GainDesign | SystemDesign:
        design = cls._design_of(name, design_file, yaml_dir, robot)
        cls._check_design(name, joints, design, rate)
        return design

    @classmethod
    def _design_of(cls, name: str, design_file: str, yaml_dir: Path | None, robot: Any = None
                   ) -> GainDesign | SystemDesign:
        """The design given from Python (deploy), else the YAML's design_file (checked against
        `robot`: (nq, nv, the actuators with a state), when known)."""
        design = cls._given if cls._given is not None \
            else cls._load(name, design_file, yaml_dir, robot)
        if issubclass(cls, LinearController) and not isinstance(design, SystemDesign):
            raise InputError(f"controller '{name}': a LinearController runs a python-control "
                             "system given from Python (deploy); a design file holds a gain",
                             hint="use type: mexone/StateFeedback for a gain file")
        return design

    @classmethod
    def _check_design(cls, name: str, joints: tuple[str, ...], design: GainDesign | SystemDesign,
                      rate: float) -> None:
        dt = getattr(design, "dt", None)
        if dt is not None and abs(dt * rate - 1.0) > 1e-6:
            raise InputError(f"controller '{name}': the design's period is {number_text(dt)} s "
                             f"but the controller runs at {number_text(rate)} Hz",
                             hint=f"set update_rate: {number_text(1.0 / dt)}")
        if tuple(joints) != tuple(design.joints):
            raise InputError(f"controller '{name}': joints {list(joints)} are not the "
                             f"design's {list(design.joints)} (in that order)")

    @classmethod
    def _load(cls, name: str, design_file: str, yaml_dir: Path | None, robot: Any = None
              ) -> GainDesign:
        path = _design_path(name, design_file, yaml_dir, "save_design")
        try:
            design = load_design(path)
            if robot is not None:
                p = design.point
                check_on_robot(path, p.qpos_index, p.qvel_index, [a for a, _ in p.act_index],
                               *robot)
        except InputError as exc:  # its message names the design file: locate it at the YAML's line
            raise InputError(f"controller '{name}': {exc.what}", hint=exc.hint) from None
        if design.interface != cls.command_interface:
            raise InputError(f"design file {path} drives the {design.interface} interface; "
                             f"{cls.__name__} drives {cls.command_interface}")
        return design

    def reset(self) -> None:
        """Forget the controller's own state (a LinearController's x)."""

    def _record(self, *row: Any) -> None:
        trace = self.trace
        if trace is not None:
            trace.append(row)
            if len(trace) >= self.trace_length:
                self.trace_full.set()

    def deviation(self) -> np.ndarray:
        """The live state's deviation from the design's point (the model's x)."""
        point = self.design.point
        assert point is not None, "a controller deployed without a plant has no point"
        return point.deviation(self._sim.model, self._sim.data, self._scratch, self._dq)


class StateFeedback(_Deployed):
    """u = u0 - K (dx - reference): a gain matrix from a linear model's design (LQR, pole
    placement) on the joints it was designed for. From Python: `deploy(lab, K, plant)`; from a
    YAML: `type: mexone/StateFeedback` with `design_file: gains.npz` (save_design)."""

    command_interface = "effort"
    design: GainDesign

    def reset(self) -> None:
        self.reference = np.zeros(self.design.K.shape[1])

    def update(self, state: State, t: float, dt: float) -> np.ndarray:
        dx = self.deviation()
        r = self.reference if self.excitation is None else self.reference + self.excitation(t)
        u = self.design.u0 - self.design.K @ (dx - r)
        self._record(t, dx, r, u)
        return u


class LinearController(_Deployed):
    """A discrete linear controller on named measured signals: u = u0 + C(r - y) (or, for what
    create_statefbk_iosystem returns, its own inputs xd, ud and the measured states). From
    Python: `deploy(lab, C, plant, rate=...)`; from a YAML only through deploy (a system is
    not a file)."""

    command_interface = "effort"
    design: SystemDesign

    def configure(self) -> None:
        super().configure()
        d = self.design
        self._rows, self._kinds = [], []  # per controller input: what feeds it
        for label in d.inputs:
            if d.direct and label.startswith(("xd[", "ud[")):
                self._rows.append(-1)
                self._kinds.append(label[:2])
            elif d.point is not None and label in d.point.states:
                self._rows.append(d.point.states.index(label))
                self._kinds.append("x")
            else:
                joint, _, what = label.rpartition(":")
                jid = mujoco.mj_name2id(self._sim.model, mujoco.mjtObj.mjOBJ_JOINT, joint)
                if jid < 0:
                    raise InputError(f"controller '{self.name}': input {label!r} names no joint of the robot")
                adr = self._sim.model.jnt_qposadr[jid] if what == "q" else self._sim.model.jnt_dofadr[jid]
                self._rows.append(int(adr))
                self._kinds.append(what)

    def reset(self) -> None:
        self.x = np.zeros(self.design.A.shape[0])
        self.reference = np.zeros(len(self.design.inputs))

    def measured(self) -> tuple[np.ndarray, np.ndarray | None]:
        """The controller's inputs' measured signals (deviations from the point, or readings),
        and the plant's state deviation dx (None without a point)."""
        dx = self.deviation() if self.design.point is not None else None
        data = self._sim.data
        y = np.zeros(len(self._rows))
        for i, (row, kind) in enumerate(zip(self._rows, self._kinds, strict=True)):
            if kind == "x" and dx is not None:
                y[i] = dx[row]
            elif kind == "q":
                y[i] = data.qpos[row]
            elif kind == "dq":
                y[i] = data.qvel[row]
        return y, dx

    def update(self, state: State, t: float, dt: float) -> np.ndarray:
        d = self.design
        y, dx = self.measured()
        r = self.reference if self.excitation is None else self.reference + self.excitation(t)
        e = np.where(np.array(self._kinds) == "x", y, r) if d.direct else r - y
        u = d.u0 + d.C @ self.x + d.D @ e
        self.x = d.A @ self.x + d.B @ e
        self._record(t, dx, r, u)
        return u


# ----- from Python -------------------------------------------------------------------------------
def deploy(lab: Lab, design: Any, plant: StateSpace | None = None, *, name: str = "design",
           rate: float | None = None,
           method: str = "zoh", u0: Sequence[float] | None = None,
           reference: Mapping[str, float] | None = None) -> StateFeedback | LinearController:
    """Run a design in the lab's loop and return the running controller (its `reference`,
    `deviation()`, `trace` are live: touch them between runs).

    design: a gain matrix K with `plant` (the StateSpace from linearize: u = u0 - K dx); a
    python-control StateSpace or TransferFunction whose inputs are measured signals and outputs
    `<joint>:effort` (u = u0 + C(r - y); continuous ones discretised at `rate` Hz by `method`);
    or what control.create_statefbk_iosystem returns, with the plant; or an estimator or LQG
    design from mexone.design.observers (an `Observer` or `Lqg`). rate: Hz (default: the
    design's 1/dt, else every physics step). The controllers driving the design's joints are
    stopped; a controller called `name` already loaded is replaced."""
    sim = getattr(lab, "sim", None)
    manager = getattr(lab, "manager", None)
    if sim is None or manager is None:
        raise ArgumentTypeError("deploy takes a mexone Lab with controllers "
                                "(Lab.create(controllers=...))")
    if not isinstance(name, str) or not name.isidentifier():
        raise _fail(f"deploy: name {printable(name, 60)!r} is not a controller name",
                    hint="letters, digits and _, starting with a letter: name='arm_lqr'")
    if rate is not None:
        rate = UPDATE_RATE.check(rate, "deploy: rate")
    own = getattr(design, "deployed", None)  # an observer or LQG design (design/observers.py)
    if own is not None:
        return cast(StateFeedback | LinearController, install(lab, *own(rate), name=name))
    built: GainDesign | SystemDesign
    if isinstance(design, control.InputOutputSystem | tuple):
        built = system_design(design, plant, rate, method, u0)
        cls: type[_Deployed] = LinearController
    else:
        if plant is None:
            raise _fail("deploy: a gain matrix K needs the plant it was designed on",
                        hint="deploy(lab, K, plant) with plant = linearize(...)")
        built = gain_design(design, plant)
        if u0 is not None:
            built = replace(built, u0=np.asarray(u0, float).reshape(built.u0.shape))
        cls = StateFeedback
        if rate is None and built.dt is not None:
            rate = 1.0 / built.dt
    rate = rate if rate is not None else 1.0 / built.dt if isinstance(built, SystemDesign) else None
    if isinstance(built, GainDesign) and built.dt is not None and rate is not None \
            and abs(built.dt * rate - 1) > 1e-6:
        raise _fail(f"deploy: K was designed for a period of {number_text(built.dt)} s; rate "
                    f"{number_text(rate)} Hz runs it at {number_text(1.0 / rate)} s",
                    hint=f"rate={number_text(1.0 / built.dt)}, or linearize at period=1/rate")
    labels = list(built.inputs) if isinstance(built, SystemDesign) else list(built.point.states)
    r = np.zeros(len(labels))
    for label, value in (reference or {}).items():
        if label not in labels:
            raise _fail(f"deploy: reference names {label!r}, not one of the controller's signals",
                        hint=", ".join(labels[:8]) + (", ..." if len(labels) > 8 else ""))
        r[labels.index(label)] = float(value)
    if not np.all(np.isfinite(r)):
        raise _fail("deploy: the reference has a NaN or inf")
    impl = install(lab, cls, built, rate, name=name)
    impl.reference[:] = r
    return cast(StateFeedback | LinearController, impl)


def install(lab: Lab, cls: type[_Deployed], built: GainDesign | SystemDesign, rate: float | None,
            exports: Mapping[str, int] | None = None, *, name: str) -> _Deployed:
    """Run `cls` (a _Deployed type) with the checked design `built` (its joints, interface) in
    the lab's loop as controller `name` at `rate` Hz: the controllers driving its joints are
    stopped, one of that name replaced. `exports`: the chained state interfaces it declares."""
    manager: Any = lab.manager  # deploy checked it is there
    sim = lab.sim
    attrs: dict[str, Any] = {"_given": built, "__module__": cls.__module__, "__doc__": cls.__doc__}
    if built.interface != "effort":
        attrs["command_interface"] = built.interface
    if exports:
        attrs["exports"] = dict(exports)
    runner_cls = type(cls.__name__, (cls,), attrs)
    from mexone.control.resolve import Plugin
    from mexone.control.spec import ControllerSpec

    plugin = Plugin(f"mexone/{cls.__name__}", runner_cls, "mexone.design", None, {},
                    {"design_file": ""}, update_rate=rate)
    spec = ControllerSpec(name, plugin.type, tuple(built.joints), plugin=plugin)

    def load() -> _Deployed:
        old = manager.controllers.get(name)
        if old is not None:
            if old.running:
                manager.switch(stop=[name])
            manager.unload(name)
        missing = [j for j in built.joints if j not in manager.hw.robot.joints]
        if missing:
            raise _fail(f"deploy: the design drives joint {missing[0]!r}, which the robot does not have")
        busy = sorted({c.name for c in manager.controllers.values()
                       if c.running and c.name != name and set(c.joints) & set(built.joints)})
        gains: dict[str, PidGains] | None = None
        if built.interface != "effort":  # the model closed the joints' PIDs as set: keep them
            drivers = {j: c for c in manager.controllers.values() if c.name in busy for j in c.joints}
            found = {j: drivers[j].pid_for(j) if j in drivers else None for j in built.joints}
            gains = {j: g for j, g in found.items() if g is not None}
            missing = [j for j in found if j not in gains]
            if missing:
                raise _fail(f"deploy: a {built.interface} design runs through the joints' PIDs, "
                            f"and no running controller gives {missing[0]!r} its gains",
                            hint="start the joint's position controller first, or design on "
                                 "inputs='effort'")
        manager.config.controllers[name] = replace(spec, gains=gains)
        manager.load(name)
        manager.switch(start=[name], stop=busy)
        return cast(_Deployed, manager.controllers[name].impl)

    return sim.work.call(load) if sim.loop_elsewhere() else load()
