"""control_toolbox::Pid, vectorised over joints (ROS Kinetic semantics, line for line).

    p_term = p * e
    i_error += dt * e;  antiwindup: i_error clamped to [i_min/i, i_max/i]
    i_term  = i * i_error;  no antiwindup: i_term clamped to [i_min, i_max]
    d_term  = d * de/dt   (de/dt given, or (e - e_last) / dt)
    cmd     = p_term + i_term + d_term

With i_min = i_max = 0 (the default) there is no integral action at all, as in ROS.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from mexone.control.spec import PidGains

__all__ = ["PidArray"]


class PidArray:
    """control_toolbox's PID for several joints at once, as arrays (the velocity controllers'
    terms that do not run in MuJoCo's actuators)."""

    def __init__(self, gains: Sequence[PidGains]) -> None:
        self.p = np.array([g.p for g in gains], dtype=float)
        self.i = np.array([g.i for g in gains], dtype=float)
        self.d = np.array([g.d for g in gains], dtype=float)
        self.i_min = np.array([g.i_clamp_min for g in gains], dtype=float)
        self.i_max = np.array([g.i_clamp_max for g in gains], dtype=float)
        self.antiwindup = np.array([g.antiwindup for g in gains], dtype=bool)
        self.i_error = np.zeros(len(gains))
        self.last_error = np.zeros(len(gains))

    @property
    def integrates(self) -> bool:
        """Whether any joint can ever get integral action (needs a per-step update)."""
        return bool(np.any((self.i != 0) & ((self.i_min != 0) | (self.i_max != 0))))

    def reset(self) -> None:
        """Forget the integral and the last error (a controller starting)."""
        self.i_error[:] = 0.0
        self.last_error[:] = 0.0

    def integral(self, error: np.ndarray, dt: float, rows: np.ndarray | slice = slice(None)
                 ) -> np.ndarray:
        """Advance the integral of `rows` (all by default) by one period; return their i_term."""
        i, lo_c, hi_c, aw = self.i[rows], self.i_min[rows], self.i_max[rows], self.antiwindup[rows]
        i_error = self.i_error[rows] + dt * error
        wind = aw & (i != 0)
        if wind.any():
            with np.errstate(divide="ignore", invalid="ignore"):
                a, b = lo_c / i, hi_c / i
            i_error = np.where(wind, np.clip(i_error, np.minimum(a, b), np.maximum(a, b)), i_error)
        self.i_error[rows] = i_error
        i_term = i * i_error
        return np.where(aw, i_term, np.clip(i_term, lo_c, hi_c))

    def error_rate(self, error: np.ndarray, dt: float) -> np.ndarray:
        """(e - e_last) / dt, the derivative computeCommand(error, dt) uses."""
        rate = (error - self.last_error) / dt
        self.last_error = error.copy()
        return rate

    def command(self, error: np.ndarray, error_dot: np.ndarray | None, dt: float) -> np.ndarray:
        """The full control_toolbox command (reference implementation for tests and users)."""
        rate = self.error_rate(error, dt) if error_dot is None else error_dot
        if error_dot is not None:
            self.last_error = error.copy()
        return self.p * error + self.integral(error, dt) + self.d * rate
