"""Static equilibrium of a rigid-unit lattice under applied strain or load (docs/physics.md §1.2).

Constant loads are a linear potential E_load = −Σ_k f_k q_k (so they stay on during the dynamics
and the energy stays conserved); applied strain holds the end units at ∓ε L/2 along the axis.
``relax`` minimises the energy with the compiled force (FIRE, a damped-dynamics minimiser that
moves continuously, so it cannot jump across a unit), then polishes FIRE's state with Newton
steps on the Hessian (``polish``) until the residual force is at round-off, and stores the
equilibrium as the initial state ``q0`` and as ``System.predeformation``.

The polish makes the equilibrium a smooth function of the scene's parameters to rounding (FIRE's
stopping tolerance leaves an error of about tolerance/λ_min, different at every build), so the
design builder's central differences through it are exact to ~1e-9 like those of any other
parameter (``flexmm.design.variables``). It is kept only where it is safe: the Hessian over the
free DOFs (assembled sparse from central differences of the force along a few colourings of
the units, ``hessian``) must be positive definite (its banded Cholesky factorisation exists),
Newton must reduce the residual and the energy and stay next to FIRE's state; otherwise (an
indefinite Hessian, e.g. a lattice stopped on a saddle or a free compressed sheet that may
rotate, or a Hessian too wide to factorise) FIRE's state is kept (``Predeformation.newton_steps``
is 0). A translation along an axis that nothing holds (balanced loads on free ends) is a zero
mode: FIRE conserves the mean displacement along it (its unit masses and zero net force keep
the total momentum zero), so the polish holds one unit and restores that mean afterwards.
"""

from __future__ import annotations

import numpy as np
from scipy import linalg as sla
from scipy import sparse
from scipy.sparse.csgraph import reverse_cuthill_mckee

from flexmm._jit import jit
from flexmm.linalg import dense_matrix, force_hessian, top_eigenvalue
from flexmm.models.base import Predeformation, System
from flexmm.models.hinge import ChainArgs
from flexmm.models.kernels import model_force
from flexmm.models.loads import LoadedChainArgs

#: sign of the inward normal of an end, along its axis
INWARD = {"left": 1.0, "bottom": 1.0, "right": -1.0, "top": -1.0}


def attach_loads(system: System, dof: np.ndarray, val: np.ndarray) -> None:
    """Put constant loads into a system's energy: its ``loads`` slot, or a loaded chain."""
    loads = (np.asarray(dof, np.int64), np.asarray(val, float))
    if "loads" in system.args._fields:
        system.args = system.args._replace(loads=loads)
    elif isinstance(system.args, ChainArgs):
        system.args = LoadedChainArgs(system.args, loads)
    else:
        raise NotImplementedError(f"model {system.model!r} takes no constant loads")


def _strained(system: System, cfg, guess: np.ndarray) -> dict[int, float]:
    """Held DOFs (index -> value) of the applied strains; also seeds ``guess`` affinely."""
    n, fields = system.n_sites, system.axis_fields
    held = {}
    for axis, eps, ends in (("x", cfg.strain_x, ("left", "right")), ("y", cfg.strain_y, ("bottom", "top"))):
        if eps is None:
            continue
        if axis not in fields:
            raise ValueError(f"model {system.model!r} has no {axis} axis to strain")
        x = system.site_coords[axis] / system.scales.length_m
        target = eps * (x - 0.5 * (x.min() + x.max()))
        k = system.field_index(fields[axis]) * n
        guess[k : k + n] += target
        for end in ends:
            for s in system.ends[end]:
                held[k + s] = target[s]
    return held


