"""Compiled kernels of the 2D rotating-squares sheet (and the linkage): ``SheetArgs``, force, energy.

The hinge law of ``hinge.py`` over the sheet's hinge list (``rotating_sheet`` documents the
geometry), plus the extra terms of the rigid-unit family, each over its own arrays: point
dipoles (``magnets``), bistable joints (``joints``) and constant loads (``loads``).

The hinges of a rectangular grid, listed as the builder lists them, take a vectorised path
(``grid_layout``, ``grid_x``, ``grid_y``: contiguous loops instead of scattered updates, the
same sums in the same order, so the same bits); ``integrators.verlet.sheet_verlet_advance``
fuses it with velocity Verlet. Any other hinge list runs the scattered loop.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from flexmm._jit import jit
from flexmm._trig import sincos
from flexmm.models.hinge import (H_HALF_A, H_HALF_B, H_KL, H_KS, H_KT, H_REST, H_SIGN, N_HINGE_PARAMS, hinge_forces,
                                 hinge_law)
from flexmm.models.joints import joint_reference, joint_terms
from flexmm.models.loads import load_reference, load_terms
from flexmm.models.magnets import dipole_reference, dipole_terms


@jit
def sheet_angles(q, theta0, cs, sn, lo=0, hi=-1, base=0):
    """cos/sin of θ0 + θ of sites lo..hi−1 (all by default) into the scratch ``cs``, ``sn`` (N,;
    or a window that holds site i at index i − ``base``).

    One simple loop over views from lo, so it vectorises (``_trig.sincos``); with libm's scalar
    sin/cos this pass cost as much as the hinge loop (benchmarks/).
    """
    n = theta0.shape[0]
    if hi < 0:
        hi = n
    th, t0, c, s_ = q[2 * n + lo : 3 * n], theta0[lo:], cs[lo - base :], sn[lo - base :]
    for i in range(hi - lo):
        s, co = sincos(t0[i] + th[i])
        c[i] = co
        s_[i] = s


class SheetArgs(NamedTuple):
    """What the sheet kernels read (``sheet_force``, ``sheet_energy``; also the linkage's).

    ``hinge_a``/``hinge_b`` (H,) joined units, ``hinge_axis`` (H,) 0 for an x hinge, 1 for y,
    ``hinge_prm`` (H, 7) law parameters, ``theta0`` (N,) rest angles, ``cos``/``sin`` (N,)
    scratch, ``dipoles`` (``magnets.empty_dipoles``), ``joints`` (``joints.empty_joints``),
    ``loads`` (``loads.empty_loads``: constant generalised forces).
    """

    hinge_a: np.ndarray
    hinge_b: np.ndarray
    hinge_axis: np.ndarray
    hinge_prm: np.ndarray
    theta0: np.ndarray
    cos: np.ndarray
    sin: np.ndarray
    dipoles: tuple
    joints: tuple
    loads: tuple


@jit
def _hinges(q, args, out, want_force, lo, hi):
    """Hinges lo..hi−1 of any hinge list: energy, and forces scattered into ``out``."""
    ha, hb, hax, hprm, theta0, cs, sn = args[:7]
    n = theta0.shape[0]
    total = 0.0
    for h in range(lo, hi):
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


# The grid path. ``rotating_sheet.hinge_pairs`` lists the hinges of an n_rows × n_cols sheet
# as: the horizontal ones row by row (site s to s + 1), horizontal wraps, the vertical ones
# (s to s + n_cols, s in order), vertical wraps. Hinges that join sites at a fixed offset (1 or
# n_cols) are computed by vectorised loops over contiguous views into per-hinge arrays, then
# added to their sites by vectorised loops. A DOF's force is the same sum, in the same order,
# as in the scattered loop (a site is the B end of the hinge listed before the one it is the A
# end of; missing hinges add exact zeros), so the forces are bit-identical to it; the wraps and
# anything else run the scattered loop.


@jit
def grid_layout(ha, hb, hax, n):
    """(n_cols, end of the horizontal rows, start and end of the vertical block) if the hinge
    list starts as ``rotating_sheet.hinge_pairs`` makes it, else n_cols = 0."""
    nh = ha.shape[0]
    lo, y0 = 0, nh  # the first vertical hinge, by bisection (the checks below verify the layout)
    while lo < y0:
        mid = (lo + y0) // 2
        if hax[mid] == 0:
            lo = mid + 1
        else:
            y0 = mid
    nc = n if y0 == nh else hb[y0] - ha[y0]
    if nc < 2 or n % nc != 0:
        return 0, 0, 0, 0
    nr = n // nc
    x1 = nr * (nc - 1)
    y1 = y0 + (nr - 1) * nc if y0 < nh else y0
    if x1 > y0 or y1 > nh:
        return 0, 0, 0, 0
    # horizontal: each hinge joins a, a + 1 along x, a increases along the list, and each row's
    # nc − 1 hinges run from its first site to its last but one (so they are r·nc + c).
    # Integer arithmetic (any bit set: not the layout), so the loops vectorise.
    bad = 0
    a1 = ha[1:]
    for h in range(x1 - 1):
        bad |= (hb[h] - ha[h] - 1) | hax[h] | ((a1[h] - ha[h] - 1) >> 63)  # >> 63: −1 if not increasing
    if x1 > 0:
        bad |= (hb[x1 - 1] - ha[x1 - 1] - 1) | hax[x1 - 1]
    for r in range(nr):
        h = r * (nc - 1)
        bad |= (ha[h] - r * nc) | (ha[h + nc - 2] - (r * nc + nc - 2))
    # vertical: hinge y0 + s joins s, s + nc along y
    a, b, ax = ha[y0:], hb[y0:], hax[y0:]
    for k in range(y1 - y0):
        bad |= (a[k] - k) | (b[k] - k - nc) | (ax[k] - 1)
    if bad != 0:
        return 0, 0, 0, 0
    return nc, x1, y0, y1


@jit
def _grid_hinges(qla, qlb, qsa, qsb, ta, tb, ca, sa, cb, sb, hf, fl, fs, ga, gb, m):
    """Hinges k < m joining A (views qla, qsa, ta, ca, sa from the first A site) to B (views
    from the first B site), the rows of their law's table end to end in ``hf`` (read with a
    constant stride: interleaved loads), into fl, fs, ∂E/∂θ_A (ga), ∂E/∂θ_B (gb)."""
    for k in range(m):
        p = N_HINGE_PARAMS * k
        fl[k], fs[k], ga[k], gb[k] = hinge_forces(
            qlb[k] - qla[k], qsb[k] - qsa[k], ta[k], tb[k], ca[k], sa[k], cb[k], sb[k], hf[p + H_REST],
            hf[p + H_HALF_A], hf[p + H_HALF_B], hf[p + H_SIGN], hf[p + H_KL], hf[p + H_KS], hf[p + H_KT])


@jit
def _grid_hinges_uniform(qla, qlb, qsa, qsb, ta, tb, ca, sa, cb, sb, p, sig, fl, fs, ga, gb, m):
    """``_grid_hinges`` for hinges that share their parameters p = (rest, h_A, h_B, k_l, k_s, k_θ)
    but the shear sign (``sig``, per hinge): nothing streamed but the signs."""
    rest, hA, hB, kl, ks, kt = p
    for k in range(m):
        fl[k], fs[k], ga[k], gb[k] = hinge_forces(qlb[k] - qla[k], qsb[k] - qsa[k], ta[k], tb[k], ca[k], sa[k], cb[k],
                                                  sb[k], rest, hA, hB, sig[k], kl, ks, kt)


@jit
def uniform_hinges(hprm):
    """(rest, h_A, h_B, k_l, k_s, k_θ) if every hinge has them (the shear sign may differ), else
    an empty tuple's stand-in: (nan, ...) — test with ``p[0] == p[0]``."""
    nan = np.nan
    if hprm.shape[0] == 0:
        return (nan, nan, nan, nan, nan, nan)
    r0 = hprm[0]
    bad = False
    for h in range(hprm.shape[0]):
        for k in range(N_HINGE_PARAMS):
            bad |= (k != H_SIGN) & (hprm[h, k] != r0[k])
    if bad:
        return (nan, nan, nan, nan, nan, nan)
    return (r0[H_REST], r0[H_HALF_A], r0[H_HALF_B], r0[H_KL], r0[H_KS], r0[H_KT])


