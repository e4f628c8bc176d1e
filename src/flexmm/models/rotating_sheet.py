"""2D lattice of rotating squares (PHYSICS.md §1.2): u, v, θ per unit, the hinge law of hinge.py.

Site s = row · n_cols + col, rest position (col h, row h), h = a cos θ0 + ℓ (ℓ: ligament
length, 0 for zero-length springs). State (nondimensional, length a, time sqrt(m/k_l), mass m):
q = [u (N), v (N), θ (N)]. A horizontal hinge joins the right corner of A = (r, c) to the left
corner of B = (r, c+1): d_l = u_B − u_A, d_s = v_B − v_A, sign σ_A. A vertical hinge joins the top
corner of A = (r, c) to the bottom corner of B = (r+1, c): d_l = v_B − v_A, d_s = u_B − u_A, sign
−σ_A (the bottom corner of B is −(a/2)(−sin φ_B, cos φ_B), so the across-axis offset
(a/2)(sin φ_A + sin φ_B) = −σ_A (a/2)[sin(θ0+θ_B) − sin(θ0+θ_A)]). Periodic edges add wrap hinges.

The kernel also carries the extra terms of the rigid-unit family, each over its own arrays:
point dipoles (``magnets``), bistable joints (``linkage``) and constant loads (``predeform``).
``args`` = (ha (H,), hb (H,), axis (H,), hinge_prm (H, 7), theta0 (N,), cos (N,), sin (N,),
dipoles, joints, loads).
"""

from __future__ import annotations

import math

import numpy as np

from flexmm._jit import jit
from flexmm._trig import sincos
from flexmm.config.rigid import RotatingSquaresSheet
from flexmm.models import predeform, variation
from flexmm.models.base import FieldSpec, System
from flexmm.models.hinge import (H_HALF_A, H_HALF_B, H_KL, H_KS, H_KT, H_REST, H_SIGN,
                                 N_HINGE_PARAMS, hinge_law)
from flexmm.models.linkage import empty_joints, joint_reference, joint_terms
from flexmm.models.magnets import MU0_OVER_4PI, dipole_reference, dipole_terms, empty_dipoles, face_magnets
from flexmm.models.predeform import empty_loads, load_reference, load_terms
from flexmm.units import Scales

FIELDS = (
    FieldSpec("u", "length", "displacement along x"),
    FieldSpec("v", "length", "displacement along y"),
    FieldSpec("theta", "angle", "staggered rotation"),
)
COORD_ATTRS = {"row": ("1", "row index of the unit"), "col": ("1", "column index of the unit")}


# ---------------------------------------------------------------- kernels
@jit
def _angles(q, theta0, cs, sn):
    """cos/sin of θ0 + θ per site into the scratch ``cs``, ``sn`` (N,).

    Two simple loops over a view from 0 so that both vectorise (``_trig.sincos``); with
    libm's scalar sin/cos this pass cost as much as the hinge loop (benchmarks/).
    """
    n = theta0.shape[0]
    th = q[2 * n : 3 * n]
    for i in range(n):
        cs[i] = theta0[i] + th[i]
    for i in range(n):
        s, c = sincos(cs[i])
        cs[i] = c
        sn[i] = s


@jit
def _hinges(q, args, out, want_force):
    ha, hb, hax, hprm, theta0, cs, sn = args[:7]
    n = theta0.shape[0]
    total = 0.0
    for h in range(ha.shape[0]):
        a = ha[h]
        b = hb[h]
        if hax[h] == 0:
            la, lb, sa, sb = a, b, n + a, n + b
        else:
            la, lb, sa, sb = n + a, n + b, a, b
        e, fl, fs, gA, gB = hinge_law(
            q[lb] - q[la], q[sb] - q[sa], q[2 * n + a], q[2 * n + b], cs[a], sn[a], cs[b], sn[b], hprm[h]
        )
        total += e
        if want_force:
            out[la] += fl
            out[lb] -= fl
            out[sa] += fs
            out[sb] -= fs
            out[2 * n + a] -= gA
            out[2 * n + b] -= gB
    return total


