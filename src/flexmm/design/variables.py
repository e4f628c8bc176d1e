"""Scene-level design variables and their map to a problem's raw arrays.

A variable is either a scalar at a dotted ``path`` of the scene (``damping.viscous.damping_ratio``,
``excitation.velocity_m_s``, ``lattice.predeform.strain_x``, ...; a number picks an element of a
list, ``*`` every element: ``lattice.predeform.loads.0.force_n`` one end load,
``lattice.predeform.loads.*.force_n`` all of them, as balanced loads on free ends need) or a
per-element ``target`` of the lattice's ``variation`` list (``k_rot_n_m_per_rad``, ``mass_kg``,
``bond.k1_n_per_m``, ...) with a ``profile``:

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
  a horizontal hinge, the upper one of a vertical hinge, the top-row one of a periodic wrap);
- ``each`` (one value per element of the target): a per-hinge target takes one value per hinge (a
  sheet's hinges in the lattice's order: the horizontal ones row by row, the wraps of a periodic
  x, the vertical ones row by row, the wraps of a periodic y; a chain's hinge b joins units b and
  b + 1), a per-unit target one per unit (site order), a mass lattice's bond target one per bond.
  Written as one ``values`` variation (``flexmm.config.variation.Values``), so the design stays a
  runnable scene.

The map from the values to the raw arrays is found by central differences of the scene builder
(one pair of builds per value), except for ``each`` variables, whose values are many but each
writes only its own element's entries: there one pair of builds moves every value at once and
⌈log₂ n⌉ more pairs, each moving the values whose index has a given bit set, tell which value
owns each changed entry (``coded_differences``); an entry written by several values (a chain's
per-unit hinge means, a hinge's rest length from its two units' θ0) is resolved by the same code
within classes of the values (index mod 2, mod 3, then random), and the result is checked along a random direction against
the builder (else: one pair per value).
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

A predeformed lattice's initial state is the equilibrium the builder relaxes to
(``models.predeform``: FIRE, then Newton steps to round-off), which moves with k_θ, the loads,
the strain, θ0, ...: the rows of its free DOFs are replaced by their exact derivatives from the
implicit function theorem (``Design._equilibrium``, ``equilibrium.equilibrium_tangents``), the
differences of the builder giving only the explicit tables and the held DOFs. Where the Newton
polish was not kept (an indefinite Hessian: ``Predeformation.newton_steps`` 0) or a launch has
displaced the equilibrium's DOFs (a soliton on a predeformed chain), those rows stay the
builder's differences through the relaxation (good to ~1e-8 after the polish, to FIRE's
tolerance over λ_min without it).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import Field, PrivateAttr, model_validator
from scipy import sparse

from flexmm.assemble import build_system, damping_arrays
from flexmm.config import scene_from_dict
from flexmm.config.base import Finite, Strict
from flexmm.design.equilibrium import equilibrium_tangents
from flexmm.design.gradient import GradientError, Raw, raw_of
from flexmm.integrators.common import Terms

#: relative step of the builder's central differences
BUILD_STEP = 1e-6


class Variable(Strict):
    """One design or fit variable (see the module docstring)."""

    name: str = Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$")
    path: str | None = Field(None, description="dotted scene path of a scalar (e.g. damping.viscous.damping_ratio; a number indexes a list, * sets every element: lattice.predeform.loads.*.force_n)")
    target: str | None = Field(None, description="per-element lattice variation target (e.g. k_rot_n_m_per_rad)")
    profile: Literal["uniform", "linear", "spline", "spline2d", "each"] = "uniform"
    knots: int = Field(4, ge=2, le=200, description="spline knots (profile: spline; spline2d: along x)")
    knots_y: int | None = Field(None, ge=2, le=200, description="spline2d: knots along y (the rows)")
    axis: Literal["x", "y"] = Field("x", description="profiles run along the columns (x) or the rows (y) of a sheet")
    initial: Finite | list[Finite] = Field(description="start value (a list: one per value of the profile)")
    bounds: tuple[Finite, Finite] | None = Field(None, description="[low, high] for every value")
    #: profile each: the number of elements of the target (set by ``Design`` from the lattice)
    _elements: int | None = PrivateAttr(None)

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
        if self.profile == "each" and self.axis != "x":
            raise ValueError("profile each gives every element its own value: leave axis unset")
        if self.profile != "each" and isinstance(self.initial, list) and len(self.initial) not in (1, self.size):
            raise ValueError(f"initial has {len(self.initial)} values; profile {self.profile} takes {self.size}")
        if self.bounds is not None and not self.bounds[0] < self.bounds[1]:
            raise ValueError(f"bounds {list(self.bounds)}: need low < high")
        return self

    @property
    def size(self) -> int:
        if self.profile == "each":
            if self._elements is None:
                raise GradientError(f"variable {self.name!r}: profile each has no size before it is bound to a lattice")
            return self._elements
        if self.profile == "spline2d":
            return self.knots * self.knots_y
        return {"uniform": 1, "linear": 2, "spline": self.knots}[self.profile]

    def start(self) -> np.ndarray:
        return np.broadcast_to(np.asarray(self.initial, float), (self.size,)).copy()

    def labels(self) -> list[str]:
        return [self.name] if self.size == 1 else [f"{self.name}[{k}]" for k in range(self.size)]


class VariableError(GradientError):
    """A variable that does not fit the lattice: ``index`` in the variables, ``field``, ``detail``."""

    def __init__(self, index: int, field: str, detail: str):
        super().__init__(f"variables[{index}].{field}: {detail}")
        self.index, self.field, self.detail = index, field, detail


def _set_path(data: dict, dotted: str, value) -> None:
    """Set ``value`` at a dotted path of a scene dict: a number indexes a list (``loads.0``), ``*``
    goes through every element of one (``loads.*.force_n``: every load); missing mappings are
    made. Raises ValueError for an index past a list's end or a list key on something else."""
    key, _, rest = dotted.partition(".")
    if isinstance(data, list):
        if not rest:
            raise ValueError("a list element is not a scalar: name one of its fields")
        if key == "*" and data:
            picked = data
        elif key.isdigit() and int(key) < len(data):
            picked = [data[int(key)]]
        else:
            raise ValueError(f"{key!r} is not an element of a list of {len(data)} (give an index or *)")
        for item in picked:
            _set_path(item, rest, value)
        return
    if not isinstance(data, dict):
        raise ValueError(f"{key!r} goes into a {type(data).__name__}, not a mapping")
    if not rest:
        data[key] = value
        return
    if not isinstance(data.get(key), (dict, list)):
        data[key] = {}
    _set_path(data[key], rest, value)


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
    """The per-unit values a target variable writes (a sheet's spline2d: (rows, cols); profile
    each: one per element of the target; otherwise one per column or row of ``profile_lines``)."""
    if var.profile == "each":
        return np.asarray(vals, float)
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