@jit
def _x_sites(ou, ov, ot, w, m):
    """Forces of the horizontal hinges on m sites (views from the first): w[:, k] is the hinge
    from site k − 1 to site k (zeros where there is none). The first terms of each sum."""
    fl, fs, ga, gb = w[0], w[1], w[2], w[3]
    for k in range(m):
        ou[k] = (0.0 - fl[k]) + fl[k + 1]
        ov[k] = (0.0 - fs[k]) + fs[k + 1]
        ot[k] = (0.0 - gb[k]) - ga[k + 1]


@jit
def _to_b(ol, os, ot, w, m):
    """The B ends' share (views from the first B site): −fl, −fs, −∂E/∂θ_B."""
    fl, fs, gb = w[0], w[1], w[3]
    for k in range(m):
        ol[k] -= fl[k]
        os[k] -= fs[k]
        ot[k] -= gb[k]


@jit
def _to_a(ol, os, ot, w, m):
    """The A ends' share (views from the first A site): +fl, +fs, −∂E/∂θ_A."""
    fl, fs, ga = w[0], w[1], w[2]
    for k in range(m):
        ol[k] += fl[k]
        os[k] += fs[k]
        ot[k] -= ga[k]


@jit
def _row_params(hf, pf, s0, m, nc):
    """Parameters of the horizontal hinges from sites s0..s0+m−1 into ``pf`` (rows end to end,
    site-indexed): each row's hinges are a contiguous run of the table; a row's last site gets
    zeros (its dummy hinge)."""
    s = s0
    end = s0 + m
    while s < end:
        r = s // nc
        c = s - r * nc
        e = min(r * nc + nc - 1, end)  # past the row's last hinge in this block
        src = hf[N_HINGE_PARAMS * (r * (nc - 1) + c) :]
        dst = pf[N_HINGE_PARAMS * (s - s0) :]
        for k in range(N_HINGE_PARAMS * (e - s)):
            dst[k] = src[k]
        if e < end:
            dst = pf[N_HINGE_PARAMS * (e - s0) :]
            for k in range(N_HINGE_PARAMS):
                dst[k] = 0.0
            e += 1
        s = e


