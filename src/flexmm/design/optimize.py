"""``flexmm design SPEC.yaml``: optimise design variables of a scene for an objective of its run.

The spec holds a scene (file or inline), the design variables (``variables.Variable`` with
bounds), the objective (``objectives.Term`` list, a weighted sum) and optional constraints
(``total_mass``: the lattice's total mass; ``mean``: the mean over the units of the values a
variable writes — e.g. a stiffness field held at its start's mean, so the design is compared with
the uniform lattice at equal mean stiffness — each equal to, or at most/least, its start value or
a given one). Every evaluation is one run with the scene's integrator (velocity Verlet, PEFRL,
BM6 or implicit midpoint: ``gradient.DIFFERENTIABLE``) with checkpoints plus one adjoint sweep
(``gradient.Trajectory.gradient``), chained through the variables' map to the raw arrays. The
optimiser is scipy's L-BFGS-B (bounds only), SLSQP (with only linear, ``mean``, constraints: every
iterate keeps them), L-BFGS-B on values projected onto equal-mean constraints and the bounds
(``MeanProjection``; the default above 100 values, e.g. one per hinge, where SLSQP's dense steps
get slow) or trust-constr (with a total-mass constraint), on variables scaled by their start
values. Each evaluation is appended to a history (an xarray dataset, ``history.nc``, rewritten
atomically); ``resume`` restarts from the best design in it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Literal

import numpy as np
from pydantic import Field, model_validator

from flexmm.assemble import build_problem
from flexmm.config.base import Positive, Strict
from flexmm.config.loader import ConfigError, ConfigIssue
from flexmm.design.gradient import Trajectory, check_differentiable
from flexmm.design.objectives import Objective, Term, bind_terms
from flexmm.design.spec import load_spec, scene_data_of
from flexmm.design.variables import (
    Design,
    Variable,
    VariableError,
    element_values,
    finite_difference,
    worst_relative_error,
)


class Constraint(Strict):
    """The total mass of the lattice's units (kg), or the mean over the units of a ``variable``'s
    values (its SI unit): ``relation`` to ``value`` (default its start value)."""

    kind: Literal["total_mass", "mean"]
    relation: Literal["equal", "at_most", "at_least"] = "equal"
    value: Positive | None = None
    variable: str | None = Field(None, description="mean: the name of the variable")

    @model_validator(mode="after")
    def _variable(self):
        if (self.kind == "mean") != (self.variable is not None):
            raise ValueError("kind mean needs variable (the name of a design variable), and only mean takes one")
        return self

    @property
    def linear(self) -> bool:
        """A mean, linear in the variables (the total mass is not)."""
        return self.variable is not None


class OptimizerOptions(Strict):
    max_iterations: int = Field(40, ge=1, le=10_000)
    mean_method: Literal["auto", "slsqp", "projection"] = Field("auto", description=(
        "with only mean constraints, all equal: SLSQP, or L-BFGS-B on values projected onto the "
        "constraints and bounds (auto: projection above 100 values, where SLSQP's dense steps get slow)"))
    tolerance: Positive = Field(1e-8, lt=1)
    sample_every: int = Field(1, ge=1, description="record the objective's DOFs every this many steps")


class DesignSpec(Strict):
    name: str = Field(pattern=r"^[A-Za-z0-9][A-Za-z0-9_.\-]*$")
    description: str = ""
    scene: str | dict
    variables: list[Variable] = Field(min_length=1)
    objective: list[Term] = Field(min_length=1)
    constraints: list[Constraint] = Field(default_factory=list)
    optimizer: OptimizerOptions = Field(default_factory=OptimizerOptions)


@dataclass
class History:
    """Every evaluation: variables (SI), objective (normalised), terms (SI), gradient norm."""

    labels: list[str]
    term_names: list[str]
    x: list[np.ndarray] = field(default_factory=list)
    objective: list[float] = field(default_factory=list)
    terms: list[list[float]] = field(default_factory=list)
    gradient_norm: list[float] = field(default_factory=list)

    def add(self, x, value, terms, gnorm) -> None:
        self.x.append(np.array(x, float))
        self.objective.append(float(value))
        self.terms.append(list(terms))
        self.gradient_norm.append(float(gnorm))

    @property
    def best(self) -> int:
        return int(np.argmin(self.objective))

    def dataset(self):
        import xarray as xr

        n = len(self.objective)
        return xr.Dataset(
            {"x": (("evaluation", "variable"), np.array(self.x).reshape(n, len(self.labels)),
                   {"units": "SI (per variable)", "long_name": "design variables"}),
             "objective": ("evaluation", np.array(self.objective), {"units": "1", "long_name":
                           "weighted objective (terms over their start values)"}),
             "term": (("evaluation", "term_name"), np.array(self.terms).reshape(n, len(self.term_names)),
                      {"units": "SI (per term)", "long_name": "objective terms"}),
             "gradient_norm": ("evaluation", np.array(self.gradient_norm),
                               {"units": "1", "long_name": "norm of the gradient in scaled variables"})},
            coords={"evaluation": np.arange(n), "variable": self.labels, "term_name": self.term_names})

    @classmethod
    def from_dataset(cls, ds) -> History:
        h = cls([str(v) for v in ds["variable"].values], [str(t) for t in ds["term_name"].values])
        for k in range(ds.sizes["evaluation"]):
            h.add(ds["x"].values[k], ds["objective"].values[k], ds["term"].values[k], ds["gradient_norm"].values[k])
        return h


class DesignProblem:
    """A design spec made concrete: variables, the run, the objective."""

    def __init__(self, spec: DesignSpec, spec_path: str | Path, base_dir: Path):
        self.spec = spec
        data, source, where = scene_data_of(spec.scene, spec_path, base_dir)
        names = [v.name for v in spec.variables]
        for k, c in enumerate(spec.constraints):
            if c.linear and c.variable not in names:
                raise ConfigError([ConfigIssue(str(spec_path), None, f"constraints[{k}].variable",
                                               f"no variable {c.variable!r} (the variables are {', '.join(names)})")])
        self._mean_weights: dict[str, np.ndarray] = {}
        try:
            self.design = Design(data, spec.variables, where, source)
        except VariableError as err:
            raise ConfigError([ConfigIssue(str(spec_path), None, f"variables[{err.index}].{err.field}",
                                           err.detail)]) from None
        #: each constraint's target (its value, or its start value), computed once
        self.targets = [c.value if c.value is not None else self.constraint_value(c, self.design.x0)
                        for c in spec.constraints]
        for k, (c, target) in enumerate(zip(spec.constraints, self.targets)):
            if not target > 0:  # the constraints are scaled by their targets
                raise ConfigError([ConfigIssue(str(spec_path), None, f"constraints[{k}]", (
                    f"the start mean of variable {c.variable!r} is {target:g}; a mean constraint needs a positive "
                    "target (give a positive value, or start the variable at a positive mean)")
                    if c.linear else f"the start total mass is {target:g} kg; it must be positive")])
        self.problem = build_problem(self.design.scene(self.design.x0))
        s = self.problem.system
        check_differentiable(s, self.problem.terms)
        bound, obs = bind_terms(spec.objective, s)
        stride = spec.optimizer.sample_every
        nsteps = stride * max(1, math.ceil(self.problem.duration / self.problem.dt / stride - 1e-9))
        self.traj = Trajectory(s.args, self.problem.terms, self.problem.dt, nsteps, stride, obs,
                               integrator=self.problem.scene.solver.integrator)
        self.objective = Objective(bound, self.traj.times * s.scales.time_s)
        rec, _ = self.traj.run(self.design.raw(self.design.x0))
        self.objective.normalise(rec, self.design.raw(self.design.x0))
        self.term_names = [f"{t.kind}[{k}]" for k, t in enumerate(spec.objective)]

    def evaluate(self, x: np.ndarray) -> tuple[float, np.ndarray, list[float]]:
        """(objective, gradient w.r.t. x, terms in SI) by one run and one adjoint sweep."""
        raw = self.design.raw(x)
        value, graw, _ = self.traj.gradient(raw, self.objective)
        return value, self.design.chain(x, graw, raw), list(self.objective.last)

    def value(self, x: np.ndarray) -> float:
        return self.traj.value(self.design.raw(x), self.objective)

    def records(self, x: np.ndarray):
        rec, _ = self.traj.run(self.design.raw(x))
        return rec

    def total_mass(self, x: np.ndarray) -> float:
        s = self.design.build(x)[0]
        k = s.field_index(s.longitudinal_field) * s.n_sites
        return float(s.mass[k : k + s.n_sites].sum() * s.scales.mass_kg)

    def mass_gradient(self, x: np.ndarray) -> np.ndarray:
        return np.array([finite_difference(self.total_mass, x, k, rel_steps=(1e-4, 1e-5, 1e-6)) for k in range(x.size)])

    def mean_weights(self, name: str) -> np.ndarray:
        """w with mean = w · x: the mean over the units of the values the variable writes (linear in them)."""
        des = self.design
        k = [v.name for v in des.variables].index(name)
        var = des.variables[k]
        start = int(np.sum(des.sizes[:k]))
        if name in self._mean_weights:
            return self._mean_weights[name]
        w = np.zeros(des.x0.size)
        if var.profile == "each":  # the mean over the elements
            w[start : start + var.size] = 1.0 / var.size
        for j in range(var.size if var.profile != "each" else 0):
            unit = np.eye(var.size)[j]
            w[start + j] = unit[0] if var.path is not None else element_values(des.base["lattice"], var, unit).mean()
        self._mean_weights[name] = w
        return w

    def constraint_value(self, c: Constraint, x: np.ndarray) -> float:
        return float(self.mean_weights(c.variable) @ x) if c.linear else self.total_mass(x)


@dataclass
class DesignResult:
    x: np.ndarray
    best: int  # its evaluation in the history
    history: History
    message: str


class MeanProjection:
    """The Euclidean projection of values onto their variables' mean constraints (w·x = m, all
    equal) and bounds: x = clip(z + τ w, lo, hi) per constrained variable, τ the root of the
    (nondecreasing, w ≥ 0) constraint; and its transpose Jacobian (on the unclipped values F:
    I − w_F w_Fᵀ/(w_F·w_F), zero on the clipped ones). L-BFGS-B on z then keeps every evaluated
    design on the constraints exactly (to rounding), at O(n) per step."""

    def __init__(self, dp: DesignProblem):
        self.lo, self.hi = dp.design.bounds
        self.rows = []  # (indices, weights, target)
        for c, target in zip(dp.spec.constraints, dp.targets):
            w = dp.mean_weights(c.variable)
            idx = np.flatnonzero(w)
            self.rows.append((idx, w[idx], target))

    def __call__(self, z: np.ndarray) -> tuple[np.ndarray, list]:
        x = np.clip(np.asarray(z, float), self.lo, self.hi)
        free = []
        for idx, w, m in self.rows:
            zi, lo, hi = z[idx], self.lo[idx], self.hi[idx]

            def excess(t, w=w, zi=zi, lo=lo, hi=hi, m=m):
                return float(w @ np.clip(zi + t * w, lo, hi)) - m

            with np.errstate(invalid="ignore", divide="ignore"):
                a = float(np.nanmin(np.where(w > 0, (lo - zi) / w, np.nan)))  # every value at its low bound
                b = float(np.nanmax(np.where(w > 0, (hi - zi) / w, np.nan)))  # ... at its high bound
            if not (np.isfinite(a) and np.isfinite(b)):  # unbounded: the plain shift, refined below
                t = (m - w @ zi) / (w @ w)
            elif excess(a) < 0 < excess(b):
                from scipy.optimize import brentq

                t = brentq(excess, a, b, xtol=1e-300, rtol=4 * np.finfo(float).eps)
            else:  # the target is at (or beyond) what the bounds allow
                t = a if excess(a) >= 0 else b
            xi = np.clip(zi + t * w, lo, hi)
            f = (xi > lo) & (xi < hi)
            if f.any():  # the exact τ on the free set, so the mean holds to rounding
                t = (m - w[~f] @ xi[~f] - w[f] @ zi[f]) / (w[f] @ w[f])
                xi[f] = zi[f] + t * w[f]
            x[idx] = xi
            free.append(f)
        return x, free

    def pullback(self, g: np.ndarray, z: np.ndarray, free: list) -> np.ndarray:
        """dJ/dz from dJ/dx at x = projection(z)."""
        out = np.array(g, float)  # unconstrained values: x = z inside the bounds
        for (idx, w, _), f in zip(self.rows, free):
            gi = np.zeros(idx.size)
            wf = w[f]
            gi[f] = g[idx][f] - wf * (wf @ g[idx][f]) / (wf @ wf) if f.any() else 0.0
            out[idx] = gi
        return out


def optimise(dp: DesignProblem, history: History | None = None, on_eval: Callable | None = None,
             save: Callable[[History], None] | None = None) -> DesignResult:
    """Minimise the objective from the start values (or the best design of ``history``)."""
    from scipy.optimize import Bounds, LinearConstraint, NonlinearConstraint, minimize

    des = dp.design
    hist = history or History(des.labels, dp.term_names)
    x_start = hist.x[hist.best] if hist.x else des.x0
    scale = np.where(des.x0 != 0, np.abs(des.x0), 1.0)
    lo, hi = des.bounds
    cache: dict[bytes, tuple[float, np.ndarray]] = {}
    opts = dp.spec.optimizer
    means = [c for c in dp.spec.constraints if c.linear]
    project = (means and len(means) == len(dp.spec.constraints) and all(c.relation == "equal" for c in means)
               and len({c.variable for c in means}) == len(means)
               and (opts.mean_method == "projection" or (opts.mean_method == "auto" and des.x0.size > 100)))
    projection = MeanProjection(dp) if project else None

    def fg(z):
        key = np.asarray(z, float).tobytes()
        if key not in cache:
            x = z * scale
            if projection is not None:
                x, free = projection(x)
            value, grad, terms = dp.evaluate(x)
            if projection is not None:
                grad = projection.pullback(grad, z * scale, free)
            gz = grad * scale
            hist.add(x, value, terms, np.linalg.norm(gz))
            if save is not None:
                save(hist)
            if on_eval is not None:
                on_eval(len(hist.objective), x, value, terms)
            cache[key] = (value, gz)
        return cache[key]

    bounds = Bounds(lo / scale, hi / scale)
    cons = []
    for c, target in zip(dp.spec.constraints, dp.targets):
        lb, ub = {"equal": (target, target), "at_most": (-np.inf, target), "at_least": (target, np.inf)}[c.relation]
        if c.linear:
            cons.append(LinearConstraint((dp.mean_weights(c.variable) * scale / target)[None, :], lb / target, ub / target))
            continue
        cons.append(NonlinearConstraint(lambda z, target=target: dp.total_mass(z * scale) / target, lb / target,
                                        ub / target, jac=lambda z, target=target: (dp.mass_gradient(z * scale) * scale
                                                                                   / target)[None, :]))
    z0 = x_start / scale
    if projection is not None:
        res = minimize(fg, z0, jac=True, method="L-BFGS-B", bounds=bounds,
                       options={"maxiter": opts.max_iterations, "ftol": opts.tolerance, "gtol": opts.tolerance})
    elif cons and all(c.linear for c in dp.spec.constraints):
        # linear constraints only: SLSQP keeps every iterate on them (to rounding)
        slsqp = [{"type": "eq" if lc.lb[0] == lc.ub[0] else "ineq",
                  "fun": (lambda z, lc=lc: lc.A @ z - lc.lb) if lc.lb[0] > -np.inf else (lambda z, lc=lc: lc.ub - lc.A @ z),
                  "jac": (lambda z, lc=lc: lc.A) if lc.lb[0] > -np.inf else (lambda z, lc=lc: -lc.A)} for lc in cons]
        res = minimize(fg, z0, jac=True, method="SLSQP", bounds=bounds, constraints=slsqp,
                       options={"maxiter": opts.max_iterations, "ftol": opts.tolerance})
    elif cons:
        res = minimize(lambda z: fg(z)[0], z0, jac=lambda z: fg(z)[1], method="trust-constr", bounds=bounds,
                       constraints=cons, options={"maxiter": opts.max_iterations, "gtol": opts.tolerance,
                                                  "xtol": opts.tolerance, "initial_tr_radius": 0.1})
    else:
        res = minimize(fg, z0, jac=True, method="L-BFGS-B", bounds=bounds,
                       options={"maxiter": opts.max_iterations, "ftol": opts.tolerance, "gtol": opts.tolerance})
    feasible = [k for k in range(len(hist.x)) if _feasible(dp, hist.x[k])]
    best = min(feasible, key=lambda k: hist.objective[k]) if feasible else hist.best
    return DesignResult(hist.x[best], best, hist, str(res.message))


def _feasible(dp: DesignProblem, x: np.ndarray, rtol: float = 1e-4) -> bool:
    for c, target in zip(dp.spec.constraints, dp.targets):
        m = dp.constraint_value(c, x)
        if (c.relation == "equal" and abs(m - target) > rtol * target) or \
           (c.relation == "at_most" and m > target * (1 + rtol)) or \
           (c.relation == "at_least" and m < target * (1 - rtol)):
            return False
    return True


#: ``check_gradient`` compares every variable up to this many; beyond, a sample of them
CHECK_ALL = 24


def check_gradient(dp: DesignProblem, directions: int = 2, limit: int = CHECK_ALL
                   ) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray]:
    """(labels, adjoint gradient, central differences, relative errors) of the objective at the
    start: every variable, or with more than ``limit`` values (a per-element design) the
    limit/2 with the largest |gradient × value| and as many others spread over the rest of
    those above 1 % of the largest, plus
    ``directions`` random directions (every value moved by ±(0.5–1) of its start; label
    ``direction[k]``), whose derivative sums the whole gradient."""
    x0 = dp.design.x0
    _, g, _ = dp.evaluate(x0)
    labels = list(dp.design.labels)
    if x0.size <= limit:
        picked = np.arange(x0.size)
    else:
        size = np.abs(g * np.where(x0 != 0, np.abs(x0), 1.0))
        top = np.argsort(-size)[: limit // 2]
        # the others among values whose derivative is at least 1 % of the largest: a smaller one is
        # below what central differences resolve to 1e-6 relative (the directions still sum them all)
        rest = np.setdiff1d(np.flatnonzero(size >= 0.01 * size.max()), top)
        spread = np.unique(np.linspace(0, rest.size - 1, min(rest.size, limit - top.size)).astype(int))
        picked = np.concatenate([top, rest[spread]]) if rest.size else top
    fd = [finite_difference(dp.value, x0, k) for k in picked]
    adj = list(g[picked])
    names = [labels[k] for k in picked]
    if x0.size > limit:
        rng = np.random.default_rng(1)
        for k in range(directions):
            d = np.where(x0 != 0, np.abs(x0), 1.0) * rng.uniform(0.5, 1.0, x0.size) * rng.choice([-1.0, 1.0], x0.size)
            fd.append(finite_difference(lambda s, d=d: dp.value(x0 + s[0] * d), np.zeros(1), 0))
            adj.append(float(g @ d))
            names.append(f"direction[{k}]")
    fd, adj = np.array(fd), np.array(adj)
    return names, adj, fd, worst_relative_error(adj, fd)


def load_design(path: str | Path) -> DesignProblem:
    spec, _, base = load_spec(path, DesignSpec)
    return DesignProblem(spec, path, base)
