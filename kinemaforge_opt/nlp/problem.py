"""A small NLP builder with named variables, parameters, costs and constraints, solved by IPOPT.

Build is separate from solve: a :class:`Problem` can be inspected (``sizes``, ``terms``)
without running IPOPT; :meth:`Problem.solve` returns an immutable :class:`Result` whose
``success`` says whether IPOPT converged (not converging is a state, not an exception) and
which reports every named cost and the worst violation of every named constraint.

Parameters are data the expressions read (IPOPT's ``p``) without fitting them.  A loop that
builds the same problem again around new data (refreshed correspondences, a new starting point)
solves through a :class:`SolverCache`: the IPOPT solver and its derivatives are built on the
first build only, the later ones pass their own parameters, bounds and guesses to it.
"""

from __future__ import annotations

import time
from collections.abc import Callable
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
    costs: name -> weighted value at the optimum; violations: constraint name -> max violation.
    lam_x, lam_g: the bound and constraint multipliers at the last iterate (the warm start of a
    continuation, :meth:`Problem.solve`)."""

    success: bool
    status: str
    iterations: int
    objective: float
    values: dict[str, np.ndarray]
    costs: dict[str, float]
    violations: dict[str, float]
    solve_time_s: float
    stats: dict = field(repr=False, default_factory=dict)
    lam_x: np.ndarray | None = field(repr=False, default=None)
    lam_g: np.ndarray | None = field(repr=False, default=None)

    @property
    def final_mu(self) -> float:
        """IPOPT's barrier parameter at the last iterate (NaN when the stats do not hold it)."""
        mu = self.stats.get("iterations", {}).get("mu", [])
        return float(mu[-1]) if len(mu) else float("nan")

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
        self._parameters: dict[str, tuple[ca.MX, np.ndarray]] = {}

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

    def parameter(self, name: str, value) -> ca.MX:
        """Declare a parameter: a symbol of ``value``'s shape (a vector or a matrix) that the
        solve gives ``value``; its cost and constraint values are reported at that value."""
        if name in self._parameters or name in self._vars:
            raise KinemaforgeError(f"problem {self.name!r}: {name!r} declared twice")
        value = np.atleast_1d(np.asarray(value, dtype=float))
        shape = (value.size, 1) if value.ndim == 1 else value.shape
        if len(shape) != 2:
            raise KinemaforgeError(f"problem {self.name!r}: parameter {name!r} must be a vector or a matrix, got shape {value.shape}")
        sym = ca.MX.sym(name, *shape)
        self._parameters[name] = (sym, value.reshape(-1, order="F").copy())
        return sym

    def add_cost(self, name: str, expr: ca.MX, weight: float | ca.MX = 1.0) -> None:
        """Add the scalar ``weight * expr`` to the objective under ``name`` (``weight``: a number
        or an expression of parameters)."""
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
    def initial(self, name: str) -> np.ndarray:
        """The initial guess of variable ``name``, in its declared shape."""
        return self._vars[name].init.reshape(self._shapes[name], order="F").copy()

    @property
    def terms(self) -> dict[str, list[str]]:
        """Names of the variables, costs and constraints."""
        return {"variables": list(self._vars), "costs": list(self._costs), "constraints": list(self._constraints)}

    @property
    def parameters(self) -> dict[str, np.ndarray]:
        """Parameter name -> its value (flattened column-major)."""
        return {n: v.copy() for n, (_, v) in self._parameters.items()}

    def structure(self) -> tuple:
        """What a compiled solver of this problem depends on besides the values of its
        parameters, bounds and guesses (and the constants its expressions hold): the names and
        shapes of its variables, parameters and constraints and the names of its costs."""
        return (tuple((n, self._shapes[n]) for n in self._vars),
                tuple((n, s.shape) for n, (s, _) in self._parameters.items()),
                tuple((n, c[0].numel()) for n, c in self._constraints.items()), tuple(self._costs))

    @property
    def sizes(self) -> dict[str, int]:
        """Number of scalar decision variables and constraint rows."""
        return {
            "variables": int(sum(v.init.size for v in self._vars.values())),
            "constraints": int(sum(c[0].numel() for c in self._constraints.values())),
        }

    def layout(self) -> tuple[dict[str, slice], dict[str, slice]]:
        """Where each variable sits in the decision vector x and each constraint in g (the
        declaration order the solver uses): (variable name -> slice, constraint name -> slice)."""
        xs, i = {}, 0
        for n, v in self._vars.items():
            xs[n] = slice(i, i + v.init.size)
            i += v.init.size
        gs, j = {}, 0
        for n, c in self._constraints.items():
            gs[n] = slice(j, j + c[0].numel())
            j += c[0].numel()
        return xs, gs

    def symbol(self, name: str) -> ca.MX:
        """The symbol of variable ``name``."""
        return self._vars[name].symbol

    # --- solve ----------------------------------------------------------------------------
    def compile(self, max_iter: int = 500, tol: float = 1e-8, print_level: int = 0, options: dict | None = None,
                on_iteration: Callable[[int, float], None] | None = None) -> "CompiledProblem":
        """Build the IPOPT solver once (casadi ``nlpsol``); the returned :class:`CompiledProblem`
        solves it many times with other bounds, initial guesses or constraint bounds.  Variables
        fixed by equal bounds are removed by IPOPT (``fixed_variable_treatment=make_parameter``),
        so one compiled problem serves every subset of free parameters."""
        return CompiledProblem(self, max_iter, tol, print_level, options, on_iteration)

    def solve(self, max_iter: int = 500, tol: float = 1e-8, print_level: int = 0, options: dict | None = None,
              warm: Result | None = None, on_iteration: Callable[[int, float], None] | None = None) -> Result:
        """Solve with IPOPT (MUMPS).  Returns a :class:`Result` whatever IPOPT's outcome.

        on_iteration: called after every IPOPT iteration with (iteration, objective) (e.g. to
        move a progress bar).

        warm: the result of an earlier solve of a problem of the same layout (its last iterate
        is this problem's initial guess): IPOPT starts from its multipliers and barrier parameter
        instead of restarting the barrier at ``mu_init`` — a restart pushes every bounded variable
        back into the interior and can undo hundreds of iterations' progress."""
        if warm is not None and warm.lam_x is not None and np.isfinite(warm.final_mu):
            options = {**(options or {}), "ipopt.warm_start_init_point": "yes", "ipopt.mu_init": warm.final_mu,
                       "ipopt.warm_start_bound_push": 1e-9, "ipopt.warm_start_mult_bound_push": 1e-9}
            return self.compile(max_iter, tol, print_level, options, on_iteration).solve(multipliers=(warm.lam_x, warm.lam_g))
        return self.compile(max_iter, tol, print_level, options, on_iteration).solve()