#: sites per group of the grid path (its scratch stays in L1/L2)
GRID_BLOCK = 2048


@jit
def grid_scratch(n):
    """Scratch of the grid passes: (w (4, nb + 1), pf (7 nb)), nb = min(GRID_BLOCK, n) (small
    sheets are called often: no more than they need)."""
    nb = min(GRID_BLOCK, n)
    return np.empty((4, nb + 1)), np.empty(N_HINGE_PARAMS * nb)


@jit
def grid_x(q, cs, sn, hprm, out, n, nc, w, pf, xprm, lo=0, hi=-1, carry=(0.0, 0.0, 0.0, 0.0), uni=None, xsig=None,
           base=0):
    """Forces of the horizontal hinges on sites lo..hi−1 (all by default) into out[:3n],
    overwriting it there (the first terms of those sites' sums): one run over the sites (hinge
    to s + 1) with a dummy hinge at each row's end (parameters 0, its forces set to 0), so the
    vector loops are long, not one per row. ``carry``: the hinge into site lo (lo − 1 → lo);
    returns the one into site hi. cos/sin must be current up to site hi (included). The
    parameters, site-indexed, come from ``xprm`` (7n, ``grid_x_params``) if it is not empty,
    else block by block from the table into ``pf``; with ``uni`` (``uniform_hinges``) the shared
    parameters and the signs ``xsig`` (n, site-indexed; any numeric type that holds them
    exactly) instead. ``cs``, ``sn`` may be a window holding site i at index i − ``base``."""
    if hi < 0:
        hi = n
    nb = w.shape[1] - 1
    u, v, th = q[:n], q[n : 2 * n], q[2 * n : 3 * n]
    ou, ov, ot = out[:n], out[n : 2 * n], out[2 * n : 3 * n]
    hf = hprm.ravel()
    c0, c1, c2, c3 = carry
    for s0 in range(lo, hi, nb):
        m = min(nb, hi - s0)
        mh = min(m, n - 1 - s0)  # hinges from the block's sites (the last site has none)
        c = s0 - base
        if uni is not None and xsig is not None:
            _grid_hinges_uniform(u[s0:], u[s0 + 1 :], v[s0:], v[s0 + 1 :], th[s0:], th[s0 + 1 :], cs[c:], sn[c:],
                                 cs[c + 1 :], sn[c + 1 :], uni, xsig[s0:], w[0, 1:], w[1, 1:], w[2, 1:], w[3, 1:], mh)
        else:
            if xprm.shape[0] > 0:
                prm = xprm[N_HINGE_PARAMS * s0 :]
            else:
                _row_params(hf, pf, s0, mh, nc)
                prm = pf[0:]
            _grid_hinges(u[s0:], u[s0 + 1 :], v[s0:], v[s0 + 1 :], th[s0:], th[s0 + 1 :], cs[c:], sn[c:],
                         cs[c + 1 :], sn[c + 1 :], prm, w[0, 1:], w[1, 1:], w[2, 1:], w[3, 1:], mh)
        for k in range(nc - 1 - s0 % nc, m, nc):  # the dummies (and the last site's)
            w[0, k + 1] = w[1, k + 1] = w[2, k + 1] = w[3, k + 1] = 0.0
        w[0, 0], w[1, 0], w[2, 0], w[3, 0] = c0, c1, c2, c3
        _x_sites(ou[s0:], ov[s0:], ot[s0:], w, m)
        c0, c1, c2, c3 = w[0, m], w[1, m], w[2, m], w[3, m]
    return c0, c1, c2, c3


