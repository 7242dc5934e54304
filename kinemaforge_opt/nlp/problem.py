"""A small NLP builder with named variables, costs and constraints, solved by IPOPT.

Build is separate from solve: a :class:`Problem` can be inspected (``sizes``, ``terms``)
without running IPOPT; :meth:`Problem.solve` returns an immutable :class:`Result` whose
``success`` says whether IPOPT converged (not converging is a state, not an exception) and
which reports every named cost and the worst violation of every named constraint.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ..errors import KinemaforgeError


@dataclass
class _Variable:
    symbol: ca.MX
    lower: np.ndarray
    upper: np.ndarray
    init: np.ndarray


@dataclass(frozen=True)
class Result:
    """An IPOPT solve.  values: variable name -> optimal value (reshaped as declared);
    costs: name -> weighted value at the optimum; violations: constraint name -> max violation."""

    success: bool
    status: str
    iterations: int
    objective: float
    values: dict[str, np.ndarray]
    costs: dict[str, float]
    violations: dict[str, float]
    solve_time_s: float
    stats: dict = field(repr=False, default_factory=dict)

    def violated(self, tol: float = 1e-6) -> list[str]:
        """Names of constraints violated by more than ``tol``."""
        return [n for n, v in self.violations.items() if v > tol]


class Problem:
    """A mutable NLP: ``variable`` / ``add_cost`` / ``add_constraint``, then ``solve``."""

    def __init__(self, name: str):
        self.name = name
        self._vars: dict[str, _Variable] = {}
        self._shapes: dict[str, tuple[int, int]] = {}
        self._costs: dict[str, ca.MX] = {}
        self._constraints: dict[str, tuple[ca.MX, np.ndarray, np.ndarray]] = {}

    # --- declaration ----------------------------------------------------------------------
    def variable(self, name: str, shape: int | tuple[int, int], lower=-np.inf, upper=np.inf, init=0.0) -> ca.MX:
        """Declare a decision variable (column vector or matrix) with bounds and initial guess."""
        if name in self._vars:
            raise KinemaforgeError(f"problem {self.name!r}: variable {name!r} declared twice")
        shape = (shape, 1) if isinstance(shape, int) else tuple(shape)
        sym = ca.MX.sym(name, *shape)
        n = shape[0] * shape[1]
        flat = lambda x: np.broadcast_to(np.asarray(x, dtype=float).reshape(-1, order="F") if np.size(x) == n else np.asarray(x, dtype=float), (n,)).copy()  # noqa: E731
        self._vars[name] = _Variable(sym, flat(lower), flat(upper), flat(init))
        self._shapes[name] = shape
        return sym

    def add_cost(self, name: str, expr: ca.MX, weight: float = 1.0) -> None:
        """Add the scalar ``weight * expr`` to the objective under ``name``."""
        if name in self._costs:
            raise KinemaforgeError(f"problem {self.name!r}: cost {name!r} added twice")
        if expr.numel() != 1:
            raise KinemaforgeError(f"problem {self.name!r}: cost {name!r} must be scalar, got {expr.shape}")
        self._costs[name] = weight * expr

    def add_constraint(self, name: str, expr: ca.MX, lower=0.0, upper=0.0) -> None:
        """Constrain ``lower <= expr <= upper`` (element-wise) under ``name``."""
        if name in self._constraints:
            raise KinemaforgeError(f"problem {self.name!r}: constraint {name!r} added twice")
        e = ca.vec(expr)
        n = e.numel()
        self._constraints[name] = (
            e,
            np.broadcast_to(np.asarray(lower, dtype=float).reshape(-1), (n,)).copy(),
            np.broadcast_to(np.asarray(upper, dtype=float).reshape(-1), (n,)).copy(),
        )

    def set_init(self, name: str, value) -> None:
        """Replace the initial guess of variable ``name``."""
        v = self._vars[name]
        v.init = np.broadcast_to(np.asarray(value, dtype=float).reshape(-1, order="F"), v.init.shape).copy()

    # --- inspection -----------------------------------------------------------------------
    @property
    def terms(self) -> dict[str, list[str]]:
        """Names of the variables, costs and constraints."""
        return {"variables": list(self._vars), "costs": list(self._costs), "constraints": list(self._constraints)}

    @property
    def sizes(self) -> dict[str, int]:
        """Number of scalar decision variables and constraint rows."""
        return {
            "variables": int(sum(v.init.size for v in self._vars.values())),
            "constraints": int(sum(c[0].numel() for c in self._constraints.values())),
        }

    # --- solve ----------------------------------------------------------------------------
    def solve(self, max_iter: int = 500, tol: float = 1e-8, print_level: int = 0, options: dict | None = None) -> Result:
        """Solve with IPOPT (MUMPS).  Returns a :class:`Result` whatever IPOPT's outcome."""
        names = list(self._vars)
        x = ca.vertcat(*[ca.vec(self._vars[n].symbol) for n in names])
        f = sum(self._costs.values(), ca.MX(0))
        cons = list(self._constraints.values())
        g = ca.vertcat(*[c[0] for c in cons]) if cons else ca.MX(0, 1)
        opts = {
            "ipopt.max_iter": max_iter,
            "ipopt.tol": tol,
            "ipopt.print_level": print_level,
            "print_time": False,
            "ipopt.sb": "yes",
        }
        opts.update(options or {})
        solver = ca.nlpsol(self.name, "ipopt", {"x": x, "f": f, "g": g}, opts)
        start = time.perf_counter()
        sol = solver(
            x0=np.concatenate([self._vars[n].init for n in names]),
            lbx=np.concatenate([self._vars[n].lower for n in names]),
            ubx=np.concatenate([self._vars[n].upper for n in names]),
            lbg=np.concatenate([c[1] for c in cons]) if cons else np.zeros(0),
            ubg=np.concatenate([c[2] for c in cons]) if cons else np.zeros(0),
        )
        elapsed = time.perf_counter() - start
        stats = solver.stats()
        xs = sol["x"].full().ravel()
        values, i = {}, 0
        for n in names:
            shape = self._shapes[n]
            size = shape[0] * shape[1]
            values[n] = xs[i : i + size].reshape(shape, order="F")
            if shape[1] == 1:
                values[n] = values[n][:, 0]
            i += size
        evaluate = ca.Function("terms", [x], list(self._costs.values()) + [c[0] for c in cons])
        outs = evaluate(sol["x"])
        outs = outs if isinstance(outs, (list, tuple)) else [outs]
        costs = {n: float(o) for n, o in zip(self._costs, outs[: len(self._costs)])}
        violations = {}
        for (n, (_, lo, hi)), o in zip(self._constraints.items(), outs[len(self._costs) :]):
            val = o.full().ravel()
            violations[n] = float(np.max(np.maximum(lo - val, val - hi), initial=0.0))
        return Result(
            success=bool(stats.get("success", False)),
            status=str(stats.get("return_status", "unknown")),
            iterations=int(stats.get("iter_count", -1)),
            objective=float(sol["f"]),
            values=values,
            costs=costs,
            violations=violations,
            solve_time_s=elapsed,
            stats=dict(stats),
        )