@jit
def fire_relax(args, q, free, dt0, dt_max, tol, max_steps):
    """FIRE minimisation (Bitzek et al., PRL 97, 170201, 2006) of the energy behind ``force``.

    Moves only DOFs with ``free[k] > 0`` (unit masses); stops when max |F| over them < ``tol``.
    Returns (steps taken, final max |F|). ``q`` is updated in place.
    """
    n = q.shape[0]
    v = np.zeros(n)
    f = np.zeros(n)
    dt, alpha, n_pos = dt0, 0.1, 0
    resid = np.inf
    for step in range(max_steps):
        model_force(q, args, f)
        power, vv, ff, resid = 0.0, 0.0, 0.0, 0.0
        for k in range(n):
            if free[k] > 0.0:
                power += f[k] * v[k]
                vv += v[k] * v[k]
                ff += f[k] * f[k]
                resid = max(resid, abs(f[k]))
        if resid < tol:
            return step, resid
        if power > 0.0:
            mix = alpha * np.sqrt(vv / ff) if ff > 0.0 else 0.0
            for k in range(n):
                v[k] = ((1.0 - alpha) * v[k] + mix * f[k]) * free[k]
            n_pos += 1
            if n_pos > 5:
                dt = min(1.1 * dt, dt_max)
                alpha *= 0.99
        else:
            for k in range(n):
                v[k] = 0.0
            dt *= 0.5
            alpha, n_pos = 0.1, 0
        for k in range(n):
            if free[k] > 0.0:
                v[k] += dt * f[k]
                q[k] += dt * v[k]
    return max_steps, resid


#: free DOFs up to which a Hessian the colourings do not recover is assembled column by column
DENSE_MAX = 1500
#: a Hessian whose banded Cholesky factor would exceed this many entries is not factorised
BAND_MAX = 20_000_000
#: Newton steps of the polish at most (it stops earlier, at round-off)
NEWTON_MAX = 8
#: the polish may move no DOF further than this from FIRE's state (nondimensional)
POLISH_RADIUS = 1e-3
#: a step that does not at least halve the residual force ends the polish (round-off reached)
NEWTON_GAIN = 0.5


def _cells(system: System) -> tuple[np.ndarray, np.ndarray, int, int]:
    """(row, column) of every site on the lattice's grid and the grid's (rows, columns); a chain is one row."""
    n = system.n_sites
    if system.grid_shape is not None:
        nr, nc = system.grid_shape
        return np.arange(n) // nc, np.arange(n) % nc, nr, nc
    return np.zeros(n, np.int64), np.arange(n), 1, n