def unit_field(design: Design, var: Variable, vals: np.ndarray) -> np.ndarray | None:
    """A sheet's (rows, cols) map of what a variable writes, for figures: spline2d its field,
    profile each its per-unit values or, for a hinge target, the mean of the hinges touching each
    unit; None for other profiles and lattices."""
    lattice = design.base["lattice"]
    if var.profile == "spline2d":
        return element_values(lattice, var, vals)
    if var.profile != "each" or lattice.get("kind") != "rotating_squares_sheet":
        return None
    from flexmm.config.rigid import SITE_TARGETS
    from flexmm.models import lattice_hinges

    rows, cols = int(lattice["n_rows"]), int(lattice["n_cols"])
    vals = np.asarray(vals, float)
    if var.target in SITE_TARGETS:
        return vals.reshape(rows, cols)

    ha, hb, _, _ = lattice_hinges(scene_from_dict(design.base, source=design.source, base_dir=design.base_dir).lattice)
    ends = np.concatenate([ha, hb])
    total = np.bincount(ends, np.concatenate([vals, vals]), rows * cols)
    return (total / np.maximum(np.bincount(ends, minlength=rows * cols), 1)).reshape(rows, cols)


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


def target_elements(lattice) -> dict[str, int]:
    """The number of elements of every per-element target of a lattice config (profile each): its
    kind's ``elements`` hook (``config.lattice.MODELS``); {} for a kind without one."""
    from flexmm.models import MODELS

    count = MODELS[lattice.kind].hook("elements")
    return {} if count is None else count(lattice)