@jit
def sheet_force(q, args, out):
    """Generalised forces −∂E/∂q of the sheet (hinges + dipoles + joints + loads) into ``out``."""
    theta0, cs, sn = args[4], args[5], args[6]
    for k in range(out.shape[0]):
        out[k] = 0.0
    _angles(q, theta0, cs, sn)
    _hinges(q, args, out, True)
    dipole_terms(q, args[7], out, True)
    joint_terms(q, theta0.shape[0], args[8], out, True)
    load_terms(q, args[9], out, True)


@jit
def sheet_energy(q, args):
    """Potential energy of the sheet (same arguments as ``sheet_force``)."""
    theta0, cs, sn = args[4], args[5], args[6]
    _angles(q, theta0, cs, sn)
    dummy = np.empty(0)
    return (_hinges(q, args, dummy, False) + dipole_terms(q, args[7], dummy, False)
            + joint_terms(q, theta0.shape[0], args[8], dummy, False) + load_terms(q, args[9], dummy, False))


def sheet_reference(q: np.ndarray, args: tuple) -> tuple[float, np.ndarray]:
    """Numpy version of the sheet energy and forces (vectorised over hinges), for the tests."""
    ha, hb, hax, hprm, theta0 = args[:5]
    n = theta0.size
    u, v, th = q[:n], q[n : 2 * n], q[2 * n : 3 * n]
    c, s = np.cos(theta0 + th), np.sin(theta0 + th)
    horiz = hax == 0
    dl = np.where(horiz, u[hb] - u[ha], v[hb] - v[ha])
    ds = np.where(horiz, v[hb] - v[ha], u[hb] - u[ha])
    p = hprm.T
    el = dl + p[H_REST] - (p[H_HALF_A] * c[ha] + p[H_HALF_B] * c[hb])
    es = ds + p[H_SIGN] * (p[H_HALF_B] * s[hb] - p[H_HALF_A] * s[ha])
    ep = th[ha] + th[hb]
    energy = 0.5 * float(np.sum(p[H_KL] * el**2 + p[H_KS] * es**2 + p[H_KT] * ep**2))
    fl, fs, fp = p[H_KL] * el, p[H_KS] * es, p[H_KT] * ep
    f = np.zeros_like(q)
    la, lb = np.where(horiz, ha, n + ha), np.where(horiz, hb, n + hb)
    sa, sb = np.where(horiz, n + ha, ha), np.where(horiz, n + hb, hb)
    np.add.at(f, la, fl)
    np.add.at(f, lb, -fl)
    np.add.at(f, sa, fs)
    np.add.at(f, sb, -fs)
    np.add.at(f, 2 * n + ha, -(fl * p[H_HALF_A] * s[ha] - fs * p[H_SIGN] * p[H_HALF_A] * c[ha] + fp))
    np.add.at(f, 2 * n + hb, -(fl * p[H_HALF_B] * s[hb] + fs * p[H_SIGN] * p[H_HALF_B] * c[hb] + fp))
    for e_f in (dipole_reference(q, args[7]), joint_reference(q, n, args[8]), load_reference(q, args[9])):
        energy += e_f[0]
        f += e_f[1]
    return energy, f


# ---------------------------------------------------------------- geometry
def checkerboard(n_rows: int, n_cols: int) -> np.ndarray:
    """σ = (−1)^(row+col) per site, shape (n_rows·n_cols,)."""
    r, c = np.divmod(np.arange(n_rows * n_cols), n_cols)
    return np.where((r + c) % 2 == 0, 1.0, -1.0)


