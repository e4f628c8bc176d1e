"""Velocity Verlet fused with the rotating-squares chain force, blocked in time.

``verlet_advance`` streams the state three times per step (force; closing kick; opening kick
and drift). Here each step is one sweep over blocks of ``hinge.BLOCK`` sites, and each block
runs three vectorised loops over block scratch (L1/L2; ``hinge.chain_block_hinges``):

1. sites: cos/sin of θ0+θ (``_trig.sincos``) and the lateral-hinge force on θ;
2. hinges inside the block (hinge i joins sites i, i+1) into per-hinge arrays (no carried
   scalars, so the loop vectorises); the block's right hinge, to the first site of the next
   block at the *old* state, is evaluated before the block moves and carried to the next block;
3. each site's forces from its two hinges with the closing kick of step s and the opening kick
   and drift of step s+1 (the last step: closing kick, F stored in ``f``); with damping or an
   applied force in the block, forces, then drives, then the (semi-implicit) kicks.

The arithmetic is that of ``verlet_advance`` with ``hinge.chain_force`` (same operations in the
same order), so trajectories are bit-identical to the unfused stepper; only the energy ledger's
dissipation sum runs in another order (rounding, tests/integrators/test_trig_and_parallel_kernels.py).

Parameters are read column-wise, and only where they vary: ``_prepare`` (one read of the
tables; ``prepare``, kept by the ``Stepper`` until h or the arrays change, so a run pays it
once) finds each column's period-2 pattern (the shear sign alternates) and the blocks that
differ from it. A block where every column is uniform gets its parameters as scalars (one
compiled variant of the loops, ``hinge.param``); one where only the site columns (θ0, k_g,
k_r) vary gets the hinge and per-DOF ones as scalars and the site ones as columns (another);
any other block reads columns (a third): block-sized copies of the pattern for the uniform
ones, full columns for those that vary there (so a graded chain streams only the columns that
vary, and only where they do).

Time blocking (both kernels): the chain is cut into fixed ranges of about ``RANGE_SITES``
sites (by N, whole blocks), and each range advances ``TIME_BLOCK`` steps at a time while its
state is in cache, on its own sites plus a halo of ``TIME_BLOCK`` sites on each side copied
before any range moves (the halo's outer sites go wrong one site per step, never reaching the
range; the halos are ≈ 1 % more work). So a chain longer than the caches streams through
memory once per ``TIME_BLOCK`` steps, not every step. The threaded kernel
(``chain_verlet_advance_parallel``) shares the ranges out in fixed chunks, so its threads
meet once per ``TIME_BLOCK`` steps; both kernels do the same arithmetic on the same ranges
and sum the ledger by range in the same order, so they give the same bits, ledger included
(``parallel.AdaptiveThreads`` relies on it).

Used for chains with their own hinge order and 2N DOFs, with on-site damping and with
prescribed-displacement or applied-force drives on up to ``MAX_DRIVES`` DOFs, but without
contacts, dashpots or ground friction (velocity-dependent forces are evaluated at a predicted
velocity that needs the neighbours' forces: ``fusable``); anything else runs ``verlet_advance``.

Compile cost: numba compiles a function once per constant passed to it (a literal type), so the
constants that only steer a branch or an offset (a segment's ``has_next``, a zero base, the serial
kernel's one chunk) go through ``_jit.runtime`` and the column accessors (``_view``, ``_at``) are
inlined: each function here compiles once per argument types, the three parameter variants of the
block loops (``_block``) being the only copies.
"""

from __future__ import annotations

import numpy as np

from flexmm._jit import jit, prange, runtime
from flexmm._trig import sincos
from flexmm.integrators.common import (ACC_DISSIPATED, ACC_WORK, MODE_DISPLACEMENT, MODE_FORCE,
                                       waveform)
from flexmm.integrators.verlet import BLOCK as DOF_BLOCK
from flexmm.integrators.verlet import _count
from flexmm.models.hinge import (BLOCK, H_HALF_A, H_HALF_B, H_KL, H_KS, H_KT, H_REST, H_SIGN, N_W, S_KG,
                                 S_KR, S_THETA0, W_FL, W_FT, W_GA, W_GB, W_X, W_Y, ChainArgs,
                                 chain_block_hinges, chain_site_forces, lane_sum, param)

#: steps a range takes at a time (between synchronisations of the threads; the halo width, in sites)
TIME_BLOCK = 32
#: sites per range, about (whole blocks; a range's state and the block scratch stay in L2)
RANGE_SITES = 2 * BLOCK
#: sites per chunk of ranges at least (the threaded kernel's unit of work)
RANGE_MIN = 6 * BLOCK
#: at most this many chunks
MAX_CHUNKS = 16
#: drives (prescribed displacements, applied forces) the fused kernels accept
MAX_DRIVES = 64

# Columns of the prepared tables: the hinge law (hinge i joins sites i, i+1), the sites, then
# per-DOF factors of the u and θ fields (kicks h/2·m⁻¹; damping: 1 − hγ/2, 1/(1 + hγ/2), c).
(C_REST, C_HA, C_HB, C_SIG, C_KL, C_KS, C_KT, C_TH0, C_KG, C_KR, C_C0, C_KICK_U, C_KICK_T,
 C_PRE_U, C_PRE_T, C_POST_U, C_POST_T, C_CD_U, C_CD_T) = range(19)
