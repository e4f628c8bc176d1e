"""Chains (networks, grids) of point masses with nonlinear bonds and on-site potentials (docs/physics.md §2).

    m_i ẍ_i = Σ_bonds ± T(x_j − x_i + s_b) − Σ_terms V′(x_i + s_t)  [− friction − damping]

One scalar displacement x per site (field ``u``). Bonds (nearest, optional second neighbours)
and on-site terms are elements with a law code and a parameter row (``flexmm.models.laws``):
the kernels below lift the scalar law over the index arrays; geometry (``mass_topology``),
parameters (``mass_params``) and variation (``variation``) only build those arrays.

Nondimensional units: length = site spacing a, mass = site mass m, time = sqrt(m/k_ref) with
k_ref the bond law's rest stiffness (or ``reference_stiffness_n_per_m``), so speeds are in
units of c0 = a sqrt(k_ref/m). ``u`` is the displacement from the initial state: the initial
(relaxed) positions are folded into the element shifts and kept in ``System.initial_displacement_m``.

Ground friction is a velocity-dependent force; it is not part of the conservative kernels
but listed in ``System.friction`` for the assembler (explicit term, see ``assemble``).
"""

from __future__ import annotations

import math

import numpy as np

from flexmm.linalg import central_difference
from flexmm.models import laws as lw
from flexmm.models.base import FieldSpec, GroundFriction, System
from flexmm.models.mass_kernels import MassArgs, mass_energy, mass_force
from flexmm.models.mass_params import law_rows, rest_stiffness
from flexmm.models.mass_topology import Topology, build_topology
from flexmm.models.variation import mass_values
from flexmm.units import Scales

FIELDS = (FieldSpec("u", "length", "displacement", "x"),)


def _law_slots(cfg, topo: Topology) -> list[tuple[str, object, np.ndarray]]:
    """(prefix, law, elements) for every law family: bonds, bonds2, on-site terms."""
    slots = [("bond", cfg.bond, topo.bonds)]
    if cfg.bond2 is not None:
        slots.append(("bond2", cfg.bond2, topo.bonds2))
    replaced = _junction_sites(cfg, topo)
    sites = np.setdiff1d(np.arange(topo.n_sites), replaced)
    for k, law in enumerate(cfg.onsite):
        slots.append((f"onsite.{k}", law, sites))
    return slots


def _junction_sites(cfg, topo: Topology) -> np.ndarray:
    js = [topo.groups[j.name][0] for j in getattr(cfg, "junctions", []) if j.onsite is not None]
    return np.asarray(js, np.int64)


def scales_of(cfg) -> Scales:
    """Length = spacing, mass = site mass, time = sqrt(m / k_ref)."""
    k_ref = cfg.reference_stiffness_n_per_m or rest_stiffness(cfg.bond, cfg.spacing_m)
    return Scales(cfg.spacing_m, math.sqrt(cfg.mass_kg / k_ref), cfg.mass_kg)


def element_values(cfg, topo: Topology) -> dict[str, np.ndarray]:
    """Every variable quantity per element (SI), after the config's variations."""
    return mass_values(cfg, topo.n_sites, topo.bonds, topo.bonds2, topo.grid_shape)


def _tables(rows_list, tab_list) -> np.ndarray:
    """Concatenate spline tables, pointing each TABLE row at its own block."""
    parts, offset = [], 0
    for (code, rows), tab in zip(rows_list, tab_list):
        if tab is not None:
            rows[:, 1] += offset
            parts.append(tab)
            offset += tab.size
    return np.concatenate(parts) if parts else np.zeros(1)


def element_arrays(cfg, topo: Topology, vals: dict, sc: Scales) -> tuple:
    """The kernels' ``args``: bond and on-site index, code and parameter arrays, spline table."""
    bonds, sites, made, tabs = [], [], [], []
    for prefix, law, elems in _law_slots(cfg, topo):
        sub = {name: vals[f"{prefix}.{name}"] for name, v in law if isinstance(v, float)}
        if prefix.startswith("onsite"):
            sub = {k: v[elems] for k, v in sub.items()}
        code, rows, tab = law_rows(law, sub, sc, len(elems))
        made.append((code, rows))
        tabs.append(tab)
        (sites if prefix.startswith("onsite") else bonds).append((elems, code, rows))
    for j in getattr(cfg, "junctions", []):
        for law in j.onsite or []:
            site = np.array([topo.groups[j.name][0]])
            sub = {name: np.array([v]) for name, v in law if isinstance(v, float)}
            code, rows, tab = law_rows(law, sub, sc, 1)
            made.append((code, rows))
            tabs.append(tab)
            sites.append((site, code, rows))
    if getattr(cfg, "static_load_n", 0.0):
        p = cfg.static_load_n / sc.force
        for site, sign in ((0, 1.0), (topo.n_sites - 1, -1.0)):
            sites.append((np.array([site]), lw.POLY, lw.poly_row([-sign * p])[None, :]))
    tab = _tables(made, tabs)
    return MassArgs(*_pack_bonds(bonds), *_pack_sites(sites), tab)