def hinge_pairs(n_rows: int, n_cols: int, periodic_x: bool, periodic_y: bool, skew: int = 0):
    """Hinges of the sheet: (a (H,), b (H,), axis (H,)), axis 0 horizontal (A left of B), 1 vertical.

    ``skew``: the top row's upper neighbours are the bottom row's units ``skew`` columns to the right
    (wrapped if periodic in x, dropped past the ends otherwise).
    """
    site = np.arange(n_rows * n_cols).reshape(n_rows, n_cols)
    a_h, b_h = site[:, :-1].ravel(), site[:, 1:].ravel()
    a_v, b_v = site[:-1, :].ravel(), site[1:, :].ravel()
    if periodic_x:
        a_h, b_h = np.concatenate([a_h, site[:, -1]]), np.concatenate([b_h, site[:, 0]])
    if periodic_y:
        cols = np.arange(n_cols) + skew
        keep = slice(None) if periodic_x else (cols >= 0) & (cols < n_cols)
        top, bottom = site[-1, :][keep], site[0, cols % n_cols][keep]
        a_v, b_v = np.concatenate([a_v, top]), np.concatenate([b_v, bottom])
    a = np.concatenate([a_h, a_v]).astype(np.int64)
    b = np.concatenate([b_h, b_v]).astype(np.int64)
    axis = np.concatenate([np.zeros(a_h.size), np.ones(a_v.size)]).astype(np.int64)
    return a, b, axis


def magnet_pairs(n_rows: int, n_cols: int, periodic_x: bool, periodic_y: bool, h: float):
    """Neighbour pairs for magnets (hinged and across a void) with rest offsets (P, 2) in units of a."""
    pairs, offs = [], []
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
        for r in range(n_rows):
            for c in range(n_cols):
                r2, c2 = r + dr, c + dc
                if periodic_y:
                    r2 %= n_rows
                if periodic_x:
                    c2 %= n_cols
                if 0 <= r2 < n_rows and 0 <= c2 < n_cols and (r2, c2) != (r, c):
                    pairs.append((r * n_cols + c, r2 * n_cols + c2))
                    offs.append((dc * h, dr * h))
    return np.array(pairs, np.int64).reshape(-1, 2), np.array(offs, float).reshape(-1, 2)


def hinge_table(a, b, axis, sigma, theta0, half_a, half_b, ligament, kl, ks, kt) -> np.ndarray:
    """Per-hinge parameter rows of hinge.hinge_law (nondimensional), shape (H, 7)."""
    hprm = np.empty((a.size, N_HINGE_PARAMS))
    # d_l is the change of the centre distance h = cos θ0 + ℓ; the springs measure the hinge
    # points' separation minus the ligament ℓ, so ℓ cancels and the rest state is stress-free
    hprm[:, H_REST] = half_a * np.cos(theta0[a]) + half_b * np.cos(theta0[b])
    hprm[:, H_HALF_A] = half_a
    hprm[:, H_HALF_B] = half_b
    hprm[:, H_SIGN] = np.where(axis == 0, sigma[a], -sigma[a])
    hprm[:, H_KL] = kl
    hprm[:, H_KS] = ks
    hprm[:, H_KT] = kt
    return hprm


def edge_sites(n_rows: int, n_cols: int) -> dict[str, list[int]]:
    """Site lists of the four edges (left/right: columns; bottom/top: rows)."""
    site = np.arange(n_rows * n_cols).reshape(n_rows, n_cols)
    return {"left": site[:, 0].tolist(), "right": site[:, -1].tolist(),
            "bottom": site[0, :].tolist(), "top": site[-1, :].tolist()}