class CompiledProblem:
    """A :class:`Problem` with its IPOPT solver built: ``solve`` may be called repeatedly with
    per-variable overrides of ``init``, ``lower`` and ``upper`` (name -> value, shaped like the
    variable) and per-constraint overrides of its bounds (``constraint_bounds``: name ->
    (lower, upper)).  Build cost (symbolic derivatives) is paid once."""

    def __init__(self, problem: Problem, max_iter: int, tol: float, print_level: int, options: dict | None,
                 on_iteration: Callable[[int, float], None] | None = None):
        self.problem = problem
        self.names = list(problem._vars)
        x = ca.vertcat(*[ca.vec(problem._vars[n].symbol) for n in self.names])
        p = ca.vertcat(*[ca.vec(s) for s, _ in problem._parameters.values()]) if problem._parameters else ca.MX(0, 1)
        f = sum(problem._costs.values(), ca.MX(0))
        cons = list(problem._constraints.values())
        g = ca.vertcat(*[c[0] for c in cons]) if cons else ca.MX(0, 1)
        opts = {
            "ipopt.max_iter": max_iter,
            "ipopt.tol": tol,
            "ipopt.print_level": print_level,
            "print_time": False,
            "ipopt.sb": "yes",
        }
        opts.update(options or {})
        if on_iteration is not None:  # kept on self: CasADi holds no reference to the Python object
            self._hook = _IterationHook(x.numel(), g.numel(), p.numel(), on_iteration)
            opts["iteration_callback"] = self._hook
        self.solver = ca.nlpsol(problem.name, "ipopt", {"x": x, "p": p, "f": f, "g": g}, opts)
        self.evaluate = ca.Function("terms", [x, p], list(problem._costs.values()) + [c[0] for c in cons])
        self._slices, self._gslices = problem.layout()
        self._structure = problem.structure()

    def _vector(self, source: Problem, attr: str, override: dict | None) -> np.ndarray:
        out = np.concatenate([getattr(source._vars[n], attr) for n in self.names]) if self.names else np.zeros(0)
        for n, value in (override or {}).items():
            if n not in self._slices:
                raise KinemaforgeError(f"problem {self.problem.name!r}: no variable {n!r}; variables: {', '.join(self.names)}")
            sl = self._slices[n]
            out[sl] = np.broadcast_to(np.asarray(value, dtype=float).reshape(-1, order="F"), (sl.stop - sl.start,))
        return out

    def solve(self, init: dict | None = None, lower: dict | None = None, upper: dict | None = None,
              constraint_bounds: dict | None = None, multipliers: tuple[np.ndarray, np.ndarray] | None = None,
              source: Problem | None = None) -> Result:
        """Solve from the declared guesses, bounds and parameter values, with the given
        overrides; ``multipliers``: initial (lam_x, lam_g) (with IPOPT's
        ``warm_start_init_point``).  ``source``: a problem of the same :meth:`Problem.structure`,
        built again around other data, whose guesses, bounds and parameter values are solved
        instead of the compiled problem's (:class:`SolverCache`)."""
        problem = self.problem if source is None else source
        if source is not None and source.structure() != self._structure:
            raise KinemaforgeError(f"problem {problem.name!r}: its structure differs from the compiled problem's")
        cons = problem._constraints
        lbg = np.concatenate([c[1] for c in cons.values()]) if cons else np.zeros(0)
        ubg = np.concatenate([c[2] for c in cons.values()]) if cons else np.zeros(0)
        for n, (lo, hi) in (constraint_bounds or {}).items():
            if n not in self._gslices:
                raise KinemaforgeError(f"problem {problem.name!r}: no constraint {n!r}; constraints: {', '.join(cons)}")
            lbg[self._gslices[n]], ubg[self._gslices[n]] = lo, hi
        start = time.perf_counter()
        warm = {} if multipliers is None else {"lam_x0": multipliers[0], "lam_g0": multipliers[1]}
        p = np.concatenate([v for _, v in problem._parameters.values()]) if problem._parameters else np.zeros(0)
        sol = self.solver(x0=self._vector(problem, "init", init), lbx=self._vector(problem, "lower", lower),
                          ubx=self._vector(problem, "upper", upper), lbg=lbg, ubg=ubg, p=p, **warm)
        elapsed = time.perf_counter() - start
        stats = self.solver.stats()
        xs = sol["x"].full().ravel()
        values = {}
        for n in self.names:
            shape = problem._shapes[n]
            values[n] = xs[self._slices[n]].reshape(shape, order="F")
            if shape[1] == 1:
                values[n] = values[n][:, 0]
        outs = self.evaluate(sol["x"], p)
        outs = outs if isinstance(outs, (list, tuple)) else [outs]
        costs = {n: float(o) for n, o in zip(problem._costs, outs[: len(problem._costs)])}
        violations = {}
        for n, o in zip(cons, outs[len(problem._costs) :]):
            val = o.full().ravel()
            sl = self._gslices[n]
            violations[n] = float(np.max(np.maximum(lbg[sl] - val, val - ubg[sl]), initial=0.0))
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
            lam_x=sol["lam_x"].full().ravel(),
            lam_g=sol["lam_g"].full().ravel(),
        )