N_COLS = 19


def fusable(args, q: np.ndarray, minv: np.ndarray, damp: np.ndarray, terms) -> bool:
    """Whether the fused sweep applies (checked once in Python when a stepper is made).

    Chain-ordered hinges, 2N DOFs; on-site damping is fine, and so are up to
    ``MAX_DRIVES`` drives that prescribe a displacement or apply a force on chain DOFs. Not:
    contacts, dashpots, ground friction (velocity-dependent forces at a predicted velocity).
    """
    if not isinstance(args, ChainArgs):
        return False
    n = args.site_prm.shape[0]
    if q.shape[0] != 2 * n or args.hinge_a.shape[0] != n - 1 or n < 2:
        return False
    if terms.con_ij.shape[0] + terms.dash_ij.shape[0] > 0 or terms.drv_dof.shape[0] > MAX_DRIVES:
        return False
    modes = np.asarray(terms.drv_mode)
    if np.any((modes != MODE_DISPLACEMENT) & (modes != MODE_FORCE)):
        return False
    if np.any((terms.drv_dof < 0) | (terms.drv_dof >= 2 * n)):
        return False
    idx = np.arange(n - 1)
    return np.array_equal(args.hinge_a, idx) and np.array_equal(args.hinge_b, idx + 1)


# ------------------------------------------------------------------ prepared tables


@jit
def _kick_factors(minv, damp, h, k):
    """DOF k's (kick h/2·m⁻¹, 1 − hγ/2, 1/(1 + hγ/2), c masked), as ``verlet._factors``."""
    g = damp[k] * minv[k]
    return (0.5 * h * minv[k], 1.0 - 0.5 * h * g, 1.0 / (1.0 + 0.5 * h * g),
            damp[k] if minv[k] > 0.0 else 0.0)


@jit
def _is_damped(minv, damp):
    d = False
    for k in range(minv.shape[0]):
        d |= damp[k] * minv[k] != 0.0
    return d


@jit
def _open(q, v, f, minv, damp, h, damped):
    """Opening half kick (with damping) and drift of the first step (``verlet._start``)."""
    if damped:
        for k in range(q.shape[0]):
            kick, pre, _, _ = _kick_factors(minv, damp, h, k)
            v[k] = v[k] * pre + kick * f[k]
            q[k] += h * v[k]
    else:
        for k in range(q.shape[0]):
            v[k] += 0.5 * h * minv[k] * f[k]
            q[k] += h * v[k]


@jit
def _differs(x, tile, m):
    """Whether x[:m] differs from tile[:m] (vectorised)."""
    bad = False
    for j in range(m):
        bad |= x[j] != tile[j]
    return bad


@jit
def _table_flags(flat, tile, width, lo, hi, flag, g, col0, tab, pat):
    """flag[g, col0 + k] = 1 where column k of rows lo..hi−1 of a row-wise table (``flat`` its
    rows end to end, ``width`` columns) differs from its period-2 pattern ``pat`` (2, width)
    (``tile``: the pattern repeated over BLOCK rows; lo even)."""
    if hi > lo and _differs(flat[lo * width :], tile, (hi - lo) * width):
        for k in range(width):
            d = False
            for i in range(lo, hi):
                d |= tab[i, k] != pat[i & 1, k]
            flag[g, col0 + k] = d


@jit
def _copy_columns(tab, full, row, c0, cols, m):
    """full[row[c0 + j]] = column cols[j] of the row-wise table, for the j that have a row: one
    pass over the table's rows (not one strided pass per column)."""
    dst = np.empty(len(cols), np.int64)
    src = np.empty(len(cols), np.int64)
    k = 0
    for j in range(len(cols)):
        if row[c0 + j] >= 0:
            dst[k] = row[c0 + j]
            src[k] = cols[j]
            k += 1
    if k > 0:
        for i in range(m):
            for j in range(k):
                full[dst[j], i] = tab[i, src[j]]


