"""``flexmm fit SPEC.yaml``: fit scene parameters to a measured trajectory by least squares.

The spec names a scene, a measured table (time × site of one field, CSV or netCDF, with its
unit) and the parameters to fit (``variables.Variable``). The residuals are
r = (model − data)/σ at every measured time and site; scipy's ``least_squares`` (trust-region
reflective, bounds) minimises ½‖r‖² with the exact Jacobian from forward sensitivities of the
run with the scene's integrator (velocity Verlet, PEFRL, BM6 or implicit midpoint:
``gradient.Trajectory.sensitivities``,
one tangent per parameter, in the same run). The uncertainty is the Gauss–Newton covariance s²(JᵀJ)⁻¹ at the optimum, with
s² = ‖r‖²/(m − n) (σ only sets the weights; with the right σ, s² ≈ 1).

Measured tables: CSV with a ``time_s`` column and one column per site, headed by the site
index; or netCDF with the field as a (time, site) variable, a ``site`` coordinate and ``time``
in seconds (a flexmm dataset is one). Times must lie on a uniform grid from t = 0 (a multiple
of the grid step); the run steps land on them exactly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import Field

from flexmm.assemble import build_problem
from flexmm.config.base import Positive, Strict
from flexmm.config.loader import ConfigError, ConfigIssue
from flexmm.design.gradient import Trajectory, check_differentiable
from flexmm.design.spec import load_spec, scene_data_of
from flexmm.design.variables import Design, Variable, finite_difference, worst_relative_error
from flexmm.errors import FlexmmError

#: SI factor of each accepted unit of a measured table
UNITS = {"m": 1.0, "mm": 1e-3, "um": 1e-6, "µm": 1e-6, "rad": 1.0, "mrad": 1e-3, "deg": math.pi / 180.0}
_KIND = {"m": "length", "mm": "length", "um": "length", "µm": "length", "rad": "angle", "mrad": "angle",
         "deg": "angle"}


class DataSpec(Strict):
    """The measured table."""

    file: str
    field: str = Field(description="model field measured (u, theta, ...)")
    unit: Literal["m", "mm", "um", "µm", "rad", "mrad", "deg"]
    sigma: Positive | None = Field(None, description="measurement noise std (in `unit`); default 1")
    sites: list[int] | None = Field(None, description="netCDF: sites to use (default all)")


class FitOptions(Strict):
    max_evaluations: int = Field(50, ge=1, le=10_000)
    tolerance: Positive = Field(1e-10, lt=1, description="ftol = xtol = gtol of least_squares")


class FitSpec(Strict):
    """A fit: a scene (file or inline), a measured table, parameters, options."""

    name: str = Field(pattern=r"^[A-Za-z0-9][A-Za-z0-9_.\-]*$")
    description: str = ""
    scene: str | dict
    data: DataSpec
    parameters: list[Variable] = Field(min_length=1)
    fit: FitOptions = Field(default_factory=FitOptions)


class FitError(FlexmmError):
    """A measured table that cannot be fitted (unreadable, wrong grid or sites)."""


@dataclass
class Measured:
    times: np.ndarray  # (T,) s
    sites: np.ndarray  # (S,)
    values: np.ndarray  # (T, S) SI


def read_table(spec: DataSpec, base_dir: Path) -> Measured:
    """The measured table in SI (see the module docstring for the formats)."""
    path = base_dir / spec.file
    if not path.exists():
        raise FitError(f"data file {spec.file!r} not found (looked in {base_dir})")
    factor = UNITS[spec.unit]
    if path.suffix.lower() in (".nc", ".h5", ".netcdf"):
        import xarray as xr

        with xr.open_dataset(path, engine="h5netcdf") as ds:
            if spec.field not in ds:
                raise FitError(f"{spec.file}: no variable {spec.field!r} (has {', '.join(map(str, ds.data_vars))})")
            da = ds[spec.field].transpose("time", "site")
            if spec.sites is not None:
                da = da.sel(site=spec.sites)
            return Measured(np.asarray(ds["time"], float), np.asarray(da["site"], int), np.asarray(da, float) * factor)
    try:
        import csv

        with open(path, newline="") as fh:
            rows = list(csv.reader(fh))
        head = [h.strip() for h in rows[0]]
        if head[0] != "time_s":
            raise ValueError("the first column must be time_s")
        sites = np.array([int(h) for h in head[1:]])
        table = np.array([[float(x) for x in r] for r in rows[1:] if r], float)
    except (ValueError, IndexError) as err:
        raise FitError(f"{spec.file}: not a table of time_s and per-site columns ({err})") from None
    if spec.sites is not None:
        keep = [list(sites).index(s) for s in spec.sites]
        sites, table = sites[keep], table[:, [0] + [k + 1 for k in keep]]
    return Measured(table[:, 0], sites, table[:, 1:] * factor)


class Fit:
    """A fit problem: the design (variables over the scene), the run, the data (all SI)."""

    def __init__(self, spec: FitSpec, spec_path: str | Path, base_dir: Path):
        self.spec = spec
        data, source, where = scene_data_of(spec.scene, spec_path, base_dir)
        self.design = Design(data, spec.parameters, where, source)
        self.measured = read_table(spec.data, base_dir)
        self.problem = build_problem(self.design.scene(self.design.x0))
        system = self.problem.system
        check_differentiable(system, self.problem.terms)
        if spec.data.field not in [f.name for f in system.fields]:
            raise FitError(f"data.field {spec.data.field!r}: the model's fields are {[f.name for f in system.fields]}")
        bad = [int(s) for s in self.measured.sites if not 0 <= s < system.n_sites]
        if bad:
            raise FitError(f"data sites {bad} outside 0..{system.n_sites - 1}")
        kind = system.fields[system.field_index(spec.data.field)].kind
        if kind != _KIND[spec.data.unit]:
            raise FitError(f"data.unit {spec.data.unit!r} is not a unit of {spec.data.field} ({kind})")
        self.kind = kind
        self.scale = system.scales.coordinate(kind)
        self.sigma = (spec.data.sigma or 1.0) * UNITS[spec.data.unit]
        self.traj, self.index = self._trajectory()

    def _trajectory(self) -> tuple[Trajectory, np.ndarray]:
        t = self.measured.times
        if t.size < 2 or np.any(np.diff(t) <= 0):
            raise FitError("measured times must increase")
        dt_data = float(np.median(np.diff(t)))
        index = np.rint(t / dt_data).astype(int)
        if np.any(np.abs(t - index * dt_data) > 1e-6 * dt_data) or index[0] < 0:
            raise FitError("measured times must lie on a uniform grid from t = 0 (multiples of one step)")
        sc = self.problem.system.scales
        stride = max(1, math.ceil(dt_data / sc.time_s / self.problem.dt - 1e-9))
        h = dt_data / sc.time_s / stride
        s = self.problem.system
        obs = np.array([s.dof(self.spec.data.field, int(site)) for site in self.measured.sites], np.int64)
        return Trajectory(s.args, self.problem.terms, h, stride * int(index[-1]), stride, obs,
                          integrator=self.problem.scene.solver.integrator), index

    # -- residuals and Jacobian --------------------------------------------------------------
    def model(self, x: np.ndarray) -> np.ndarray:
        rec, _ = self.traj.run(self.design.raw(x), segment=self.traj.nsteps + 1)
        return rec.q[self.index] * self.scale

    def residuals(self, x: np.ndarray) -> np.ndarray:
        return ((self.model(x) - self.measured.values) / self.sigma).ravel()

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        raw = self.design.raw(x)
        _, tangents = self.traj.sensitivities(raw, self.design.jacobian(x))
        return np.stack([(t.q[self.index] * self.scale / self.sigma).ravel() for t in tangents], axis=1)

    def cost_gradient(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        """½‖r‖² and its gradient by the adjoint (one reverse sweep)."""
        index, scale, sigma, data = self.index, self.scale, self.sigma, self.measured.values

        def objective(rec, raw):
            r = (rec.q[index] * scale - data) / sigma
            dq = np.zeros_like(rec.q)
            np.add.at(dq, index, r * scale / sigma)
            return 0.5 * float(np.sum(r * r)), dq, 0.0, 0.0, None

        value, graw, _ = self.traj.gradient(self.design.raw(x), objective)
        return value, self.design.chain(x, graw)

    def cost(self, x: np.ndarray) -> float:
        r = self.residuals(x)
        return 0.5 * float(r @ r)


@dataclass
class FitResult:
    x: np.ndarray
    stderr: np.ndarray
    covariance: np.ndarray
    cost0: float
    cost: float
    reduced_chi2: float
    evaluations: int
    status: str


def solve(fit: Fit, progress=None) -> FitResult:
    """scipy least_squares from the spec's initial values; Gauss–Newton covariance at the optimum."""
    from scipy.optimize import least_squares

    x0 = fit.design.x0
    lo, hi = fit.design.bounds
    x_scale = np.where(x0 != 0, np.abs(x0), 1.0)
    opts = fit.spec.fit
    calls = {"n": 0}

    def fun(x):
        calls["n"] += 1
        r = fit.residuals(x)
        if progress is not None:
            progress(calls["n"], x, 0.5 * float(r @ r))
        return r

    res = least_squares(fun, x0, jac=fit.jacobian, bounds=(lo, hi), x_scale=x_scale, method="trf",
                        ftol=opts.tolerance, xtol=opts.tolerance, gtol=opts.tolerance,
                        max_nfev=opts.max_evaluations)
    J = fit.jacobian(res.x)
    m, n = J.shape
    s2 = float(res.fun @ res.fun) / max(m - n, 1)
    cov = s2 * np.linalg.pinv(J.T @ J)
    return FitResult(res.x, np.sqrt(np.diag(cov)), cov, fit.cost(x0), 0.5 * float(res.fun @ res.fun), s2,
                     calls["n"], res.message)