def _flat(raw: Raw) -> np.ndarray:
    return np.concatenate([a.ravel() for _, a in raw.items()])


def _unflat(vec: np.ndarray, like: Raw) -> Raw:
    parts, k = [], 0
    for a in [a for _, a in like.items()]:
        parts.append(np.asarray(vec[k : k + a.size], float).reshape(a.shape))
        k += a.size
    return Raw(*parts)


def _change(rp: np.ndarray, rm: np.ndarray) -> np.ndarray:
    """rp − rm, zero where the two are equal (also equal infinities)."""
    return np.where(rp == rm, 0.0, rp - rm)


class Design:
    """Variables over a base scene: values ↔ scene dicts ↔ raw arrays (and their Jacobian)."""

    def __init__(self, scene_data: dict, variables: list[Variable], base_dir: str | Path | None = None,
                 source: str = "<scene>"):
        self.base = copy.deepcopy(scene_data)
        self.base_dir = base_dir
        self.source = source
        self.variables = [self._bound(k, v) for k, v in enumerate(variables)]
        self.sizes = [v.size for v in self.variables]
        self.labels = [lab for v in self.variables for lab in v.labels()]
        self.x0 = np.concatenate([v.start() for v in self.variables]) if self.variables else np.zeros(0)
        lo = [v.bounds[0] if v.bounds else -np.inf for v in self.variables for _ in range(v.size)]
        hi = [v.bounds[1] if v.bounds else np.inf for v in self.variables for _ in range(v.size)]
        self.bounds = (np.asarray(lo, float), np.asarray(hi, float))
        #: the values of profile-each variables (their Jacobian is found by ``coded_differences``)
        self.each = np.zeros(self.x0.size, bool)
        for var, idx in zip(self.variables, np.split(np.arange(self.x0.size), np.cumsum(self.sizes)[:-1])):
            self.each[idx] = var.profile == "each"
        self.scales = None
        self._built: tuple | None = None  # (x, system) of the last build
        built = self.build(self.x0)
        self.scales = built[0].scales
        #: the raw arrays at the start (their shapes, to unflatten Jacobian columns)
        self.template = raw_of(*built)
        self._affine: tuple | None = None  # (x, flat raw(x), Jacobian) when the map looked affine
        self.jacobian_builds = 0
        #: how the last Jacobian of the each-values was found: "coded" or "differences" (fallback)
        self.each_method: str | None = None

    def _bound(self, index: int, var: Variable) -> Variable:
        """A profile-each variable with its element count (from the base lattice) and a checked initial."""
        if var.profile != "each":
            return var
        lattice = scene_from_dict(self.base, source=self.source, base_dir=self.base_dir).lattice
        counts = target_elements(lattice)
        if var.target not in counts:
            known = ", ".join(counts) or "none"
            raise VariableError(index, "target", f"profile each needs a per-element target of the lattice "
                                f"(kind {lattice.kind!r}: {known}); got {var.target!r}")
        n = counts[var.target]
        if isinstance(var.initial, list) and len(var.initial) not in (1, n):
            raise VariableError(index, "initial", f"{len(var.initial)} values; profile each takes one per element "
                                f"of {var.target}, and the lattice has {n} (or give one value for all)")
        bound = var.model_copy()
        bound._elements = n
        return bound

    def split(self, x: np.ndarray) -> list[np.ndarray]:
        return np.split(np.asarray(x, float), np.cumsum(self.sizes)[:-1]) if self.variables else []

    def scene_data(self, x: np.ndarray) -> dict:
        """The base scene dict with the variables set to ``x``."""
        data = copy.deepcopy(self.base)
        lat = data.setdefault("lattice", {})
        for k, (var, vals) in enumerate(zip(self.variables, self.split(x))):
            if var.path is not None:
                try:
                    _set_path(data, var.path, float(vals[0]))
                except ValueError as err:
                    raise VariableError(k, "path", f"{var.path!r}: {err}") from None
                continue
            variations = lat.setdefault("variation", [])
            if var.profile in ("uniform", "linear"):
                ramp = {"kind": "gradient", "target": var.target, "start": float(vals[0]), "end": float(vals[-1])}
                if var.axis == "y":
                    ramp["axis"] = "y"
                variations.append(ramp)
            elif var.profile == "each":
                variations.append({"kind": "values", "target": var.target, "values": [float(v) for v in vals]})
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
        self._built = (np.array(x, float), system)
        return system, Terms(**terms), damp

    def raw(self, x: np.ndarray) -> Raw:
        system, terms, damp = self.build(x)
        return raw_of(system, terms, damp)

    def jacobian_matrix(self, x: np.ndarray, raw: Raw | None = None) -> sparse.csc_array:
        """d raw / d x (rows: the raw arrays flattened in field order, columns: the values), by
        differences of the builder; given the raw arrays built at ``x``, the Jacobian of an earlier
        design is reused if it predicts them."""
        x = np.asarray(x, float)
        if raw is not None and self._affine is not None and self._predicts(x, raw):
            return self._affine[2]
        built = self._built if self._built is not None and np.array_equal(self._built[0], x) else None
        system = built[1] if built is not None else self.build(x)[0]  # before the differences' builds
        out = self._equilibrium(x, system, self._differences(x))
        if raw is not None:
            self._affine = (x.copy(), raw, out)
        return out

    def jacobian(self, x: np.ndarray, raw: Raw | None = None) -> list[Raw]:
        """d raw / d x_k for every value k (``jacobian_matrix``'s columns as raw arrays)."""
        like = self.template
        J = self.jacobian_matrix(x, raw).tocsc()
        J.sum_duplicates()
        out = []
        for k in range(J.shape[1]):
            col = np.zeros(J.shape[0])
            col[J.indices[J.indptr[k] : J.indptr[k + 1]]] = J.data[J.indptr[k] : J.indptr[k + 1]]
            out.append(_unflat(col, like))
        return out

    def _predicts(self, x: np.ndarray, raw: Raw) -> bool:
        """raw(x) = raw(x_ref) + J (x − x_ref) to rounding (relative 1e-9 of each array's size)?"""
        x_ref, raw_ref, jac = self._affine
        return _close(raw, _unflat(_flat(raw_ref) + jac @ (x - x_ref), raw_ref), 1e-9)

    def _equilibrium(self, x: np.ndarray, system, J: sparse.csc_array) -> sparse.csc_array:
        """J with the rows of a predeformed equilibrium's free DOFs in q0 replaced by their exact
        derivatives (``equilibrium.equilibrium_tangents``; ``system``: built at x), where they
        apply: the Newton polish was kept and no launch has displaced those DOFs (q0 = the rest
        state there)."""
        pre = system.predeformation
        if pre is None or pre.free is None or not np.array_equal(system.q0[pre.free], pre.rest_state[pre.free]):
            return J
        like = self.template
        start = np.cumsum([0] + [a.size for _, a in like.items()])
        at = {name: (start[k], start[k + 1]) for k, (name, _) in enumerate(like.items())}
        J = sparse.csr_array(J)

        def block(name, shape):
            lo, hi = at[name]
            return J[lo:hi].toarray().T.reshape((x.size, *shape))

        tang = equilibrium_tangents(system, block("t1", like.t1.shape), block("t2", like.t2.shape),
                                    block("q0", like.q0.shape))
        if tang is None:
            return sparse.csc_array(J)
        rows = at["q0"][0] + pre.free
        keep = np.ones(J.shape[0])
        keep[rows] = 0.0
        new = tang[:, pre.free].T  # (free, values)
        r, c = np.nonzero(new)
        return sparse.csc_array(sparse.diags_array(keep) @ J
                                + sparse.csr_array((new[r, c], (rows[r], c)), shape=J.shape))

    def _differences(self, x: np.ndarray) -> sparse.csc_array:
        cols: dict[int, np.ndarray] = {}
        for k in np.flatnonzero(~self.each):
            xp, xm, step = _pair(x, [k], self.bounds)
            self.jacobian_builds += 2
            cols[k] = _change(_flat(self.raw(xp)), _flat(self.raw(xm))) / (2.0 * step[0])
        if self.each.any():
            J = self._each_jacobian(x)
            return J + _matrix(cols, x.size, J.shape[0]) if cols else J
        return _matrix(cols, x.size, None)

    def _each_jacobian(self, x: np.ndarray) -> sparse.csc_array:
        """The columns of the profile-each values: ``coded_differences``, checked along a random
        direction against central differences of the builder; one pair per value if that fails."""
        idx = np.flatnonzero(self.each)

        def change(moved: np.ndarray) -> np.ndarray:
            xp, xm, _ = _pair(x, idx[moved], self.bounds)
            self.jacobian_builds += 2
            return _change(_flat(self.raw(xp)), _flat(self.raw(xm)))

        steps = _pair(x, idx)[2]
        coded = idx.size > 2 * (math.ceil(math.log2(idx.size)) + 2)  # fewer builds than one pair per value
        J = coded_differences(change, idx.size, steps) if coded else None
        if J is not None:
            rng = np.random.default_rng(0)
            d = np.zeros(x.size)
            d[idx] = rng.uniform(0.5, 1.0, idx.size) * rng.choice([-1.0, 1.0], idx.size) * steps
            self.jacobian_builds += 2
            fd = _change(_flat(self.raw(x + d)), _flat(self.raw(x - d))) / 2.0
            like = self.template
            if _close(_unflat(fd, like), _unflat(J @ d[idx], like), 1e-6):
                self.each_method = "coded"
                return _embed(J, idx, x.size)
        self.each_method = "differences"
        cols = {}
        for j, k in enumerate(idx):
            cols[k] = change(np.arange(idx.size) == j) / (2.0 * steps[j])
        return _matrix(cols, x.size, next(iter(cols.values())).size)

    def chain(self, x: np.ndarray, graw: Raw, raw: Raw | None = None) -> np.ndarray:
        """dJ/dx from dJ/draw (``raw``: the arrays built at x, to reuse an affine map's Jacobian)."""
        return np.asarray(self.jacobian_matrix(x, raw).T @ _flat(graw)).ravel()


