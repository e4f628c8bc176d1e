"""Scene-level design variables and their map to a problem's raw arrays.

A variable is either a scalar at a dotted ``path`` of the scene (``damping.viscous.damping_ratio``,
``excitation.velocity_m_s``, ...) or a per-element ``target`` of the lattice's ``variation``
list (``k_rot_n_m_per_rad``, ``mass_kg``, ``bond.k1_n_per_m``, ...) with a ``profile``:

- ``uniform`` (1 value): every element takes it (a gradient variation with start = end);
- ``linear`` (2 values): a linear ramp over the elements from the first to the last value;
- ``spline`` (``knots`` values): a clamped cubic B-spline (scipy) over the units (a sheet's
  columns, or rows with ``axis: y``) with the values as its control points, written as defects
  (a hinge target: the hinges touching each unit, so a hinge between two units takes the value
  written last). It is linear in
  the values and stays between the smallest and largest of them, so the bounds hold at every
  unit (an interpolating spline can overshoot, e.g. to a negative mass);
- ``spline2d`` (``knots`` × ``knots_y`` values, row-major: the ``knots`` values along x of the
  first row of control points, then the next): a sheet's 2D field, the tensor product of the
  clamped B-splines over its columns and its rows, one defect per unit in increasing site order
  (a hinge target: every hinge takes the value of the later of its two units — the right one of
  a horizontal hinge, the upper one of a vertical hinge, the top-row one of a periodic wrap).

The map from the values to the raw arrays is found by central differences of the scene builder.
When it is affine (a stiffness target: the tables hold the value over fixed scales), the
Jacobian found at one design predicts the raw arrays built at the next exactly; ``Design``
checks that prediction against the build each evaluation makes anyway and then reuses the
Jacobian (a per-unit 2D field of a sheet launched with an exact soliton costs tens of builds of
0.1–0.3 s otherwise), recomputing it whenever the prediction fails.

Variables are appended to the scene's own variations, so the lattice's scales stay those of
its base parameters and every design is a runnable scene (``Design.scene_data``). The map from
variables to the raw arrays (``gradient.Raw``) is the scene builder itself; its derivative is
taken by central differences of the builder (no time stepping, so it is cheap; relative error
about 1e-9 for these smooth maps), and chained with the exact adjoint of the run.
"""

from __future__ import annotations

import copy
import math
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from flexmm.assemble import build_system, damping_arrays
from flexmm.config import scene_from_dict
from flexmm.config.base import Finite, Strict
from flexmm.design.gradient import GradientError, Raw, raw_of
from flexmm.integrators.common import Terms

#: relative step of the builder's central differences
BUILD_STEP = 1e-6


class Variable(Strict):
    """One design or fit variable (see the module docstring)."""

    name: str = Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$")
    path: str | None = Field(None, description="dotted scene path of a scalar (e.g. damping.viscous.damping_ratio)")
    target: str | None = Field(None, description="per-element lattice variation target (e.g. k_rot_n_m_per_rad)")
    profile: Literal["uniform", "linear", "spline", "spline2d"] = "uniform"
    knots: int = Field(4, ge=2, le=200, description="spline knots (profile: spline; spline2d: along x)")
    knots_y: int | None = Field(None, ge=2, le=200, description="spline2d: knots along y (the rows)")
    axis: Literal["x", "y"] = Field("x", description="profiles run along the columns (x) or the rows (y) of a sheet")
    initial: Finite | list[Finite] = Field(description="start value (a list: one per value of the profile)")
    bounds: tuple[Finite, Finite] | None = Field(None, description="[low, high] for every value")

    @model_validator(mode="after")
    def _consistent(self):
        if (self.path is None) == (self.target is None):
            raise ValueError("give exactly one of path (a scene scalar) or target (a lattice variation target)")
        if self.path is not None and self.profile != "uniform":
            raise ValueError(f"profile {self.profile!r} needs a target (a path is a single scalar)")
        if self.path is not None and self.axis != "x":
            raise ValueError("axis applies to a target's profile, not to a path")
        if (self.profile == "spline2d") != (self.knots_y is not None):
            raise ValueError("profile spline2d needs knots_y (and knots_y only applies to spline2d)")
        if self.profile == "spline2d" and self.axis != "x":
            raise ValueError("a spline2d field spans both axes: leave axis unset")
        if isinstance(self.initial, list) and len(self.initial) not in (1, self.size):
            raise ValueError(f"initial has {len(self.initial)} values; profile {self.profile} takes {self.size}")
        if self.bounds is not None and not self.bounds[0] < self.bounds[1]:
            raise ValueError(f"bounds {list(self.bounds)}: need low < high")
        return self

    @property
    def size(self) -> int:
        if self.profile == "spline2d":
            return self.knots * self.knots_y
        return {"uniform": 1, "linear": 2, "spline": self.knots}[self.profile]

    def start(self) -> np.ndarray:
        return np.broadcast_to(np.asarray(self.initial, float), (self.size,)).copy()

    def labels(self) -> list[str]:
        return [self.name] if self.size == 1 else [f"{self.name}[{k}]" for k in range(self.size)]