def check_gradient(fit: Fit) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(adjoint gradient, central differences, relative errors) of ½‖r‖² at the start point."""
    x0 = fit.design.x0
    _, g = fit.cost_gradient(x0)
    fd = np.array([finite_difference(fit.cost, x0, k) for k in range(x0.size)])
    return g, fd, worst_relative_error(g, fd)


def load_fit(path: str | Path) -> Fit:
    spec, _, base = load_spec(path, FitSpec)
    try:
        return Fit(spec, path, base)
    except FitError as err:
        raise ConfigError([ConfigIssue(str(path), None, "data", str(err))]) from None


def synthetic_table(scene_data: dict, field: str, sites: list[int], dt_s: float, n_times: int,
                    noise: float, seed: int = 0, base_dir: str | Path | None = None) -> Measured:
    """A measured table made by running a scene (its integrator, the scene's dt rounded down
    to divide ``dt_s``) with Gaussian noise of std ``noise`` (SI) added: the fits' test data."""
    design = Design(scene_data, [], base_dir)
    problem = build_problem(design.scene(design.x0))
    s = problem.system
    stride = max(1, math.ceil(dt_s / s.scales.time_s / problem.dt - 1e-9))
    obs = np.array([s.dof(field, site) for site in sites], np.int64)
    traj = Trajectory(s.args, problem.terms, dt_s / s.scales.time_s / stride, stride * (n_times - 1), stride, obs,
                      integrator=problem.scene.solver.integrator)
    rec, _ = traj.run(design.raw(design.x0), segment=traj.nsteps + 1)
    kind = s.fields[s.field_index(field)].kind
    values = rec.q * s.scales.coordinate(kind)
    values = values + np.random.default_rng(seed).normal(0.0, noise, values.shape)
    return Measured(dt_s * np.arange(n_times), np.asarray(sites), values)


def write_table(measured: Measured, path: str | Path, unit: str) -> None:
    """CSV of a table in ``unit`` (the format ``read_table`` reads)."""
    factor = UNITS[unit]
    with open(path, "w") as fh:
        fh.write(",".join(["time_s"] + [str(int(s)) for s in measured.sites]) + "\n")
        for t, row in zip(measured.times, measured.values / factor):
            fh.write(",".join([f"{t:.9g}"] + [f"{v:.9e}" for v in row]) + "\n")