def _pair(x: np.ndarray, moved, bounds: tuple | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x + h, x − h, h) with the builder's relative step h on the values ``moved`` only; a value
    within h of one of its ``bounds`` (low, high arrays) moves the pair inside them, (x, x + 2h)
    or (x − 2h, x): the scene may not exist beyond (a damping coefficient below 0)."""
    moved = np.asarray(moved, np.int64)
    step = np.where(x[moved] != 0, BUILD_STEP * np.abs(x[moved]), BUILD_STEP)
    shift = np.zeros(moved.size)
    if bounds is not None:
        lo, hi = bounds[0][moved], bounds[1][moved]
        shift = np.where(x[moved] - step < lo, step, np.where(x[moved] + step > hi, -step, 0.0))
    xp, xm = x.copy(), x.copy()
    xp[moved] += step + shift
    xm[moved] += shift - step
    return xp, xm, step


def _matrix(cols: dict[int, np.ndarray], n: int, rows: int | None) -> sparse.csc_array:
    """A sparse (rows, n) matrix with the given dense columns (the others zero)."""
    m = next(iter(cols.values())).size if cols else (rows or 0)
    if not cols:
        return sparse.csc_array((m, n))
    r, c, v = [], [], []
    for k, col in cols.items():
        nz = np.flatnonzero(col)
        r.append(nz)
        c.append(np.full(nz.size, k))
        v.append(col[nz])
    return sparse.csc_array((np.concatenate(v), (np.concatenate(r), np.concatenate(c))), shape=(m, n))


def _embed(J: sparse.csc_array, idx: np.ndarray, n: int) -> sparse.csc_array:
    """J's columns placed at the columns ``idx`` of an (rows, n) matrix."""
    coo = J.tocoo()
    return sparse.csc_array((coo.data, (coo.row, idx[coo.col])), shape=(J.shape[0], n))