class SolverCache:
    """IPOPT solvers reused across problems built again with the same structure (a loop that
    rebuilds its problem around refreshed data): building the solver and its derivatives costs
    more than solving a small problem (~20 ms against ~12 ms for the screw NLP's 37-variable
    visual rounds).

    The builder names what its expressions hold as constants in ``key``: two problems may share a
    solver only if they have the same key, the same :meth:`Problem.structure` and the same solver
    options; everything else that varies must be a parameter, a bound or a guess."""

    def __init__(self):
        self._solvers: dict[tuple, CompiledProblem] = {}

    def __len__(self) -> int:
        """The number of solvers built."""
        return len(self._solvers)

    def solve(self, problem: Problem, key: tuple, max_iter: int = 500, tol: float = 1e-8,
              options: dict | None = None) -> Result:
        """Solve ``problem`` (as :meth:`Problem.solve`, cold) with the solver built for the
        first problem of this ``key``, structure and options, building it if there is none."""
        opts = tuple(sorted((options or {}).items()))
        for name, value in opts:
            if not isinstance(value, (str, int, float, bool)):
                raise KinemaforgeError(f"solver option {name!r} holds a {type(value).__name__}: only plain values can key a cached solver")
        full = (key, problem.structure(), max_iter, tol, opts)
        if full not in self._solvers:
            self._solvers[full] = problem.compile(max_iter, tol, 0, options)
        return self._solvers[full].solve(source=problem)


class _IterationHook(ca.Callback):
    """CasADi's ``iteration_callback``: IPOPT calls it after each iteration with nlpsol's outputs
    (x, f, g, lam_x, lam_g, lam_p); it passes (iteration, objective) on and returns 0 (go on)."""

    def __init__(self, nx: int, ng: int, np_: int, report: Callable[[int, float], None]):
        ca.Callback.__init__(self)
        self._nx, self._ng, self._np, self._report, self._iteration = nx, ng, np_, report, 0
        self.construct("iteration_hook", {})

    def get_n_in(self):
        return ca.nlpsol_n_out()

    def get_n_out(self):
        return 1

    def get_name_in(self, i):
        return ca.nlpsol_out(i)

    def get_name_out(self, i):
        return "ret"

    def get_sparsity_in(self, i):
        n = {"x": self._nx, "f": 1, "g": self._ng, "lam_x": self._nx, "lam_g": self._ng, "lam_p": self._np}[ca.nlpsol_out(i)]
        return ca.Sparsity.dense(n, 1)

    def eval(self, arg):
        self._report(self._iteration, float(arg[1]))
        self._iteration += 1
        return [0]