def hessian(system: System, q: np.ndarray, free: np.ndarray) -> sparse.csr_array | None:
    """K = −∂F/∂q at q over the DOFs ``free`` (indices), sparse and symmetrised.

    Central differences of the force (``linalg.force_hessian``) along one probe per field and
    colour of the units, coloured by (row mod 3, column mod 3): a unit interacts with the units
    next to it (diagonals included), so every unit has exactly one unit of each colour within
    reach and each response entry has one owner. Checked along a random direction against the
    force; if that fails (longer reach, periodic wraps), assembled column by column up to
    ``DENSE_MAX`` free DOFs, else None.
    """
    n, ndof, m = system.n_sites, q.size, free.size
    if m == 0:
        return None
    op = force_hessian(system.force, system.args, q)
    pos = np.full(ndof, -1)
    pos[free] = np.arange(m)
    row, col, nr, nc = _cells(system)
    shift = np.array([0, 1, -1])  # the offset to the unit of colour c from a unit of colour c − d (mod 3)
    rows, cols, vals = [], [], []
    for a in range(3):
        for b in range(3):
            mine = np.flatnonzero((row % 3 == a) & (col % 3 == b))
            if mine.size == 0:
                continue
            orow, ocol = row + shift[(a - row) % 3], col + shift[(b - col) % 3]
            near = (orow >= 0) & (orow < nr) & (ocol >= 0) & (ocol < nc)
            owner = np.where(near, orow * nc + ocol, 0)
            for f in range(ndof // n):
                probe = np.zeros(ndof)
                probe[f * n + mine] = 1.0
                probe[pos < 0] = 0.0
                if not probe.any():
                    continue
                resp = op(probe)
                for g in range(ndof // n):
                    i, j = pos[g * n : (g + 1) * n], pos[f * n + owner]
                    keep = near & (i >= 0) & (j >= 0) & (resp[g * n : (g + 1) * n] != 0.0)
                    rows.append(i[keep])
                    cols.append(j[keep])
                    vals.append(resp[g * n : (g + 1) * n][keep])
    K = sparse.csr_array((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(m, m))
    K = 0.5 * (K + K.T)
    z = np.zeros(ndof)
    z[free] = np.random.default_rng(0).standard_normal(m)
    want = op(z)[free]
    if np.abs(K @ z[free] - want).max(initial=0.0) <= 1e-6 * np.abs(want).max(initial=0.0):
        return K
    return sparse.csr_array(dense_matrix(op, ndof, free)) if m <= DENSE_MAX else None


def _cholesky(K: sparse.csr_array) -> tuple[np.ndarray, np.ndarray] | None:
    """(permutation, upper banded Cholesky factor) of the symmetric K in reverse Cuthill–McKee
    order; None if K is not positive definite or its band is too wide (``BAND_MAX``)."""
    m = K.shape[0]
    perm = reverse_cuthill_mckee(sparse.csr_matrix(K), symmetric_mode=True)
    Kp = sparse.coo_array(K[perm][:, perm])
    up = Kp.col >= Kp.row
    width = int((Kp.col - Kp.row)[up].max(initial=0))
    if (width + 1) * m > BAND_MAX:
        return None
    band = np.zeros((width + 1, m))
    band[width + Kp.row[up] - Kp.col[up], Kp.col[up]] = Kp.data[up]
    try:
        return perm, sla.cholesky_banded(band, lower=False, check_finite=False)
    except np.linalg.LinAlgError:
        return None


def _cho_solve(factor: tuple[np.ndarray, np.ndarray], rhs: np.ndarray) -> np.ndarray:
    perm, band = factor
    out = np.empty_like(rhs)
    out[perm] = sla.cho_solve_banded((band, False), rhs[perm], check_finite=False)
    return out


def free_translations(system: System, K: sparse.csr_array, free: np.ndarray) -> list[np.ndarray]:
    """The DOFs (indices into ``free``) of each axis field that is entirely free and along
    which K has a zero mode (a uniform translation: balanced loads on free ends)."""
    n, out = system.n_sites, []
    pos = np.full(system.q0.size, -1)
    pos[free] = np.arange(free.size)
    scale = np.abs(K.data).max(initial=0.0)
    for name in dict.fromkeys(system.axis_fields.values()):
        k = system.field_index(name) * n
        idx = pos[k : k + n]
        if np.any(idx < 0):
            continue
        t = np.zeros(free.size)
        t[idx] = 1.0
        if np.abs(K @ t).max(initial=0.0) <= 1e-7 * scale:
            out.append(idx)
    return out


class HessianFactor:
    """K = −∂F/∂q over the DOFs ``free`` (indices) at q (``hessian``), factorised: ``solve(r)``
    returns x with K x = r on the DOFs ``solve_set`` (indices into ``free``), holding one DOF (its
    middle unit) of each free translation (``translations``: their DOFs as indices into ``free``)
    at zero. ``HessianFactor.of`` is None
    where K is not positive definite on the other DOFs or cannot be assembled or factorised."""

    def __init__(self, translations: list[np.ndarray], solve_set: np.ndarray, factor: tuple, size: int):
        self.translations, self.solve_set, self._factor, self._size = translations, solve_set, factor, size

    @classmethod
    def of(cls, system: System, q: np.ndarray, free: np.ndarray,
           translations: list[np.ndarray] | None = None) -> HessianFactor | None:
        K = hessian(system, q, free)
        if K is None:
            return None
        if translations is None:
            translations = free_translations(system, K, free)
        pinned = np.array([idx[idx.size // 2] for idx in translations], np.int64)
        solve_set = np.setdiff1d(np.arange(free.size), pinned)
        factor = _cholesky(K[solve_set][:, solve_set])
        return None if factor is None else cls(translations, solve_set, factor, free.size)

    def solve(self, r: np.ndarray) -> np.ndarray:
        x = np.zeros(self._size)
        x[self.solve_set] = _cho_solve(self._factor, r[self.solve_set])
        return x


def polish(system: System, q: np.ndarray, free: np.ndarray, start: np.ndarray) -> int:
    """Newton steps on ``hessian`` from FIRE's state ``q`` over the DOFs ``free`` (indices);
    ``q`` is updated in place if they are kept (module docstring). ``start``: FIRE's starting
    state, whose mean along a free translation FIRE conserved. Returns the steps kept (0: q is
    FIRE's state, unchanged)."""
    f = np.empty(q.size)

    def residual(x):
        system.force(x, system.args, f)
        return f[free].copy()

    x = q.copy()
    r = residual(x)
    best, taken, translations = np.abs(r).max(initial=0.0), 0, None
    for _ in range(NEWTON_MAX):
        factor = HessianFactor.of(system, x, free, translations)
        if factor is None:
            break
        translations = factor.translations
        trial = x.copy()
        trial[free] += factor.solve(r)
        r_trial = residual(trial)
        worst = np.abs(r_trial).max(initial=0.0)
        if not worst <= NEWTON_GAIN * best or np.abs(trial - q).max() > POLISH_RADIUS:
            break
        x, r, best, taken = trial, r_trial, worst, taken + 1
    if not taken:
        return 0
    for idx in translations:  # back to FIRE's mean along each free translation (a symmetry)
        dofs = free[idx]
        x[dofs] += (start[dofs].sum() - x[dofs].sum()) / dofs.size
    q[:] = x
    return taken


def _stiffest(system: System, q: np.ndarray, free: np.ndarray) -> float:
    """Largest Hessian eigenvalue over the free DOFs (``free`` a 0/1 mask) at q."""
    kx = force_hessian(system.force, system.args, q)
    return top_eigenvalue(lambda x: free * kx(free * x), q.size, np.flatnonzero(free))


def relax(system: System, cfg) -> Predeformation:
    """Minimise the energy under ``cfg`` (a ``Predeform``); update q0, inv_mass, args, predeformation.

    Raises ValueError if the minimiser does not reach ``cfg.gradient_tolerance`` (e.g. a load
    with nothing to hold the lattice).
    """
    n = system.n_sites
    q = system.q0.copy()
    rot = system.field_index(system.rotation_field) * n
    q[rot : rot + n] += np.where(system.inv_mass[rot : rot + n] > 0, cfg.theta_guess_rad, 0.0)
    held = _strained(system, cfg, q)
    dof, val = [], []
    for load in cfg.loads:
        sites = system.ends[load.end]
        field = system.end_field(load.end)
        k = system.field_index(field) * n
        f = INWARD[load.end] * load.force_n / system.scales.force / len(sites)
        dof += [k + s for s in sites]
        val += [f] * len(sites)
    if dof:
        attach_loads(system, np.array(dof), np.array(val))
    for k, x in held.items():
        q[k] = x
    free = system.inv_mass > 0
    free[list(held)] = False
    mask = free.astype(float)
    start = q.copy()
    lam = max(_stiffest(system, q, mask), 1e-12)
    steps, resid = fire_relax(system.args, q, mask, 0.1 / np.sqrt(lam), 0.5 / np.sqrt(lam),
                              cfg.gradient_tolerance, cfg.max_steps)
    if not resid <= cfg.gradient_tolerance:
        raise ValueError(f"predeformation did not converge: max residual force {resid:.3g} "
                         f"(nondimensional) after {steps} steps; is every load balanced by a fixed or "
                         "strained end?")
    newton = polish(system, q, np.flatnonzero(free), start) if cfg.newton else 0
    if newton:
        f = np.empty(q.size)
        system.force(q, system.args, f)
        resid = np.abs(f[free]).max(initial=0.0)
    system.q0 = q
    system.inv_mass[list(held)] = 0.0
    system.predeformation = Predeformation(rest_state=q.copy(), residual=float(resid), steps=int(steps),
                                           energy=float(system.energy(q, system.args)), newton_steps=newton,
                                           free=np.flatnonzero(free))
    return system.predeformation
