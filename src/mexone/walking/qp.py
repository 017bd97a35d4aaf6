"""One home for solving the stack's QPs: daqp (a dense active-set solver, the fastest on the
small dense QPs walking solves) called directly, with two-sided rows; any other solver
`qpsolvers` has by name; one error when there is no solution.

Directly rather than through `qpsolvers.solve_qp`: at 500 Hz the wrapper's checks and copies
cost as much as daqp's solve itself. No warm start: daqp's work on these QPs is its set-up (the
factorisation); its active-set iterations are one to three, so starting from the last active
set saved nothing (benchmarks/RESULTS.md, the walking stack)."""

from __future__ import annotations

import math
from typing import Any

import daqp
import numpy as np
import qpsolvers

from mexone.errors import InputError

__all__ = ["solve", "Infeasible", "SOLVERS"]

SOLVERS = ("daqp", "proxqp", "osqp", "quadprog", "piqp", "clarabel")
_INF = 1e30  # daqp's infinity
_EQUALITY = 5  # daqp's constraint sense for an equality


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
          ub: np.ndarray | None = None, solver: str = "daqp", what: str = "QP",
          G_low: np.ndarray | None = None) -> np.ndarray:
    """argmin 1/2 x'Px + q'x  s.t.  G_low <= Gx <= h, Ax = b, lb <= x <= ub (G_low: -inf when
    None); Infeasible when none (or when the problem itself is not finite: a NaN from upstream
    never reaches the solver)."""
    for name, value, bound in (("cost", P, False), ("cost", q, False), ("constraints", G, False),
                               ("constraints", h, True), ("constraints", A, False),
                               ("constraints", b, False), ("constraints", G_low, True)):
        # a bound may be infinite (that side is free), never NaN; nothing else may be either (a
        # sum is NaN or infinite when an element is: one pass, no temporary array)
        if value is not None:
            total = float(value.sum())
            if math.isnan(total) or (not bound and math.isinf(total)):
                raise Infeasible(f"the {what}'s {name} are not finite (NaN or inf in its inputs)")
    if solver == "daqp":
        x = _daqp(P, q, G, h, A, b, lb, ub, G_low)
    else:
        if G is not None:  # one-sided rows, the infinite sides left out
            assert h is not None, "G without h"
            up, down = np.isfinite(h), np.zeros(len(h), dtype=np.bool_)
            if G_low is not None:
                down = np.isfinite(G_low)
            G = np.vstack([G[up], -G[down]])
            h = np.concatenate([h[up], -G_low[down]]) if G_low is not None else h[up]
        x = qpsolvers.solve_qp(P, q, G, h, A, b, lb, ub, solver=solver)
    if x is None or not np.all(np.isfinite(x)):
        raise Infeasible(f"the {what} has no solution ({solver})")
    return x


def _daqp(P: np.ndarray, q: np.ndarray, G: Any, h: Any, A: Any, b: Any, lb: np.ndarray | None,
          ub: np.ndarray | None, G_low: np.ndarray | None) -> np.ndarray | None:
    # G, h and A, b: arrays when their counts (mg, me) are not 0
    n = q.shape[0]
    mg = 0 if G is None else G.shape[0]
    me = 0 if A is None else A.shape[0]
    boxed = lb is not None or ub is not None
    ms = n if boxed else 0
    upper = np.empty(ms + mg + me)
    lower = np.empty(ms + mg + me)
    if boxed:
        upper[:n] = _INF if ub is None else np.minimum(ub, _INF)
        lower[:n] = -_INF if lb is None else np.maximum(lb, -_INF)
    if mg:
        upper[ms:ms + mg] = np.minimum(h, _INF)
        lower[ms:ms + mg] = -_INF if G_low is None else G_low
    if me:
        upper[ms + mg:] = lower[ms + mg:] = b
    rows = np.vstack([G, A]) if mg and me else G if mg else A if me else np.zeros((0, n))
    if np.any(lower > upper):  # contradictory bounds: daqp would not say so
        return None
    rows = np.ascontiguousarray(rows)
    sense = np.zeros(ms + mg + me, dtype=np.intc)
    if boxed:  # a fixed variable (lb == ub) is an equality: daqp keeps it active
        sense[:n][upper[:n] == lower[:n]] = _EQUALITY
    sense[ms + mg:] = _EQUALITY
    x, _, flag, _ = daqp.solve(P, q, rows, upper, lower, sense)
    return x if flag > 0 else None