def _close(a: Raw, b: Raw, rtol: float) -> bool:
    """Every array of a equal to b's to ``rtol`` of its largest finite entry (same infinities)."""
    for name, x in a.items():
        y = getattr(b, name)
        if x.shape != y.shape or not np.array_equal(np.isfinite(x), np.isfinite(y)):
            return False
        fin = np.isfinite(x)
        scale = max(float(np.abs(x[fin]).max(initial=0.0)), 1e-300)
        if np.abs(x[fin] - y[fin]).max(initial=0.0) > rtol * scale:
            return False
    return True


#: an entry's change counts as all of the moved values' total (or none) to this relative tolerance
CODE_TOLERANCE = 1e-7
#: rounds of random classes tried on entries written by several values before giving up
CODE_ROUNDS = 8


def coded_differences(change: Callable[[np.ndarray], np.ndarray], n: int, steps: np.ndarray,
                      classes: int = 4, seed: int = 0) -> sparse.csc_array | None:
    """The Jacobian (entries × n) of a map whose values each change few entries, from few central
    differences: ``change(moved)`` is the change of every entry (raw(x + h) − raw(x − h), h =
    ``steps`` on the values ``moved`` (a boolean mask), zero elsewhere).

    All values moved at once give each entry's total D; moving the values whose index has bit b
    set (b < ⌈log₂ n⌉) gives, for an entry that one value owns, either D or 0, and these bits spell
    the owner (Curtis–Powell–Reid compression with the owners found by the code itself). Entries
    whose changes are neither (several owners) are retried within classes of the values (index
    mod 2, mod 3, then random; each class coded alike) until each is owned singly within every
    class of a round; None if
    some entry stays unresolved after ``CODE_ROUNDS`` rounds."""
    rows, cols, vals = [], [], []

    def decode(members: np.ndarray, entries: np.ndarray | None):
        """(entries resolved, their owners (indices into 0..n−1), their D) over the values ``members``."""
        mask = np.zeros(n, bool)
        mask[members] = True
        total = change(mask)
        if entries is not None:
            total = total[entries]
        bits = max(1, math.ceil(math.log2(members.size))) if members.size > 1 else 0
        code = np.zeros(total.size, np.int64)
        ok = total != 0
        seen = total != 0
        for b in range(bits):
            moved = np.zeros(n, bool)
            moved[members[(np.arange(members.size) >> b) & 1 == 1]] = True
            part = change(moved)
            if entries is not None:
                part = part[entries]
            tol = CODE_TOLERANCE * np.abs(total)
            one = np.abs(part - total) <= tol
            ok &= one | (np.abs(part) <= tol)
            seen |= part != 0
            code |= one.astype(np.int64) << b
        ok &= code < members.size
        owner = members[np.minimum(code, members.size - 1)]
        # an entry untouched by every moved set has no owner here; one seen but inconsistent is ambiguous
        return ok, ~seen, owner, total

    ok, untouched, owner, total = decode(np.arange(n), None)
    m = total.size
    good = np.flatnonzero(ok)
    rows.append(good)
    cols.append(owner[good])
    vals.append(total[good] / (2.0 * steps[owner[good]]))
    pending = np.flatnonzero(~ok & ~untouched)
    rng = np.random.default_rng(seed)
    for r in range(CODE_ROUNDS):
        if pending.size == 0:
            break
        # neighbours in index (a chain's adjacent hinges or units) first, then random classes
        label = np.arange(n) % (r + 2) if r < 2 else rng.integers(0, classes, n)
        done = np.ones(pending.size, bool)
        found = []
        for c in range(classes):
            members = np.flatnonzero(label == c)
            if members.size == 0:
                continue
            ok_c, untouched_c, owner_c, total_c = decode(members, pending)
            done &= ok_c | untouched_c
            found.append((ok_c, owner_c, total_c))
        for ok_c, owner_c, total_c in found:
            take = done & ok_c
            rows.append(pending[take])
            cols.append(owner_c[take])
            vals.append(total_c[take] / (2.0 * steps[owner_c[take]]))
        if r >= 2 and not done.any():  # random classes resolve nothing: too many owners per entry
            break
        pending = pending[~done]
    if pending.size:
        return None
    J = sparse.csc_array((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(m, n))
    J.sum_duplicates()
    return J


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