@jit
def grid_x_params(hprm, n, nc):
    """The horizontal hinges' parameters site-indexed (7n; zeros at the rows' ends), for callers
    that advance many steps with the same tables (``verlet.sheet_verlet_advance``)."""
    xprm = np.empty(N_HINGE_PARAMS * n)
    _row_params(hprm.ravel(), xprm, 0, n - 1, nc)
    for k in range(N_HINGE_PARAMS * (n - 1), N_HINGE_PARAMS * n):
        xprm[k] = 0.0
    return xprm


@jit
def grid_y(q, cs, sn, hprm, out, n, nc, y0, s0, m, w, uni=None, ysig=None, base=0):
    """Forces of the vertical hinges y0 + s0 .. y0 + s0 + m − 1 (from sites s0.. to s0 + nc..)
    added to out: hinges, then their B sites, then their A sites (a site-centred pass like the
    horizontal one measured slower here). Sites below s0 + m then have all their hinge forces.
    ``cs``, ``sn`` may be a window holding site i at index i − ``base`` (``grid_x``)."""
    u, v, th = q[:n], q[n : 2 * n], q[2 * n : 3 * n]
    ou, ov, ot = out[:n], out[n : 2 * n], out[2 * n : 3 * n]
    b = s0 + nc
    ca, cb = s0 - base, b - base
    if uni is not None and ysig is not None:  # shared parameters, signs ysig (vertical hinges in order)
        _grid_hinges_uniform(v[s0:], v[b:], u[s0:], u[b:], th[s0:], th[b:], cs[ca:], sn[ca:], cs[cb:], sn[cb:], uni,
                             ysig[s0:], w[0], w[1], w[2], w[3], m)
    else:
        _grid_hinges(v[s0:], v[b:], u[s0:], u[b:], th[s0:], th[b:], cs[ca:], sn[ca:], cs[cb:], sn[cb:],
                     hprm.ravel()[N_HINGE_PARAMS * (y0 + s0) :], w[0], w[1], w[2], w[3], m)
    _to_b(ov[b:], ou[b:], ot[b:], w, m)
    _to_a(ov[s0:], ou[s0:], ot[s0:], w, m)


@jit
def _grid_forces(q, cs, sn, hprm, out, n, nc, y0, y1):
    """Forces of the grid's horizontal hinges and of its block of vertical ones into out[:3n]
    (overwritten)."""
    w, pf = grid_scratch(n)
    nb = pf.shape[0] // N_HINGE_PARAMS
    grid_x(q, cs, sn, hprm, out, n, nc, w, pf, pf[:0])
    for s0 in range(0, y1 - y0, nb):  # vertical block: along y, d_l in v and d_s in u
        grid_y(q, cs, sn, hprm, out, n, nc, y0, s0, min(nb, y1 - y0 - s0), w)


@jit
def sheet_force(q, args, out):
    """Generalised forces −∂E/∂q of the sheet (hinges + dipoles + joints + loads) into ``out``.

    Hinges listed as ``rotating_sheet.hinge_pairs`` makes them take the vectorised grid path
    (``grid_x``, ``grid_y``; its wraps and any other hinge list: the scattered loop, same result).
    """
    ha, hb, hax, hprm, theta0, cs, sn = args[:7]
    n = theta0.shape[0]
    sheet_angles(q, theta0, cs, sn)
    nc, x1, y0, y1 = grid_layout(ha, hb, hax, n)
    if nc > 0:
        for k in range(3 * n, out.shape[0]):
            out[k] = 0.0
        _grid_forces(q, cs, sn, hprm, out, n, nc, y0, y1)
        _hinges(q, args, out, True, x1, y0)  # horizontal wraps
        _hinges(q, args, out, True, y1, ha.shape[0])  # vertical wraps, anything else
    else:
        for k in range(out.shape[0]):
            out[k] = 0.0
        _hinges(q, args, out, True, 0, ha.shape[0])
    dipole_terms(q, args[7], out, True)
    joint_terms(q, n, args[8], out, True)
    load_terms(q, args[9], out, True)


@jit
def sheet_energy(q, args):
    """Potential energy of the sheet (same arguments as ``sheet_force``)."""
    theta0, cs, sn = args[4], args[5], args[6]
    sheet_angles(q, theta0, cs, sn)
    dummy = np.empty(0)
    return (_hinges(q, args, dummy, False, 0, args[0].shape[0]) + dipole_terms(q, args[7], dummy, False)
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