def _set_path(data: dict, dotted: str, value) -> None:
    *head, last = dotted.split(".")
    for key in head:
        nxt = data.get(key)
        if not isinstance(nxt, dict):
            nxt = data[key] = {}
        data = nxt
    data[last] = value


def spline_values(coefficients: np.ndarray, n: int) -> np.ndarray:
    """Values at n elements of the clamped B-spline (degree ≤ 3) with these control points, over 0..n−1."""
    from scipy.interpolate import BSpline

    c = np.asarray(coefficients, float)
    k = min(3, c.size - 1)
    inner = np.linspace(0.0, n - 1.0, c.size - k + 1)
    t = np.concatenate([np.full(k, 0.0), inner, np.full(k, n - 1.0)])
    return BSpline(t, c, k)(np.arange(n, dtype=float))


def spline_basis(knots: int, n: int) -> np.ndarray:
    """(n, knots): column k is the clamped B-spline of ``spline_values`` with control point k set to 1."""
    return np.stack([spline_values(np.eye(knots)[k], n) for k in range(knots)], axis=1)


def spline2d_values(coefficients: np.ndarray, knots: int, knots_y: int, n_rows: int, n_cols: int) -> np.ndarray:
    """(n_rows, n_cols) field of the tensor-product clamped B-spline with (knots_y, knots) control values."""
    c = np.asarray(coefficients, float).reshape(knots_y, knots)
    return spline_basis(knots_y, n_rows) @ c @ spline_basis(knots, n_cols).T


def element_values(lattice: dict, var: Variable, vals: np.ndarray) -> np.ndarray:
    """The per-unit values a target variable writes (a sheet's spline2d: (rows, cols); otherwise
    one per column or row of ``profile_lines``)."""
    if var.profile == "spline2d":
        rows, cols = lattice.get("n_rows"), lattice.get("n_cols")
        if rows is None or cols is None:
            raise GradientError(f"variable {var.name!r}: profile spline2d needs a sheet with n_rows and n_cols "
                                f"(lattice kind {lattice.get('kind')!r} has no n_rows)")
        return spline2d_values(vals, var.knots, var.knots_y, int(rows), int(cols))
    n = len(profile_lines(lattice, var.axis, var.name))
    if var.profile == "spline":
        return spline_values(vals, n)
    return np.linspace(vals[0], vals[-1], n)


def profile_lines(lattice: dict, axis: str, name: str = "") -> list[list[int]]:
    """The units of each column (axis x) or row (axis y) of a lattice dict, in order (a chain: its units);
    ``name``, the variable's, for the errors."""
    rows, cols = lattice.get("n_rows"), lattice.get("n_cols")
    if cols is None:
        if axis == "y":
            raise GradientError(f"variable {name!r}: axis: y needs a sheet (a lattice with rows)")
        return [[i] for i in range(int(lattice.get("n_units", 0)))]
    if rows is None:
        raise GradientError(f"variable {name!r}: a profile along the columns or rows needs a sheet with n_rows "
                            f"(lattice kind {lattice.get('kind')!r} has none)")
    rows, cols = int(rows), int(cols)
    if axis == "x":
        return [[r * cols + c for r in range(rows)] for c in range(cols)]
    return [[r * cols + c for c in range(cols)] for r in range(rows)]