@jit
def _prepare(args, minv, damp, h, damped):
    """Column tables of (parameters, masses, damping, h): (rep, full, row, flag, any_kg, uniform,
    hinges_uniform).

    ``rep`` (N_COLS, min(BLOCK, n) + 2): each column's period-2 pattern (taken mid-chain), repeated;
    ``flag[g, c]``: block g (sites g·BLOCK...) differs from it, so reads ``full[row[c]]`` (n,);
    ``any_kg[g]``: block g has lateral stretch (else the cheaper θ force law, as ``chain_force``);
    ``uniform[g]``: every column used is constant on block g (but the alternating shear sign);
    ``hinges_uniform[g]``: so are the hinge and per-DOF columns (the site columns may vary).
    Cost: one vectorised read of the tables, masses and damping, plus a copy of each column
    that varies (benchmarks/run.py prints it in steps).
    """
    hprm, sprm = args[2], args[3]
    n = sprm.shape[0]
    nh, ns = hprm.shape[1], sprm.shape[1]
    ncols = N_COLS if damped else C_PRE_U
    nblocks = (n + BLOCK - 1) // BLOCK
    mid = 2 * ((n - 1) // 4)  # an even site with a hinge to its right (n ≥ 2)
    hpat = np.empty((2, nh))
    spat = np.empty((2, ns))
    for k in range(nh):
        hpat[0, k] = hprm[mid, k]
        hpat[1, k] = hprm[mid + 1, k] if mid + 1 < n - 1 else hprm[mid, k]
    for k in range(ns):
        spat[0, k] = sprm[mid, k]
        spat[1, k] = sprm[mid + 1, k]
    nrep = min(BLOCK, n) + 2  # a short chain needs no longer tables (calls may be frequent)
    rep = np.zeros((N_COLS, nrep))
    hcols = (H_REST, H_HALF_A, H_HALF_B, H_SIGN, H_KL, H_KS, H_KT)
    for c in range(C_TH0):
        rep[c, 0], rep[c, 1] = hpat[0, hcols[c]], hpat[1, hcols[c]]
    for c, k in ((C_TH0, S_THETA0), (C_KG, S_KG), (C_KR, S_KR)):
        rep[c, 0], rep[c, 1] = spat[0, k], spat[1, k]
    _, rep[C_C0, 0] = sincos(spat[0, S_THETA0])
    _, rep[C_C0, 1] = sincos(spat[1, S_THETA0])
    for fld in range(2):  # kicks and damping factors of the u (fld 0) and θ (fld 1) DOFs
        for j in range(2):
            kick, pre, post, cd = _kick_factors(minv, damp, h, fld * n + mid + j)
            rep[C_KICK_U + fld, j], rep[C_PRE_U + fld, j], rep[C_POST_U + fld, j], rep[C_CD_U + fld, j] = (
                kick, pre, post, cd)
    for c in range(N_COLS):
        for j in range(2, nrep):
            rep[c, j] = rep[c, j & 1]
    # which blocks differ from the patterns
    hflat, sflat = hprm.ravel(), sprm.ravel()
    htile, stile = np.empty((nrep - 2) * nh), np.empty((nrep - 2) * ns)
    mtile, dtile = np.empty((2, nrep - 2)), np.empty((2, nrep - 2))
    for j in range(htile.shape[0]):
        htile[j] = hpat[(j // nh) & 1, j % nh]
    for j in range(stile.shape[0]):
        stile[j] = spat[(j // ns) & 1, j % ns]
    for fld in range(2):
        for j in range(nrep - 2):
            mtile[fld, j] = minv[fld * n + mid + (j & 1)]
            dtile[fld, j] = damp[fld * n + mid + (j & 1)]
    flag = np.zeros((nblocks, N_COLS), np.uint8)
    sflag = np.zeros((nblocks, ns), np.uint8)
    any_kg = np.zeros(nblocks, np.uint8)
    uniform = np.zeros(nblocks, np.uint8)
    hinges_uniform = np.zeros(nblocks, np.uint8)
    for g in range(nblocks):
        a = g * BLOCK
        b = min(a + BLOCK, n)
        _table_flags(hflat, htile, nh, a, min(b, n - 1), flag, g, C_REST, hprm, hpat)
        _table_flags(sflat, stile, ns, a, b, sflag, g, 0, sprm, spat)
        flag[g, C_TH0], flag[g, C_KG], flag[g, C_KR] = sflag[g, S_THETA0], sflag[g, S_KG], sflag[g, S_KR]
        flag[g, C_C0] = flag[g, C_TH0]
        for fld in range(2):
            bad = _differs(minv[fld * n + a :], mtile[fld], b - a)
            if damped:
                bad |= _differs(damp[fld * n + a :], dtile[fld], b - a)
            flag[g, C_KICK_U + fld] = bad
            if damped:
                flag[g, C_PRE_U + fld] = flag[g, C_POST_U + fld] = flag[g, C_CD_U + fld] = bad
        kg_nz = rep[C_KG, 0] != 0.0 or rep[C_KG, 1] != 0.0
        if flag[g, C_KG]:
            kg_nz = False
            for i in range(a, b):
                kg_nz |= sprm[i, S_KG] != 0.0
        any_kg[g] = kg_nz
        uni = True
        for c in range(ncols):
            if c < C_TH0 or c >= C_KICK_U:
                uni &= flag[g, c] == 0 and (c == C_SIG or rep[c, 0] == rep[c, 1])
        hinges_uniform[g] = uni
        for c in range(C_TH0, C_KICK_U):
            uni &= flag[g, c] == 0 and rep[c, 0] == rep[c, 1]
        uniform[g] = uni
    # full columns where needed
    row = np.full(N_COLS, -1, np.int64)
    nf = 0
    for c in range(N_COLS):
        for g in range(nblocks):
            if flag[g, c] != 0 and row[c] < 0:
                row[c] = nf
                nf += 1
    full = np.empty((nf, n))
    _copy_columns(hprm, full, row, C_REST, hcols, n - 1)
    _copy_columns(sprm, full, row, C_TH0, (S_THETA0, S_KG, S_KR), n)
    for c in range(C_TH0):
        if row[c] >= 0:
            full[row[c], n - 1] = 0.0
    if row[C_C0] >= 0:
        col = full[row[C_C0]]
        for i in range(n):
            _, col[i] = sincos(sprm[i, S_THETA0])
    for fld in range(2):
        for which in range(4 if damped else 1):
            c = (C_KICK_U, C_PRE_U, C_POST_U, C_CD_U)[which] + fld
            if row[c] >= 0:
                col = full[row[c]]
                for i in range(n):
                    col[i] = _kick_factors(minv, damp, h, fld * n + i)[which]
    return (rep, full, row, flag, any_kg, uniform, hinges_uniform)


@jit(inline=True)  # inlined: its callers pass the column as a constant (a compiled copy each, else)
def _view(tables, c, g, a):
    """Column c from site a on, for block g (a in block g)."""
    rep, full, row, flag = tables[0], tables[1], tables[2], tables[3]
    if flag[g, c] != 0:
        return full[row[c], a:]
    return rep[c, (a & 1):]


@jit(inline=True)
def _at(tables, c, i):
    """Column c at site i."""
    rep, full, row = tables[0], tables[1], tables[2]
    if row[c] >= 0:
        return full[row[c], i]
    return rep[c, i & 1]


# ------------------------------------------------------------------ one block


@jit
def _force_kick(fl, ga, gb, ft, qu, qt, vu, vt, ku, kt, h, m, fou, fot, last):
    """Forces from the hinges (``hinge.chain_site_forces``) fused with the closing kick of this
    step and the opening kick and drift of the next (``verlet._end_start``); the last step:
    closing kick and F stored (``verlet._end``). No damping, no applied force in the block."""
    if last:
        for i in range(m):
            fu = fl[i + 1] - fl[i]
            fth = ft[i] - (gb[i] + ga[i + 1])
            vu[i] += param(ku, i) * fu
            vt[i] += param(kt, i) * fth
            fou[i] = fu
            fot[i] = fth
    else:
        for i in range(m):
            fu = fl[i + 1] - fl[i]
            fth = ft[i] - (gb[i] + ga[i + 1])
            vu[i] += 2.0 * param(ku, i) * fu
            qu[i] += h * vu[i]
            vt[i] += 2.0 * param(kt, i) * fth
            qt[i] += h * vt[i]


@jit
def _kick_drift(q, v, f, kick, h, fout, m, last):
    """``_force_kick``'s kicks and drift for given forces f (one field)."""
    if last:
        for i in range(m):
            v[i] += param(kick, i) * f[i]
            fout[i] = f[i]
    else:
        for i in range(m):
            v[i] += 2.0 * param(kick, i) * f[i]
            q[i] += h * v[i]


@jit
def _kick_drift_damped(q, v, f, kick, pre, post, h, fout, m, last):
    """``_kick_drift`` with semi-implicit on-site damping (``verlet._end_start``, ``verlet._end``)."""
    if last:
        for i in range(m):
            v[i] = (v[i] + param(kick, i) * f[i]) * param(post, i)
            fout[i] = f[i]
    else:
        for i in range(m):
            v[i] = (v[i] + param(kick, i) * f[i]) * param(post, i) * param(pre, i) + param(kick, i) * f[i]
            q[i] += h * v[i]


@jit
def _dissipation(vu, vt, cdu, cdt, x, m):
    """Σ c v² over the block's u and θ DOFs (``hinge.lane_sum``: vectorised, fixed order)."""
    for i in range(m):
        x[i] = param(cdu, i) * vu[i] * vu[i] + param(cdt, i) * vt[i] * vt[i]
    return lane_sum(x, m)


@jit
def _has_drive(drives, a, m):
    """Whether a drive (applied force or prescribed displacement) acts on sites a..a+m−1."""
    dof, n = drives[0], drives[3]
    for d in range(dof.shape[0]):
        if a <= dof[d] % n < a + m:
            return True
    return False


@jit
def _block_body(qu, qt, vu, vt, fou, fot, prm, fac, w, a, m, right, ub, tb, th0_next, fl_left, gb_left, with_kg,
                h, last, damped, drives, gvals):
    """``_block`` with its parameters ``prm`` (``hinge.chain_block_hinges``) and per-DOF factors
    ``fac`` = (kick u, kick θ, pre u, pre θ, post u, post θ, c u, c θ), columns or uniform."""
    fr, gbr = chain_block_hinges(qu, qt, prm, w, m, right, ub, tb, th0_next, fl_left, gb_left, with_kg)
    ku, kt, preu, pret, postu, postt, cdu, cdt = fac
    if not damped and not _has_drive(drives, a, m):
        _force_kick(w[W_FL], w[W_GA], w[W_GB], w[W_FT], qu, qt, vu, vt, ku, kt, h, m, fou, fot, last)
        return fr, gbr, 0.0
    fu, ft = w[W_X], w[W_FT]
    chain_site_forces(w[W_FL], w[W_GA], w[W_GB], fu, ft, m)
    dof, mode, n = drives[0], drives[1], drives[3]
    for d in range(dof.shape[0]):  # applied forces, in the order of common.position_forces
        i = dof[d] % n - a
        if mode[d] == MODE_FORCE and 0 <= i < m:
            if dof[d] < n:
                fu[i] += gvals[d]
            else:
                ft[i] += gvals[d]
    for d in range(dof.shape[0]):  # keep f current on prescribed DOFs: their work is −f·v
        i = dof[d] % n - a
        if mode[d] == MODE_DISPLACEMENT and 0 <= i < m:
            if dof[d] < n:
                fou[i] = fu[i]
            else:
                fot[i] = ft[i]
    diss = 0.0
    if damped:
        diss = _dissipation(vu, vt, cdu, cdt, w[W_Y], m)
        _kick_drift_damped(qu, vu, fu, ku, preu, postu, h, fou, m, last)
        _kick_drift_damped(qt, vt, ft, kt, pret, postt, h, fot, m, last)
    else:
        _kick_drift(qu, vu, fu, ku, h, fou, m, last)
        _kick_drift(qt, vt, ft, kt, h, fot, m, last)
    return fr, gbr, diss


@jit
def _block(qu, qt, vu, vt, fou, fot, tables, w, g, a, m, right, ub, tb, fl_left, gb_left, h, last, damped, drives,
           gvals):
    """One step on the m sites a..a+m−1 of block g (state views from site a).

    ``right``: the hinge a+m−1 ↔ a+m exists, site a+m has (u, θ) = (ub, tb) at the old state;
    (fl_left, gb_left): the hinge a−1 ↔ a at the old state. Returns that right hinge's
    (fl, gb) and the block's damping power (v½, before the kicks). Three compiled variants of
    the loops, by what the block's parameters are: all uniform (scalars), the hinges' and the
    per-DOF factors uniform (scalars) but the site columns (θ0, k_g, k_r) not (columns: a chain
    graded in its lateral hinges streams one or two columns, its hinge loop stays as cheap as a
    uniform one's), or any (columns).
    """
    th0_next = _at(tables, C_TH0, a + m) if right else 0.0
    with_kg = tables[4][g] != 0
    r = tables[0]
    p = a & 1
    sig = (r[C_SIG, p], r[C_SIG, p + 1])
    if tables[6][g] != 0:
        fac = (r[C_KICK_U, 0], r[C_KICK_T, 0], r[C_PRE_U, 0], r[C_PRE_T, 0], r[C_POST_U, 0], r[C_POST_T, 0],
               r[C_CD_U, 0], r[C_CD_T, 0])
        if tables[5][g] != 0:
            prm = (r[C_REST, 0], r[C_HA, 0], r[C_HB, 0], sig, r[C_KL, 0], r[C_KS, 0], r[C_KT, 0], r[C_TH0, 0],
                   r[C_KG, 0], r[C_KR, 0], r[C_C0, 0])
            return _block_body(qu, qt, vu, vt, fou, fot, prm, fac, w, a, m, right, ub, tb, th0_next, fl_left,
                               gb_left, with_kg, h, last, damped, drives, gvals)
        sites = (r[C_REST, 0], r[C_HA, 0], r[C_HB, 0], sig, r[C_KL, 0], r[C_KS, 0], r[C_KT, 0],
                 _view(tables, C_TH0, g, a), _view(tables, C_KG, g, a), _view(tables, C_KR, g, a),
                 _view(tables, C_C0, g, a))
        return _block_body(qu, qt, vu, vt, fou, fot, sites, fac, w, a, m, right, ub, tb, th0_next, fl_left, gb_left,
                           with_kg, h, last, damped, drives, gvals)
    cols = (_view(tables, C_REST, g, a), _view(tables, C_HA, g, a), _view(tables, C_HB, g, a),
            _view(tables, C_SIG, g, a), _view(tables, C_KL, g, a), _view(tables, C_KS, g, a),
            _view(tables, C_KT, g, a), _view(tables, C_TH0, g, a), _view(tables, C_KG, g, a),
            _view(tables, C_KR, g, a), _view(tables, C_C0, g, a))
    facs = (_view(tables, C_KICK_U, g, a), _view(tables, C_KICK_T, g, a), _view(tables, C_PRE_U, g, a),
            _view(tables, C_PRE_T, g, a), _view(tables, C_POST_U, g, a), _view(tables, C_POST_T, g, a),
            _view(tables, C_CD_U, g, a), _view(tables, C_CD_T, g, a))
    return _block_body(qu, qt, vu, vt, fou, fot, cols, facs, w, a, m, right, ub, tb, th0_next, fl_left, gb_left,
                       with_kg, h, last, damped, drives, gvals)


@jit
def _segment(qu, qt, vu, vt, fou, fot, base, lo, hi, nxt_u, nxt_t, has_next, fl_left, gb_left, tables, w, h,
             last, damped, drives, gvals):
    """One step on sites lo..hi−1 of arrays that hold site i at index i − base.

    Blocks follow the global grid of ``BLOCK`` (their parameter flags). (nxt_u, nxt_t): the
    old state of site hi when ``has_next`` (the next segment's first site). Returns the
    (fl, gb) of the segment's right hinge and the damping power.
    """
    diss = 0.0
    a = lo
    while a < hi:
        g = a // BLOCK
        b = min((g + 1) * BLOCK, hi)
        k = a - base
        m = b - a
        if b < hi:
            ub, tb, right = qu[k + m], qt[k + m], True
        else:
            ub, tb, right = nxt_u, nxt_t, has_next
        fl_left, gb_left, d = _block(qu[k:], qt[k:], vu[k:], vt[k:], fou[k:], fot[k:], tables, w, g, a, m, right,
                                     ub, tb, fl_left, gb_left, h, last, damped, drives, gvals)
        diss += d
        a = b
    return fl_left, gb_left, diss


# ------------------------------------------------------------------ drives


@jit
def _drive_values(drives, t, gvals):
    """Applied-force values of the drives at t (0 for the others)."""
    dof, mode, shape, prm = drives[0], drives[1], drives[2], drives[4]
    for d in range(dof.shape[0]):
        gvals[d] = 0.0
        if mode[d] == MODE_FORCE:
            gvals[d], _ = waveform(shape[d], prm[d], t)


@jit
def _prescribe(drives, t, state, base, lo, hi):
    """Prescribed displacements at t on the sites lo..hi−1 of ``state`` (qu, qt, vu, vt; site i at
    index i − base), in drive order as ``common.apply_prescribed``."""
    dof, mode, shape, prm, n = drives[0], drives[1], drives[2], drives[4], drives[3]
    for d in range(dof.shape[0]):
        i = dof[d] % n
        if mode[d] == MODE_DISPLACEMENT and lo <= i < hi:
            fld = 0 if dof[d] < n else 1
            g, dg = waveform(shape[d], prm[d], t)
            state[fld][i - base] = g
            state[2 + fld][i - base] = dg


@jit
def _power(drives, gvals, state, base, lo, hi, out):
    """Power g·v of each applied force on sites lo..hi−1 into out[d] (others untouched)."""
    dof, mode, n = drives[0], drives[1], drives[3]
    for d in range(dof.shape[0]):
        i = dof[d] % n
        if mode[d] == MODE_FORCE and lo <= i < hi:
            out[d] = gvals[d] * state[2 + (0 if dof[d] < n else 1)][i - base]


@jit
def _drives_of(terms, n):
    return (terms.drv_dof, terms.drv_mode, terms.drv_shape, n, terms.drv_prm)


# ------------------------------------------------------------------ the ranges of one call


@jit
def _n_ranges(n):
    """Ranges of a chain (about ``RANGE_SITES`` each, by N only: serial and threaded kernels cut
    the chain alike, so they do the same arithmetic and sum their ledgers in the same order)."""
    return max(1, n // RANGE_SITES)


@jit
def _n_chunks(n):
    """Chunks of consecutive ranges the threaded kernel shares out (fixed by N, not by thread
    count, so the compiled kernel is cacheable)."""
    return max(1, min(n // RANGE_MIN, MAX_CHUNKS))


@jit
def _edge(n, nr, r):
    """First site of range r of nr (a block boundary; n for r = nr)."""
    return n if r >= nr else (r * n // nr) // BLOCK * BLOCK


@jit
def _ledger(acc, h, damped, diss, p0, p1):
    """The energy ledger of one step, as ``verlet_advance`` adds it: ``diss`` the damping power
    of each range, ``p0``/``p1`` the power of each drive at the step's start/end time."""
    if damped:
        d = 0.0
        for r in range(diss.shape[0]):
            d += diss[r]
        acc[ACC_DISSIPATED] += h * d
    a = 0.0
    for k in range(p0.shape[0]):
        a += p0[k]
    b = 0.0
    for k in range(p1.shape[0]):
        b += p1[k]
    acc[ACC_WORK] += 0.5 * h * (a + b)


@jit
def _prescribed_power(drives, f, state, lo, hi, out):
    """Power −f·v of each prescribed displacement on sites lo..hi−1 into out[d]: the work it does
    against the rest of the chain (``common.applied_power``); ``_block_body`` keeps f current on
    those DOFs, ``state`` holds site i at index i."""
    dof, mode, n = drives[0], drives[1], drives[3]
    for d in range(dof.shape[0]):
        i = dof[d] % n
        if mode[d] == MODE_DISPLACEMENT and lo <= i < hi:
            out[d] = -(f[dof[d]] * state[2 + (0 if dof[d] < n else 1)][i])


@jit
def _hold_rates(drives, state, lo, hi, out):
    """The imposed rates of the prescribed displacements on sites lo..hi−1 into out[d], right
    after ``_prescribe`` (``_against`` makes them powers once the step's forces are in)."""
    dof, mode, n = drives[0], drives[1], drives[3]
    for d in range(dof.shape[0]):
        i = dof[d] % n
        if mode[d] == MODE_DISPLACEMENT and lo <= i < hi:
            out[d] = state[2 + (0 if dof[d] < n else 1)][i]


@jit
def _against(drives, f, lo, hi, out):
    """out[d] ← −f·out[d] for the prescribed displacements on sites lo..hi−1 (``_hold_rates``)."""
    dof, mode, n = drives[0], drives[1], drives[3]
    for d in range(dof.shape[0]):
        if mode[d] == MODE_DISPLACEMENT and lo <= dof[d] % n < hi:
            out[d] = -(f[dof[d]] * out[d])


@jit
def _start_drives(drives, t, gvals, state, f, lo, hi, p0):
    """Before a step from t: the drives' power at t (v½; f the force at t) on sites lo..hi−1."""
    _drive_values(drives, t, gvals)
    _power(drives, gvals, state, runtime(0), lo, hi, p0)
    _prescribed_power(drives, f, state, lo, hi, p0)


# ------------------------------------------------------------------ time blocks over ranges


@jit
def _snapshot(q, v, n, lo, hi, k, halo):
    """Old state of the k sites on each side of lo..hi−1 (fewer at the chain's ends) into
    halo[0] (left) and halo[1] (right), rows (u, θ, u̇, θ̇)."""
    wl, wr = max(0, lo - k), min(n, hi + k)
    for j in range(lo - wl):
        halo[0, 0, j] = q[wl + j]
        halo[0, 1, j] = q[n + wl + j]
        halo[0, 2, j] = v[wl + j]
        halo[0, 3, j] = v[n + wl + j]
    for j in range(wr - hi):
        halo[1, 0, j] = q[hi + j]
        halo[1, 1, j] = q[n + hi + j]
        halo[1, 2, j] = v[hi + j]
        halo[1, 3, j] = v[n + hi + j]


@jit
def _range_steps(q, v, f, tables, w, halo, hf, drives, gvals, p0, p1, diss, n, lo, hi, k, t, h, last_step, damped):
    """k steps of sites lo..hi−1 from t, with the halos of ``_snapshot`` advanced alongside (their
    outer ends free: wrong values enter one site per step and never reach lo..hi−1). Writes
    only the range's own sites of q, v, f; per step s: the damping power into diss[s], the
    drives' powers into p0[s], p1[s] (those on the range's sites)."""
    wl, wr = max(0, lo - k), min(n, hi + k)
    G = (q[:n], q[n:], v[:n], v[n:])
    L = (halo[0, 0], halo[0, 1], halo[0, 2], halo[0, 3])
    R = (halo[1, 0], halo[1, 1], halo[1, 2], halo[1, 3])
    for s in range(k):
        last = s == last_step
        _start_drives(drives, t, gvals, G, f, lo, hi, p0[s])
        t += h
        _prescribe(drives, t, L, wl, wl, lo)
        _prescribe(drives, t, G, runtime(0), lo, hi)
        _prescribe(drives, t, R, hi, hi, wr)
        _drive_values(drives, t, gvals)
        _power(drives, gvals, G, runtime(0), lo, hi, p1[s])
        _hold_rates(drives, G, lo, hi, p1[s])
        fl, gb = 0.0, 0.0
        if lo > 0:
            fl, gb, _ = _segment(L[0], L[1], L[2], L[3], hf[0], hf[1], wl, wl, lo, q[lo], q[n + lo], runtime(True),
                                 0.0, 0.0, tables, w, h, last, damped, drives, gvals)
        fl, gb, diss[s] = _segment(G[0], G[1], G[2], G[3], f[:n], f[n:], runtime(0), lo, hi, R[0][0], R[1][0], hi < n,
                                   fl, gb, tables, w, h, last, damped, drives, gvals)
        _against(drives, f, lo, hi, p1[s])
        if hi < n and not last:
            _segment(R[0], R[1], R[2], R[3], hf[0], hf[1], hi, hi, wr, 0.0, 0.0, runtime(False), fl, gb, tables, w, h,
                     last, damped, drives, gvals)


@jit
def _work(n, nd, n_chunks):
    """Scratch of one call: (halo, halo forces, block scratch, drive values) per range or chunk,
    and the per-step ledger terms of each range (p0, p1, diss; ``_time_block_end``)."""
    nr, kt = _n_ranges(n), TIME_BLOCK
    return (np.zeros((nr, 2, 4, kt)), np.empty((n_chunks, 2, kt)), np.empty((n_chunks, N_W, min(BLOCK, n) + 1)),
            np.zeros((n_chunks, nd)), np.zeros((nr, kt, nd)), np.zeros((nr, kt, nd)), np.zeros((kt, nr)))


@jit
def _time_block_start(q, v, n, k, work):
    """Before k steps: every range's halos at the old state (no range has moved yet)."""
    halo, p0, p1 = work[0], work[4], work[5]
    nr = halo.shape[0]
    for r in range(nr):
        _snapshot(q, v, n, _edge(n, nr, r), _edge(n, nr, r + 1), k, halo[r])
    p0[:] = 0.0
    p1[:] = 0.0


@jit
def _chunk_steps(q, v, f, tables, work, drives, c, n_chunks, n, k, t, h, last_step, damped):
    """k steps of the ranges of chunk c (of n_chunks: the ranges in order, shared out as evenly
    as they go), one range after the other, each while it is in cache."""
    halo, hf, w, gvals, p0, p1, diss = work
    nr = halo.shape[0]
    for r in range(c * nr // n_chunks, (c + 1) * nr // n_chunks):
        _range_steps(q, v, f, tables, w[c], halo[r], hf[c], drives, gvals[c], p0[r], p1[r], diss[:, r], n,
                     _edge(n, nr, r), _edge(n, nr, r + 1), k, t, h, last_step, damped)


@jit
def _time_block_end(acc, h, damped, k, t, work):
    """The ledger of the k steps, step by step, each range's terms in range order (the same sums
    whatever the chunks and threads); returns t + k h as the steps add it."""
    p0, p1, diss = work[4], work[5], work[6]
    nr, nd = p0.shape[0], p0.shape[2]
    sp0, sp1 = np.zeros(nd), np.zeros(nd)
    for s in range(k):
        for d in range(nd):  # each drive's power from the range that holds its site
            sp0[d] = 0.0
            sp1[d] = 0.0
            for r in range(nr):
                sp0[d] += p0[r, s, d]
                sp1[d] += p1[r, s, d]
        _ledger(acc, h, damped, diss[s], sp0, sp1)
        t += h
    return t


# ------------------------------------------------------------------ the kernels


def prepare(args, minv: np.ndarray, damp: np.ndarray, h: float) -> tuple:
    """The column tables of the fused kernels for these parameters, masses, damping and step
    (``_prepare``): what ``chain_verlet_advance_prepared`` takes, built once per stepper."""
    return _prepare(args, minv, damp, h, _is_damped(minv, damp))


@jit
def chain_verlet_advance_prepared(tables, args, q, v, f, minv, damp, terms, t, h, nsteps, acc):
    """``chain_verlet_advance`` with its tables given (``prepare`` of the same args, minv, damp
    and h), so a stepper that calls it often pays their preparation once."""
    if nsteps <= 0:
        return t
    n = args[3].shape[0]
    damped = _is_damped(minv, damp)
    _open(q, v, f, minv, damp, h, damped)
    drives = _drives_of(terms, n)
    work = _work(n, drives[0].shape[0], 1)
    s0 = 0
    while s0 < nsteps:
        k = min(TIME_BLOCK, nsteps - s0)
        _time_block_start(q, v, n, k, work)
        _chunk_steps(q, v, f, tables, work, drives, runtime(0), runtime(1), n, k, t, h, nsteps - 1 - s0, damped)
        t = _time_block_end(acc, h, damped, k, t, work)
        s0 += k
    _count(acc, nsteps)
    return t


@jit(parallel=True)
def chain_verlet_advance_parallel_prepared(tables, args, q, v, f, minv, damp, terms, t, h, nsteps, acc):
    """``chain_verlet_advance_parallel`` with its tables given (``prepare``)."""
    if nsteps <= 0:
        return t
    n = args[3].shape[0]
    damped = _is_damped(minv, damp)
    nd2 = q.shape[0]
    nb = max(1, min(nd2 // DOF_BLOCK, 16))
    for c in prange(nb):
        lo, hi = c * nd2 // nb, (c + 1) * nd2 // nb
        _open(q[lo:hi], v[lo:hi], f[lo:hi], minv[lo:hi], damp[lo:hi], h, damped)
    drives = _drives_of(terms, n)
    nch = _n_chunks(n)
    work = _work(n, drives[0].shape[0], nch)
    s0 = 0
    while s0 < nsteps:
        k = min(TIME_BLOCK, nsteps - s0)
        _time_block_start(q, v, n, k, work)
        for c in prange(nch):
            _chunk_steps(q, v, f, tables, work, drives, c, nch, n, k, t, h, nsteps - 1 - s0, damped)
        t = _time_block_end(acc, h, damped, k, t, work)
        s0 += k
    _count(acc, nsteps)
    return t


@jit
def chain_verlet_advance(args, q, v, f, minv, damp, terms, t, h, nsteps, acc):
    """``verlet_advance`` for ``hinge.chain_force`` (same arguments and results), fused, and
    blocked in time: each range of ``RANGE_SITES`` sites takes ``TIME_BLOCK`` steps while it is
    in cache (halos: module docstring), so a long chain streams through memory once per
    ``TIME_BLOCK`` steps. Only where ``fusable`` holds (the caller checks). Prepares its tables
    on every call (``Stepper`` keeps them: ``chain_verlet_advance_prepared``).
    """
    if nsteps <= 0:
        return t
    tables = _prepare(args, minv, damp, h, _is_damped(minv, damp))
    return chain_verlet_advance_prepared(tables, args, q, v, f, minv, damp, terms, t, h, nsteps, acc)


@jit
def chain_verlet_advance_parallel(args, q, v, f, minv, damp, terms, t, h, nsteps, acc):
    """``chain_verlet_advance`` with the chain's ranges shared out among numba's threads (in
    ``_n_chunks`` fixed chunks), which meet once per ``TIME_BLOCK`` steps. Bit-identical to it:
    the ranges, not the chunks, fix the arithmetic."""
    if nsteps <= 0:
        return t
    tables = _prepare(args, minv, damp, h, _is_damped(minv, damp))
    return chain_verlet_advance_parallel_prepared(tables, args, q, v, f, minv, damp, terms, t, h, nsteps, acc)