# ---------------------------------------------------------------- builder
def build(cfg: RotatingSquaresSheet) -> System:
    """The sheet as a System; edges free, fixed (all DOFs of the edge units held) or periodic."""
    nr, nc, n = cfg.n_rows, cfg.n_cols, cfg.n_units
    m, J, kl, a = cfg.unit_mass_kg, cfg.unit_inertia_kg_m2, cfg.k_long_n_per_m, cfg.a_m
    scales = Scales(a, math.sqrt(m / kl), m)
    px, py = cfg.left == "periodic", cfg.bottom == "periodic"
    ha, hb, hax = hinge_pairs(nr, nc, px, py, cfg.skew_cols)
    row, col = np.divmod(np.arange(n), nc)
    base = {"theta0_rad": cfg.theta0_rad, "mass_kg": m, "inertia_kg_m2": J, "k_long_n_per_m": kl,
            "k_shear_n_per_m": cfg.k_shear_n_per_m, "k_rot_n_m_per_rad": cfg.k_rot_n_m_per_rad}
    site_v, hinge_v = variation.parameter_arrays(base, cfg.variation, col, row, ha, hb)
    sigma = checkerboard(nr, nc)
    theta0 = site_v["theta0_rad"]
    ell = cfg.ligament_length_m / a
    hprm = hinge_table(ha, hb, hax, sigma, theta0, 0.5, 0.5, ell, hinge_v["k_long_n_per_m"] / kl,
                       hinge_v["k_shear_n_per_m"] / kl, hinge_v["k_rot_n_m_per_rad"] / (kl * a * a))
    h = math.cos(cfg.theta0_rad) + ell
    dip = empty_dipoles(n)
    if cfg.magnets is not None:
        mg = cfg.magnets
        pos, dirs = face_magnets(mg.recess_m / a)
        pab, off = magnet_pairs(nr, nc, px, py, h)
        strength = mg.moment_a_m2 * math.sqrt(MU0_OVER_4PI / (kl * a**5))  # s² = μ0 m²/(4π k_l a⁵)
        s = strength * (sigma if mg.polarity == "attract" else np.ones(n))
        kc = 10.0 if mg.contact_stiffness_n_per_m is None else mg.contact_stiffness_n_per_m / kl
        dip = (pab, off, pos, dirs, theta0, sigma, s, np.array([2.0 * mg.recess_m / a, kc]))
    args = (ha, hb, hax, hprm, theta0, np.zeros(n), np.zeros(n), dip, empty_joints(), empty_loads())
    mass = np.concatenate([site_v["mass_kg"], site_v["mass_kg"], site_v["inertia_kg_m2"] / a**2]) / m
    inv_mass = 1.0 / mass
    ends = edge_sites(nr, nc)
    for end, sites in ends.items():
        if getattr(cfg, end) == "fixed":
            for f in range(3):
                inv_mass[f * n + np.asarray(sites)] = 0.0
    horiz = hax == 0
    spacing = h * a
    system = System(
        model=cfg.kind, fields=FIELDS, n_sites=n, scales=scales, mass=mass, inv_mass=inv_mass,
        force=sheet_force, energy=sheet_energy, args=args, q0=np.zeros(3 * n), v0=np.zeros(3 * n),
        spacing_m=spacing,
        site_coords={"x": col * spacing, "y": row * spacing, "row": row, "col": col},
        reference=sheet_reference,
        meta={
            "theta0": cfg.theta0_rad,
            "Ks": cfg.k_shear_n_per_m / kl,
            "Ktheta": cfg.k_rot_n_m_per_rad / (kl * a * a),
            "alpha2": J / (m * a * a),
            "n_rows": nr, "n_cols": nc,
            "omega_ref": 1.0,
            "ends": ends,
            "end_fields": {"left": "u", "right": "u", "bottom": "v", "top": "v"},
            "axis_fields": {"x": "u", "y": "v"},
            "longitudinal_field": "u",
            "rotation_field": "theta",
            "site_coord_attrs": COORD_ATTRS,
            "load_slot": 9,
            "neighbour_pairs": np.stack([ha[horiz], hb[horiz]], 1),
        },
    )
    if cfg.predeform is not None:
        predeform.relax(system, cfg.predeform)
    return system


def launch_soliton(system: System, amplitude: float, center: int, direction: int) -> None:
    """Add a planar vector soliton (chain theory with n_v = 2, s_v = 1) centred on column ``center``.

    Every row gets the chain profile of PHYSICS.md §1.3 (v = 0): exact for a sheet periodic in y,
    the natural launch for a wide sheet.
    """
    from flexmm.theory.rotating import RotatingChainND, soliton_initial_state

    m = system.meta
    p = RotatingChainND(m["theta0"], m["Ks"], m["Ktheta"], m["alpha2"], 2, 1)
    nr, nc, n = m["n_rows"], m["n_cols"], system.n_sites
    U, T, dU, dT = soliton_initial_state(p, amplitude, nc, center, direction)
    for k, (vals, rates) in enumerate(((U, dU), (np.zeros(nc), np.zeros(nc)), (T, dT))):
        system.q0[k * n : (k + 1) * n] += np.tile(vals, nr)
        system.v0[k * n : (k + 1) * n] += np.tile(rates, nr)
