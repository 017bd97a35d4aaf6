"""One home for solving the stack's QPs: daqp (a dense active-set solver, the fastest on the
small dense QPs walking solves) called directly, with two-sided rows and a warm start from the
last solve's active set; any other solver `qpsolvers` has by name; one error when there is no
solution.

Directly rather than through `qpsolvers.solve_qp`: at 500 Hz the wrapper's checks and copies
cost as much as daqp's solve itself (benchmarks/RESULTS.md, the walking stack)."""

from __future__ import annotations

import math

import daqp
import numpy as np
import qpsolvers

from mexone.errors import InputError

__all__ = ["solve", "Infeasible", "WarmStart", "SOLVERS"]

SOLVERS = ("daqp", "proxsuite", "osqp", "quadprog", "piqp", "clarabel")
_INF = 1e30  # daqp's infinity
_ACTIVE, _LOWER, _EQUALITY = 1, 2, 5  # daqp's constraint senses


class Infeasible(RuntimeError):
    """The QP has no solution (or the solver gave up): the caller stops safely and says why."""


class WarmStart:
    """The active set of a problem's last solve (daqp): the next solve of a problem of the same
    shape starts from it (a walking QP's active set changes little from one update to the next).
    One per problem that is solved again and again."""

    __slots__ = ("sense",)

    def __init__(self) -> None:
        self.sense: np.ndarray | None = None


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
          G_low: np.ndarray | None = None, warm: WarmStart | None = None) -> np.ndarray:
    """argmin 1/2 x'Px + q'x  s.t.  G_low <= Gx <= h, Ax = b, lb <= x <= ub (G_low: -inf when
    None); Infeasible when none (or when the problem itself is not finite: a NaN from upstream
    never reaches the solver). `warm`: daqp starts from (and keeps) the last active set."""
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
        x = _daqp(P, q, G, h, A, b, lb, ub, G_low, warm)
    else:
        if G is not None:  # one-sided rows, the infinite sides left out
            up, down = np.isfinite(h), np.zeros(len(h), dtype=bool)
            if G_low is not None:
                down = np.isfinite(G_low)
            G = np.vstack([G[up], -G[down]])
            h = np.concatenate([h[up], -G_low[down]]) if G_low is not None else h[up]
        x = qpsolvers.solve_qp(P, q, G, h, A, b, lb, ub, solver=solver)
    if x is None or not np.all(np.isfinite(x)):
        raise Infeasible(f"the {what} has no solution ({solver})")
    return x


def _daqp(P, q, G, h, A, b, lb, ub, G_low, warm: WarmStart | None) -> np.ndarray | None:
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
    cold = np.zeros(ms + mg + me, dtype=np.intc)
    if boxed:  # a fixed variable (lb == ub) is an equality: daqp keeps it active
        cold[:n][upper[:n] == lower[:n]] = _EQUALITY
    cold[ms + mg:] = _EQUALITY
    sense = cold
    if warm is not None and warm.sense is not None and warm.sense.shape == cold.shape:
        sense = np.where(cold == _EQUALITY, cold, warm.sense).astype(np.intc)
    x, _, flag, info = daqp.solve(P, q, rows, upper, lower, sense)
    if flag <= 0 and sense is not cold:  # the last active set misled it: from scratch
        x, _, flag, info = daqp.solve(P, q, rows, upper, lower, cold)
    if flag <= 0:
        if warm is not None:
            warm.sense = None
        return None
    if warm is not None:
        lam = info["lam"]
        start = np.where(lam > 0, _ACTIVE, np.where(lam < 0, _ACTIVE | _LOWER, 0)).astype(np.intc)
        start[sense == _EQUALITY] = 0
        warm.sense = start
    return x