def _pack_bonds(groups) -> tuple:
    if not groups:
        return (np.zeros(0, np.int64),) * 3 + (np.zeros((0, lw.N_LAW_PRM)),)
    idx = np.concatenate([g[0] for g in groups]).reshape(-1, 2).astype(np.int64)
    code = np.concatenate([np.full(len(g[0]), g[1], np.int64) for g in groups])
    prm = np.ascontiguousarray(np.concatenate([g[2] for g in groups]))
    return np.ascontiguousarray(idx[:, 0]), np.ascontiguousarray(idx[:, 1]), code, prm


def _pack_sites(groups) -> tuple:
    if not groups:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, lw.N_LAW_PRM))
    idx = np.concatenate([g[0] for g in groups]).astype(np.int64)
    code = np.concatenate([np.full(len(g[0]), g[1], np.int64) for g in groups])
    return idx, code, np.ascontiguousarray(np.concatenate([g[2] for g in groups]))


def relax(args: tuple, q: np.ndarray, free: np.ndarray) -> tuple[np.ndarray, float]:
    """Local energy minimum nearest ``q`` over the ``free`` DOFs; returns (q, max |F|).

    A trust-region Newton–CG search (Hessian-vector products by central differences of the
    compiled force) whose first steps are short (radius 0.01 spacing), so a guess inside a well
    relaxes within it. A state that is not a local minimum (e.g. free end magnets pushing a
    metastable chain over) relaxes to wherever the energy leads: hold such ends fixed.
    """
    from scipy.optimize import minimize

    f = np.zeros_like(q)
    work = q.copy()

    def energy(y):
        work[free] = y
        return mass_energy(work, args)

    def grad(y):
        work[free] = y
        mass_force(work, args, f)
        return -f[free]

    def hessp(y, p):
        return central_difference(grad, y, p)

    if free.size:
        res = minimize(energy, q[free], jac=grad, hessp=hessp, method="trust-ncg",
                       options={"initial_trust_radius": 0.01, "max_trust_radius": 1.0,
                                "gtol": 1e-11, "maxiter": 10000})
        work[free] = res.x
    mass_force(work, args, f)
    return work, float(np.max(np.abs(f[free]), initial=0.0))


def fold_initial_state(args: tuple, x0: np.ndarray) -> None:
    """Shift every element so that q = 0 means the sites sit at ``x0`` (in place)."""
    bi, bj, _, bprm, si, _, sprm, _ = args
    bprm[:, 0] += x0[bj] - x0[bi]
    sprm[:, 0] += x0[si]


def _fixed_sites(cfg, topo: Topology, conditions=("fixed",)) -> list[int]:
    """Sites of the ends whose condition (chain, grid) is one of ``conditions``."""
    out = []
    for end in ("left", "right"):
        if getattr(cfg, end, None) in conditions:
            out += topo.ends[end]
    return out


def friction_arrays(fr, force_n: np.ndarray, sc: Scales) -> GroundFriction:
    """Nondimensional regularised-Coulomb levels per site (forward v > 0, backward v < 0)."""
    ratio = 1.0 if fr.backward_force_n is None else (
        fr.backward_force_n / fr.force_n if fr.force_n > 0 else math.inf)
    back = force_n * ratio if math.isfinite(ratio) else np.full(force_n.size, fr.backward_force_n)
    return GroundFriction(sites=np.arange(force_n.size, dtype=np.int64), forward=force_n / sc.force,
                          backward=back / sc.force, velocity=fr.regularisation_m_s / sc.velocity)


def element_counts(cfg) -> dict[str, int]:
    """Target -> number of elements, of each per-element target (its ``ModelSpec.elements``)."""
    return {k: v.size for k, v in element_values(cfg, build_topology(cfg)).items()}


def build(cfg) -> System:
    """A MassChain, MassNetwork or MassGrid config as a System (state: u of every site)."""
    topo = build_topology(cfg)
    sc = scales_of(cfg)
    vals = element_values(cfg, topo)
    args = element_arrays(cfg, topo, vals, sc)
    n = topo.n_sites
    mass = vals["mass_kg"] / sc.mass_kg
    for j in getattr(cfg, "junctions", []):
        if j.mass_kg is not None:
            mass[topo.groups[j.name][0]] = j.mass_kg / sc.mass_kg
    inv_mass = 1.0 / mass
    inv_mass[_fixed_sites(cfg, topo)] = 0.0
    x0 = vals["initial_displacement_m"] / sc.length_m
    if cfg.relax:  # fixed and driven ends are held where they start
        held = np.zeros(n, bool)
        held[_fixed_sites(cfg, topo, ("fixed", "driven"))] = True
        x0, _ = relax(args, x0, np.flatnonzero((inv_mass > 0) & ~held))
    fold_initial_state(args, x0)
    nx_ny = topo.grid_shape  # (nx, ny), site = i + nx j
    friction = None if cfg.friction is None else friction_arrays(cfg.friction, vals["friction.force_n"], sc)
    return System(
        model=cfg.kind, fields=FIELDS, n_sites=n, scales=sc, mass=mass, inv_mass=inv_mass,
        args=args, q0=np.zeros(n), v0=np.zeros(n),
        spacing_m=cfg.spacing_m, site_coords=topo.coords,
        ends=topo.ends,
        grid_shape=None if nx_ny is None else (nx_ny[1], nx_ny[0]),
        neighbour_pairs=topo.bonds, site_groups=topo.groups,
        friction=friction,
        initial_displacement_m=x0 * sc.length_m,
    )