class Design:
    """Variables over a base scene: values ↔ scene dicts ↔ raw arrays (and their Jacobian)."""

    def __init__(self, scene_data: dict, variables: list[Variable], base_dir: str | Path | None = None,
                 source: str = "<scene>"):
        self.base = copy.deepcopy(scene_data)
        self.variables = list(variables)
        self.base_dir = base_dir
        self.source = source
        self.sizes = [v.size for v in self.variables]
        self.labels = [lab for v in self.variables for lab in v.labels()]
        self.x0 = np.concatenate([v.start() for v in self.variables]) if self.variables else np.zeros(0)
        lo = [v.bounds[0] if v.bounds else -np.inf for v in self.variables for _ in range(v.size)]
        hi = [v.bounds[1] if v.bounds else np.inf for v in self.variables for _ in range(v.size)]
        self.bounds = (np.asarray(lo, float), np.asarray(hi, float))
        self.scales = None
        self.scales = self.build(self.x0)[0].scales
        self._affine: tuple | None = None  # (x, raw(x), Jacobian) when the map looked affine
        self.jacobian_builds = 0

    def split(self, x: np.ndarray) -> list[np.ndarray]:
        return np.split(np.asarray(x, float), np.cumsum(self.sizes)[:-1]) if self.variables else []

    def scene_data(self, x: np.ndarray) -> dict:
        """The base scene dict with the variables set to ``x``."""
        data = copy.deepcopy(self.base)
        lat = data.setdefault("lattice", {})
        for var, vals in zip(self.variables, self.split(x)):
            if var.path is not None:
                _set_path(data, var.path, float(vals[0]))
                continue
            variations = lat.setdefault("variation", [])
            if var.profile in ("uniform", "linear"):
                ramp = {"kind": "gradient", "target": var.target, "start": float(vals[0]), "end": float(vals[-1])}
                if var.axis == "y":
                    ramp["axis"] = "y"
                variations.append(ramp)
            elif var.profile == "spline2d":
                field = element_values(lat, var, vals).ravel()  # site = row · n_cols + col
                variations += [{"kind": "defects", "target": var.target, "sites": [site], "value": float(v)}
                               for site, v in enumerate(field)]
            else:
                lines = profile_lines(lat, var.axis, var.name)
                values = spline_values(vals, len(lines))
                variations += [{"kind": "defects", "target": var.target, "sites": sites, "value": float(v)}
                               for sites, v in zip(lines, values)]
        return data

    def scene(self, x: np.ndarray):
        return scene_from_dict(self.scene_data(x), source=self.source, base_dir=self.base_dir)

    def build(self, x: np.ndarray) -> tuple:
        """(system, terms, damp) of the scene at ``x`` (no time-step analysis)."""
        scene = self.scene(x)
        system, terms = build_system(scene)
        terms = terms._asdict()
        damp = damping_arrays(system, scene, terms)
        if self.scales is not None and system.scales != self.scales:
            changed = [v.name for v in self.variables if v.path is not None]
            raise GradientError(f"variables {changed} change the lattice's reference scales; give a "
                                "per-element target (profile: uniform) instead of the base parameter's path")
        return system, Terms(**terms), damp

    def raw(self, x: np.ndarray) -> Raw:
        system, terms, damp = self.build(x)
        return raw_of(system, terms, damp)

    def jacobian(self, x: np.ndarray, raw: Raw | None = None) -> list[Raw]:
        """d raw / d x_k for every value k, by central differences of the builder; given the raw
        arrays built at ``x``, the Jacobian of an earlier design is reused if it predicts them."""
        x = np.asarray(x, float)
        if raw is not None and self._affine is not None and self._predicts(x, raw):
            return self._affine[2]
        out = self._differences(x)
        if raw is not None:
            self._affine = (x.copy(), raw, out)
        return out

    def _predicts(self, x: np.ndarray, raw: Raw) -> bool:
        """raw(x) = raw(x_ref) + J (x − x_ref) to rounding (relative 1e-9 of each array's size)?"""
        x_ref, raw_ref, jac = self._affine
        pred = raw_ref
        for k, d in enumerate(jac):
            if x[k] != x_ref[k]:
                pred = pred.axpy(x[k] - x_ref[k], d)
        for name, a in raw.items():
            b = getattr(pred, name)
            if a.shape != b.shape or not np.array_equal(np.isfinite(a), np.isfinite(b)):
                return False
            fin = np.isfinite(a)
            scale = max(float(np.abs(a[fin]).max(initial=0.0)), 1e-300)
            if np.abs(a[fin] - b[fin]).max(initial=0.0) > 1e-9 * scale:
                return False
        return True

    def _differences(self, x: np.ndarray) -> list[Raw]:
        out = []
        self.jacobian_builds += 2 * x.size
        for k in range(x.size):
            step = BUILD_STEP * max(abs(x[k]), 1e-300) if x[k] != 0 else BUILD_STEP
            xp, xm = x.copy(), x.copy()
            xp[k] += step
            xm[k] -= step
            rp, rm = self.raw(xp), self.raw(xm)
            out.append(rp.slope(rm, 2.0 * step))
        return out

    def chain(self, x: np.ndarray, graw: Raw, raw: Raw | None = None) -> np.ndarray:
        """dJ/dx from dJ/draw (``raw``: the arrays built at x, to reuse an affine map's Jacobian)."""
        return np.array([graw.dot(d) for d in self.jacobian(x, raw)])


def finite_difference(f, x: np.ndarray, k: int, rel_steps=(1e-3, 1e-4, 1e-5, 1e-6, 1e-7)) -> float:
    """Central difference of a scalar f along x_k where it is most stable: consecutive steps'
    estimates agree best there (truncation error falls, rounding error grows as the step shrinks)."""
    x = np.asarray(x, float)
    scale = abs(x[k]) if x[k] != 0 else 1.0
    est = []
    for r in rel_steps:
        h = r * scale
        xp, xm = x.copy(), x.copy()
        xp[k] += h
        xm[k] -= h
        est.append((f(xp) - f(xm)) / (2 * h))
    j = min(range(len(est) - 1), key=lambda i: abs(est[i + 1] - est[i]))
    return 0.5 * (est[j] + est[j + 1])


def worst_relative_error(adjoint: np.ndarray, fd: np.ndarray) -> np.ndarray:
    """Relative errors |adjoint − fd| / |fd| per variable (0 where both vanish)."""
    adjoint, fd = np.asarray(adjoint, float), np.asarray(fd, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        err = np.abs(adjoint - fd) / np.abs(fd)
    err[(fd == 0) & (adjoint == 0)] = 0.0
    err[(fd == 0) & (adjoint != 0)] = math.inf
    return err
