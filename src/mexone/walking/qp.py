"""One home for solving the stack's QPs: `qpsolvers` with a solver picked by name (daqp by
default: a dense active-set solver, fastest on the small dense QPs walking solves), and one error
when there is no solution."""

from __future__ import annotations

import numpy as np
import qpsolvers

from mexone.errors import InputError

__all__ = ["solve", "Infeasible", "SOLVERS"]

SOLVERS = ("daqp", "proxsuite", "osqp", "quadprog", "piqp", "clarabel")


class Infeasible(RuntimeError):
    """The QP has no solution (or the solver gave up): the caller stops safely and says why."""


def check_solver(name: str) -> str:
    """`name` if qpsolvers has that solver installed, else one line naming those it has."""
    if name not in qpsolvers.available_solvers:
        raise InputError(f"QP solver '{name}' is not installed",
                         hint="installed: " + ", ".join(qpsolvers.available_solvers)
                              + " (pip install qpsolvers[" + name + "])")
    return name


def solve(P: np.ndarray, q: np.ndarray, G: np.ndarray | None = None, h: np.ndarray | None = None,
          A: np.ndarray | None = None, b: np.ndarray | None = None, lb: np.ndarray | None = None,
          ub: np.ndarray | None = None, solver: str = "daqp", what: str = "QP") -> np.ndarray:
    """argmin 1/2 x'Px + q'x  s.t.  Gx <= h, Ax = b, lb <= x <= ub; Infeasible when none (or
    when the problem itself is not finite: a NaN from upstream never reaches the solver)."""
    for name, value in (("cost", P), ("cost", q), ("constraints", G), ("constraints", h),
                        ("constraints", A), ("constraints", b)):
        if value is not None and not np.all(np.isfinite(value)):
            raise Infeasible(f"the {what}'s {name} are not finite (NaN or inf in its inputs)")
    x = qpsolvers.solve_qp(P, q, G, h, A, b, lb, ub, solver=solver)
    if x is None or not np.all(np.isfinite(x)):
        raise Infeasible(f"the {what} has no solution ({solver})")
    return x
