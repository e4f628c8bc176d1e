"""The differentiable integrators as the tape's ``Steps`` (``tape.Steps``: forward run with
checkpoints and records, replay of a segment, reverse of a segment, tangent), on the compiled
sweeps of velocity Verlet (``sweeps``), a splitting (``splitting``) and the implicit midpoint
rule (``midpoint``), and their fast paths, chosen in one place (``steps_of``: ``ACCELERATORS``,
keyed by the integrator and the model's form).

The model part of every reverse step takes the run's ``form`` (``Trajectory.form``: a chain's
columns, a grid sheet's hinge families, or the model's own adjoint kernel). The fast paths:

- velocity Verlet on a chain-ordered chain without velocity terms (``ChainColumns``): the run
  and its replay with the column force (``sweeps.chain_forward``/``chain_replay``; a long damped
  chain's run by the engine's fused kernel, ``_engine_run``), each state's force taken again
  in the reverse step, so a segment's replayed states fit in cache (``CACHE_MB``);
- ... a uniform one (``UniformChain``): replay and reverse with scalar parameters
  (``sweeps.chain_uniform_replay``/``_reverse``), a long one window by window
  (``sweeps.chain_uniform_tiles``);
- velocity Verlet on a uniform grid sheet (``UniformSheet``: ``sweeps.sheet_uniform_reverse``);
- a splitting on a uniform chain or grid sheet (``UniformChainSplit``, ``UniformSheetSplit``:
  ``splitting.Uniform``, stage forces and adjoints from the shared law).

Each gives the generic path's records bit for bit and its gradient to rounding
(tests/design); ``Trajectory``'s flags ``column_sweeps``, ``uniform_sweeps``, ``engine_forward``,
``tiles`` turn them off for comparisons.
"""

from __future__ import annotations

import numpy as np

from flexmm.design import midpoint, splitting, sweeps
from flexmm.design.kernels import (N_V, chain_add_columns, sheet_grid_add, sheet_uniform,
                                   sheet_uniform_scratch, with_tables)
from flexmm.design.tape import (ENGINE_MIN_STEPS, GradientError, Raw, Records, Steps, chain_segment, stack,
                               tile_segment)
from flexmm.integrators import verlet_chain
from flexmm.integrators.common import ACC_HEADER
from flexmm.models.hinge import H_SIGN
from flexmm.models.sheet_kernels import grid_scratch

#: the column sweeps keep every state only if they fit in this many MB (a cache's size)
CACHE_MB = 4.0
#: chains of this many sites or more run forward with the engine's time-blocked kernel when it
#: gives the same bits (``ChainColumns._engine_run``) ...
ENGINE_SITES = 4096
#: a uniform chain of this many sites or more (without contacts or loads) replays and sweeps back
#: each segment of ``tape.TILE_STEPS`` steps in windows of ``TILE_SITES`` sites plus halos
#: (``sweeps.chain_uniform_tiles``): longer segments than the whole chain's states in cache allow
TILE_MIN_SITES = 8192
TILE_SITES = 2048


#: no observed DOFs, no records (a replay)
_NONE, _NO_RECORD = np.empty(0, np.int64), np.empty((1, 0))


class _Common(Steps):
    """What every integrator's steps share: the run and the replay of a segment by the
    integrator's compiled loop (``loop``: checkpoints every ``seg`` steps, records every
    ``stride``; with seg = 1 and no records, a replay), keeping what its reverse step reads
    (``keep``), and the reverse of the run's start."""

    #: what the reverse step reads besides (q, v, f, t), kept by the forward run (``loop``'s K)
    K: np.ndarray

    def loop(self, q, v, f, t, nsteps, seg, stride, obs, ck, K, rec) -> int:
        """``nsteps`` steps from (q, v, f, t) in place by the integrator's compiled loop (checkpoints
        ``ck`` = (CQ, CV, CF, CT), records ``rec`` = (Rq, Rv, Rf), K: ``keep``'s); returns the first
        step that did not converge, or −1."""
        raise NotImplementedError

    def keep(self, rows: int | None, where: str) -> np.ndarray:
        """``loop``'s K for ``rows`` steps (None: nothing kept), named by ``where``
        (``Trajectory._scratch_array``)."""
        raise NotImplementedError

    def states(self, SQ, SV, SF, ST, K) -> tuple:
        """The states as ``reverse`` reads them."""
        return SQ, SV, SF, ST, K

    def check(self, failed: int) -> None:
        """Refuse a run whose step ``failed`` (≥ 0) did not converge."""

    def forward(self, seg, scratch=False, keep=False):
        traj = self.traj
        q, v, f = self.start(self.args, self.terms)
        ck = traj._buffers(self.n, traj.nsteps // seg + 1, "checkpoints" if scratch else "")
        rec = traj._records()
        self.K = self.keep(traj.nsteps if keep else None, "checkpoints")
        self._run(q, v, f, seg, ck, rec)
        return rec, (*ck, seg)

    def _run(self, q, v, f, seg, ck, rec) -> None:
        traj = self.traj
        self.check(self.loop(q, v, f, traj.t0, traj.nsteps, seg, traj.stride, traj.obs, ck, self.K,
                             (rec.q, rec.v, rec.f)))

    def kept(self, checkpoints):
        return self.states(*checkpoints[:4], self.K)

    def replay(self, checkpoints, c, m):
        seg = checkpoints[4]
        SQ, SV, SF, ST = self.traj._buffers(self.n, seg + 1, "segment")
        K = self.keep(seg, "segment")
        self._replay(*(x[c] for x in checkpoints[:4]), m, SQ, SV, SF, ST, K)
        return self.states(SQ, SV, SF, ST, K)

    def _replay(self, q0, v0, f0, t0, m, SQ, SV, SF, ST, K) -> None:
        """The m steps from a checkpoint, every state kept (the run's loop)."""
        self.loop(q0.copy(), v0.copy(), f0.copy(), t0, m, 1, m + 1, _NONE, (SQ, SV, SF, ST), K, (_NO_RECORD,) * 3)

    def reverse_start(self, args, terms) -> None:
        """Reverse of the run's start (prescription, initial force): (lq, lv) become the gradients
        w.r.t. q0, v0; the column forms' parameter adjoints are added to (g1, g2)."""
        traj, raw, a, form = self.traj, self.raw, self.adj, self.form
        q0 = raw.q0.copy()
        v0 = raw.v0.copy()
        sweeps.apply_prescribed_only(terms, q0, v0, traj.t0)
        sweeps.reverse_initial(args, terms, q0, v0, traj.t0, a.lq, a.lv, a.lf, a.g1, a.g2, a.gcon, a.gdrv, a.gdash,
                               form)
        if form[0] == sweeps.FORM_CHAIN:  # a loaded chain's t2: its site table, then its loads' values
            n, flat = traj._nchain, a.g2.reshape(-1)
            chain_add_columns(form[5], a.g1, flat[: 3 * n].reshape(n, 3))
            flat[3 * n :] += form[12]
        elif form[0] == sweeps.FORM_GRID:
            sheet_grid_add(form[5], form[6], form[7], a.g1, a.g2, form[1], traj._grid[1])

    def start(self, args, terms) -> tuple:
        """(q, v, f) at the run's start: the driven DOFs prescribed, the total force."""
        raw = self.raw
        q, v, f = raw.q0.copy(), raw.v0.copy(), np.empty_like(raw.q0)
        sweeps.initial_force(args, terms, q, v, f, self.traj.t0)
        return q, v, f


# ---------------------------------------------------------------- velocity Verlet (``sweeps``)


class Verlet(_Common):
    """Velocity Verlet (``sweeps.forward``, ``replay``, ``reverse``, ``tangent``): a state is (q, v,
    f, t), with velocity terms also the f_a of the step into it (``integrators.verlet.step_force``)."""

    def __init__(self, traj, raw, form):
        super().__init__(traj, raw, form)
        self.args, self.terms, self.kick, self.pre, self.post = traj.bind(raw)
        self.state_bytes = (4 if traj._vdep else 3) * self.n * 8  # q, v, f (and f_a)

    def loop(self, q, v, f, t, nsteps, seg, stride, obs, ck, K, rec):
        sweeps.forward(self.args, self.terms, self.kick, self.pre, self.post, q, v, f, t, self.traj.h, nsteps, seg,
                       stride, obs, *ck, K, *rec)
        return -1

    def _replay(self, q0, v0, f0, t0, m, SQ, SV, SF, ST, K):
        sweeps.replay(self.args, self.terms, self.kick, self.pre, self.post, q0, v0, f0, t0, self.traj.h, m,
                      SQ, SV, SF, ST, K)

    def keep(self, rows, where):
        if rows is None or not self.traj._vdep:
            return np.empty((0, self.n))
        return self.traj._scratch_array(f"{where}.fa", (rows + 1, self.n))

    def begin(self, adj):
        super().begin(adj)
        n = self.n
        self.lw, self.GK, self.GV = np.zeros(n), np.zeros(n), np.zeros(n)

    def reverse(self, states, k0, m):
        a, traj = self.adj, self.traj
        sweeps.reverse(self.args, self.terms, self.kick, self.pre, self.post, *states, traj.h, k0, m, traj.stride,
                       traj.obs, a.dq, a.dv, a.df, a.lq, a.lv, a.lf, self.lw, a.g1, a.g2, self.GK, self.GV, a.gcon,
                       a.gdrv, a.gdash, self.form)

    def end(self, checkpoints):
        a, raw = self.adj, self.raw
        self.GK += self.lw * checkpoints[2][0]  # the products of the first step's λw with the initial state
        self.GV += self.lw * checkpoints[1][0]
        self.reverse_start(self.args, self.terms)
        # K = h/2 m⁻¹, P = 1 − h/2 c m⁻¹, S = 1/(1 + h/2 c m⁻¹); GV = ∂J/∂P + S² ∂J/∂S
        hh = 0.5 * self.traj.h
        g_minv = hh * self.GK - hh * raw.damp * self.GV
        g_damp = -hh * raw.minv * self.GV
        return Raw(a.g1, a.g2, g_minv, g_damp, a.gcon, a.gdrv, a.lq, a.lv, a.gdash)

    def tangent(self, directions, rec, TQ, TV, TF):
        traj, raw = self.traj, self.raw
        hh = 0.5 * traj.h

        def d(name):
            return stack(raw, directions, name)

        dminv, ddamp = d("minv"), d("damp")
        dg = ddamp * raw.minv + raw.damp * dminv  # d(c m⁻¹)
        DK = hh * dminv
        DP = -hh * dg
        DS = -(self.post * self.post) * hh * dg
        q, v, f = raw.q0.copy(), raw.v0.copy(), np.empty(self.n)
        sweeps.tangent(self.args, self.terms, self.kick, self.pre, self.post, q, v, f, traj.t0, traj.h, traj.nsteps,
                       traj.stride, traj.obs, d("t1"), d("t2"), DK, DP, DS, d("con"), d("drv"), d("dash"), d("q0"),
                       d("v0"), rec.q, rec.v, rec.f, TQ, TV, TF)


class ChainColumns(Verlet):
    """A chain-ordered chain without velocity terms: the run and replay with the column force
    (the same bits), the replay keeping (q, v) only and the reverse step taking each state's force
    again; every state kept only if they fit in ``CACHE_MB``."""

    @classmethod
    def applies(cls, traj, raw, form) -> bool:
        return not traj._vdep

    def budget_mb(self, memory_mb):
        return min(memory_mb, CACHE_MB)

    def segment(self, nsteps, memory_mb, asked):
        return asked or chain_segment(nsteps, self.n, 2 * self.n * 8, memory_mb)  # replayed states: q, v

    def _run(self, q, v, f, seg, ck, rec):
        if not self._engine_run(q, v, f, seg, ck, rec):
            form, traj = self.form, self.traj
            sweeps.chain_forward(form[3], form[1] != 0, form[10], form[11], self.terms, self.kick, self.pre, self.post,
                                 q, v, f, traj.t0, traj.h, traj.nsteps, seg, traj.stride, traj.obs, *ck, rec.q, rec.v,
                                 rec.f)

    def _engine_run(self, q, v, f, seg, ck, rec: Records) -> bool:
        """The forward run by the engine's fused, time-blocked chain kernel
        (``integrators.verlet_chain``), stopping at each checkpoint and record, where it gives
        ``chain_forward``'s bits and is faster: a damped chain (undamped, the engine adds the two
        half kicks between steps as one: a different rounding) of ``ENGINE_SITES`` sites or more
        (shorter ones fit in cache, where ``chain_forward`` is as fast), stopping at most every
        ``ENGINE_MIN_STEPS`` steps (each call is blocked in time over its steps). Returns whether
        it ran."""
        traj, raw, args, terms = self.traj, self.raw, self.args, self.terms
        if (not traj.engine_forward or raw.t2.shape[0] < ENGINE_SITES or min(seg, traj.stride) < ENGINE_MIN_STEPS
                or not np.any(raw.damp * raw.minv != 0.0)
                or not verlet_chain.fusable(args, q, raw.minv, raw.damp, terms)):
            return False
        CQ, CV, CF, CT = ck
        tables = verlet_chain.prepare(args, raw.minv, raw.damp, traj.h)
        ledger = np.zeros(ACC_HEADER)
        t, k = traj.t0, 0
        while True:
            if k % seg == 0:
                CQ[k // seg], CV[k // seg], CF[k // seg], CT[k // seg] = q, v, f, t
            if k % traj.stride == 0:
                j = k // traj.stride
                rec.q[j], rec.v[j], rec.f[j] = q[traj.obs], v[traj.obs], f[traj.obs]
            if k == traj.nsteps:
                return True
            m = min(seg - k % seg, traj.stride - k % traj.stride, traj.nsteps - k)
            t = verlet_chain.chain_verlet_advance_prepared(tables, args, q, v, f, raw.minv, raw.damp, terms, t, traj.h,
                                                           m, ledger)
            k += m

    def _replay(self, q0, v0, f0, t0, m, SQ, SV, SF, ST, K):
        form = self.form
        sweeps.chain_replay(form[3], form[1] != 0, form[10], form[11], self.terms, self.kick, self.pre, self.post,
                            q0, v0, f0, t0, self.traj.h, m, SQ, SV, ST)


class UniformChain(ChainColumns):
    """A uniform chain (``kernels.chain_uniform``, no DOFs past the chain's): replay and reverse
    with scalar parameters (``sweeps.chain_uniform_replay``, ``chain_uniform_reverse``; the
    integrator factors scalar per field where constant, ``field_factors``), keeping each state's
    force and cos/sin; a long one (``_tiled``) window by window (``sweeps.chain_uniform_tiles``)."""

    @classmethod
    def applies(cls, traj, raw, form):
        return not traj._vdep and raw.q0.size == 2 * traj._nchain

    def __init__(self, traj, raw, form):
        super().__init__(traj, raw, form)
        self.u, self.fac = form[2], field_factors(self.kick, self.pre, self.post, 2)
        self.tiled = False

    def segment(self, nsteps, memory_mb, asked):
        tile_seg = asked or tile_segment(nsteps, self.n, memory_mb)
        self.tiled = self._tiled(tile_seg)
        if self.tiled:
            return tile_seg
        return asked or chain_segment(nsteps, self.n, 4 * self.n * 8, memory_mb)  # q, v, f, cos/sin

    def _tiled(self, seg: int) -> bool:
        """Whether segments of ``seg`` steps replay and sweep back window by window: a chain of
        ``TILE_MIN_SITES`` sites or more, without contacts or constant loads, and segments short
        enough that a window's halos (``sweeps.tile_halo``) add at most half its interior (a longer
        segment — asked for, or forced by the memory budget — runs over the whole chain)."""
        traj = self.traj
        return (traj.tiles and traj._nchain >= TILE_MIN_SITES and traj.terms.con_ij.shape[0] == 0
                and self.form[10].size == 0 and 4 * sweeps.tile_halo(seg) <= TILE_SITES)

    def windows(self, seg: int) -> tuple[np.ndarray, int]:
        """The tiles of the chain's sites for segments of ``seg`` steps (``sweeps.tile_windows``)
        and their windows' length."""
        halo = sweeps.tile_halo(seg)
        nchain = self.traj._nchain
        return sweeps.tile_windows(nchain, TILE_SITES, halo), min(nchain, TILE_SITES + 2 * halo)

    def begin(self, adj):
        super().begin(adj)
        self.ur = np.empty((N_V, self.n // 2 + 1))
        self.tiles = None

    def kept(self, checkpoints):
        return (*checkpoints[:4], self.traj._scratch_array("cos/sin", (0, 2, self.n // 2)))

    def replay(self, checkpoints, c, m):
        traj, n, seg, form = self.traj, self.n, checkpoints[4], self.form
        SQ, SV, SF, ST = traj._buffers(n, seg + 1, "segment")
        SC = traj._scratch_array("cos/sin", (seg + 1, 2, n // 2))
        sweeps.chain_uniform_replay(self.u, form[1] != 0, form[10], form[11], self.fac, self.terms,
                                    *(x[c] for x in checkpoints[:4]), traj.h, m, SQ, SV, SF, ST, SC, self.ur)
        return SQ, SV, SF, ST, SC

    def reverse(self, states, k0, m):
        a, traj, form = self.adj, self.traj, self.form
        sweeps.chain_uniform_reverse(self.terms, self.u, self.fac, *states, traj.h, k0, m, traj.stride, traj.obs,
                                     a.dq, a.dv, a.df, a.lq, a.lv, a.lf, self.lw, self.GK, self.GV, a.gcon, a.gdrv,
                                     form[5], self.ur, form[10], form[12])

    def sweep_segment(self, checkpoints, c, k0, m):
        if not self.tiled:
            return super().sweep_segment(checkpoints, c, k0, m)
        traj, a, form, seg = self.traj, self.adj, self.form, checkpoints[4]
        if self.tiles is None:
            windows, length = self.windows(seg)
            ostart, oloc, ocol = sweeps.tile_observed(traj.obs, self.n // 2, windows, length)
            SQ, SV, SF, ST = traj._buffers(2 * length, seg + 1, "window")
            SC = traj._scratch_array("window.cos/sin", (seg + 1, 2, length))
            self.tiles = (windows, length, ostart, oloc, ocol, traj.stride, a.dq, a.dv, a.df, a.lq, a.lv, a.lf,
                          self.lw, self.GK, self.GV, a.gcon, a.gdrv, form[5], form[12], SQ, SV, SF, ST, SC,
                          np.empty((N_V, length + 1)))
        sweeps.chain_uniform_tiles(self.u, form[1] != 0, self.fac, self.terms, *(x[c] for x in checkpoints[:4]),
                                   traj.h, k0, m, *self.tiles)


class UniformSheet(Verlet):
    """A uniform grid sheet (``kernels.sheet_uniform``) without contacts or velocity terms: the
    reverse step with its shared hinge law as scalars (``sweeps.sheet_uniform_reverse``)."""

    @classmethod
    def applies(cls, traj, raw, form):
        return traj.terms.con_ij.shape[0] == 0 and not traj._vdep

    def __init__(self, traj, raw, form):
        super().__init__(traj, raw, form)
        self.p = sheet_uniform(raw.t1, raw.t2)
        self.sgx, self.sgy = form[3][H_SIGN].copy(), form[4][H_SIGN].copy()
        self.fac = field_factors(self.kick, self.pre, self.post, 3)

    def begin(self, adj):
        super().begin(adj)
        self.sr = sheet_uniform_scratch(self.n // 3, self.form[1])

    def reverse(self, states, k0, m):
        a, traj, form = self.adj, self.traj, self.form
        sweeps.sheet_uniform_reverse(self.terms, self.p, form[1], self.sgx, self.sgy, self.fac, *states[:4], traj.h,
                                     k0, m, traj.stride, traj.obs, a.dq, a.dv, a.df, a.lq, a.lv, a.lf, self.lw,
                                     self.GK, self.GV, a.gdrv, form[5], form[6], form[7], self.sr)


def field_factors(kick, pre, post, nf: int) -> tuple:
    """The integrator factors (K per field, then S, then P) of ``nf`` equal fields of DOFs:
    scalars if each is constant on every field, else per-field columns."""
    n = kick.size // nf
    fields = [a[i * n : (i + 1) * n] for a in (kick, post, pre) for i in range(nf)]
    if all(np.all(a == a[0]) for a in fields):
        return tuple(float(a[0]) for a in fields)
    return tuple(np.ascontiguousarray(a) for a in fields)


# ---------------------------------------------------------------- splittings (``splitting``)


class Split(_Common):
    """A kick/drift splitting (``splitting.forward``, ``reverse``, ``tangent``): a state is (q, v,
    f, t) and the step's stage forces, kept by the run or replay (``stages`` = False: the reverse
    step evaluates them again, one more forward run; the same bits)."""

    #: keep each step's stage forces for the reverse step
    stages = True

    def __init__(self, traj, raw, form):
        super().__init__(traj, raw, form)
        self.args = with_tables(traj.args, raw.t1, raw.t2)
        self.terms = traj.terms._replace(con_prm=raw.con, drv_prm=raw.drv)
        kicks, drifts, fsal = traj._split
        #: the kick factors per DOF (the tangent's), and as scalars per field where they are (the sweeps')
        self.E, self.G = splitting.kick_factors(kicks, raw.minv, raw.damp, traj.h)
        E, G = splitting.field_factors(self.E, self.G, {sweeps.FORM_CHAIN: 2, sweeps.FORM_GRID: 3}.get(form[0], 1))
        self.method = (kicks, drifts, E, G, fsal)
        self.uni = self.uniform()

    def uniform(self) -> splitting.Uniform:
        """The ``uni`` argument of the sweeps (``splitting.Uniform``): none here."""
        e1, e2 = np.zeros(0), np.zeros((0, 0))
        return splitting.Uniform(splitting.UNI_NONE, 0, e1, e1, e1, e2, e2, e1, e2, e2, e2, e1)

    @property
    def n_stages(self) -> int:
        kicks, drifts, _, _, fsal = self.method
        return splitting.n_stage_forces(drifts, fsal) if self.stages else 0

    @property
    def state_bytes(self) -> int:
        return (3 + self.n_stages) * self.n * 8

    def segment(self, nsteps, memory_mb, asked):
        return asked or chain_segment(nsteps, self.n, self.state_bytes, memory_mb)  # states and stage forces in cache

    def loop(self, q, v, f, t, nsteps, seg, stride, obs, ck, K, rec):
        splitting.forward(self.args, self.terms, self.uni, *self.method, q, v, f, t, self.traj.h, nsteps, seg, stride,
                          obs, *ck, *rec, K)
        return -1

    def keep(self, rows, where):
        """The stage forces of ``rows`` steps (one array for the run's and the segments')."""
        ns, n = self.n_stages, self.n
        return self.traj._scratch_array("stages", (rows, ns, n)) if ns and rows is not None else np.empty((1, 0, n))

    def begin(self, adj):
        super().begin(adj)
        kicks = self.method[0]
        self.GE, self.GG = np.zeros((kicks.size, self.n)), np.zeros((kicks.size, self.n))

    def reverse(self, states, k0, m):
        a, traj = self.adj, self.traj
        splitting.reverse(self.args, self.terms, self.uni, *self.method, *states, traj.h, k0, m, traj.stride, traj.obs,
                          a.dq, a.dv, a.df, a.lq, a.lv, a.lf, self.GE, self.GG, a.g1, a.g2, a.gcon, a.gdrv, self.form)

    def end(self, checkpoints):
        a, raw = self.adj, self.raw
        self.reverse_start(self.args, self.terms)
        g_minv, g_damp = splitting.kick_factor_gradients(self.method[0], raw.minv, raw.damp, self.traj.h, self.GE,
                                                         self.GG)
        return Raw(a.g1, a.g2, g_minv, g_damp, a.gcon, a.gdrv, a.lq, a.lv, a.gdash)

    def tangent(self, directions, rec, TQ, TV, TF):
        traj, raw = self.traj, self.raw
        kicks, drifts, _, _, fsal = self.method
        dminv, ddamp = stack(raw, directions, "minv"), stack(raw, directions, "damp")
        de_m, de_c, dg_m, dg_c = splitting.kick_factor_partials(kicks, raw.minv, raw.damp, traj.h)
        DE = np.ascontiguousarray(de_m[None] * dminv[:, None] + de_c[None] * ddamp[:, None])
        DG = np.ascontiguousarray(dg_m[None] * dminv[:, None] + dg_c[None] * ddamp[:, None])
        q, v, f = raw.q0.copy(), raw.v0.copy(), np.empty(self.n)
        splitting.tangent(self.args, self.terms, self.uni, kicks, drifts, self.E, self.G, DE, DG, fsal, q, v, f,
                          traj.t0, traj.h, traj.nsteps, traj.stride, traj.obs,
                          *(stack(raw, directions, k) for k in ("t1", "t2", "con", "drv", "q0", "v0")),
                          rec.q, rec.v, rec.f, TQ, TV, TF)


class UniformChainSplit(Split):
    """A splitting on a uniform chain without contacts or constant loads: stage forces and their
    adjoints from the shared law (``splitting.UNI_CHAIN``; the column form's accumulators)."""

    @classmethod
    def applies(cls, traj, raw, form):
        return traj.terms.con_ij.shape[0] == 0 and form[10].size == 0

    def uniform(self):
        e1, e2, form = np.zeros(0), np.zeros((0, 0)), self.form
        return splitting.Uniform(splitting.UNI_CHAIN, form[1], form[2], e1, e1, form[5], e2, e1,
                                 np.zeros((N_V, self.traj._nchain + 1)), e2, e2, e1)


class UniformSheetSplit(Split):
    """A splitting on a uniform grid sheet without contacts (``splitting.UNI_SHEET``)."""

    @classmethod
    def applies(cls, traj, raw, form):
        return traj.terms.con_ij.shape[0] == 0

    def uniform(self):
        raw, form = self.raw, self.form
        n, nc = raw.t2.shape[0], form[1]
        return splitting.Uniform(splitting.UNI_SHEET, nc, sheet_uniform(raw.t1, raw.t2), form[3][H_SIGN].copy(),
                                 form[4][H_SIGN].copy(), form[5], form[6], form[7], sheet_uniform_scratch(n, nc),
                                 grid_scratch(n)[0], raw.t1, raw.t2)


# ---------------------------------------------------------------- the implicit midpoint rule (``midpoint``)


class Midpoint(_Common):
    """The implicit midpoint rule (``midpoint.forward``, ``reverse``, ``tangent``): a state is (q, v,
    f, t) and the step's midpoint velocity; one linear solve per reverse step."""

    def __init__(self, traj, raw, form):
        super().__init__(traj, raw, form)
        self.args, self.terms = traj.bind(raw)[:2]
        self.state_bytes = 4 * self.n * 8  # q, v, f, V

    @property
    def mv(self) -> tuple:
        """``midpoint._jv``'s Hessian-vector product arguments: a form of its own (fresh
        accumulators), parameter-adjoint sinks, zero dashpot and drive directions."""
        raw = self.raw
        sinks = tuple(np.zeros_like(a) for a in (raw.t1, raw.t2, raw.con, raw.drv))
        return (self.traj.form(raw), *sinks, np.zeros_like(raw.dash), np.zeros_like(raw.drv))

    def failed(self, step: int, what: str) -> None:
        if step >= 0:
            raise GradientError(
                f"implicit_midpoint: {what} did not converge at step {step} "
                f"(t = {self.traj.t0 + step * self.traj.h:.6g}); the engine would split that step into substeps, "
                "which the adjoint does not follow (compression past buckling, or a step far beyond the explicit "
                "limit): reduce solver.dt_s")

    @property
    def prm(self) -> tuple:
        return self.args, self.terms, self.raw.minv, self.raw.damp

    def loop(self, q, v, f, t, nsteps, seg, stride, obs, ck, K, rec):
        return midpoint.forward(*self.prm, midpoint.NEWTON_RTOL, q, v, f, t, self.traj.h, nsteps, seg, stride, obs,
                                *ck, K, *rec)[1]

    def keep(self, rows, where):
        """The midpoint velocity of each of ``rows`` steps."""
        return np.empty((0, self.n)) if rows is None else self.traj._scratch_array(f"{where}.V", (rows, self.n))

    def states(self, SQ, SV, SF, ST, K):
        return SQ, SV, K, ST

    def check(self, failed):
        self.failed(failed, "Newton's iteration (to the design tolerance)")

    def begin(self, adj):
        super().begin(adj)
        self.gminv, self.gdamp = np.zeros(self.n), np.zeros(self.n)
        self._mv = self.mv

    def reverse(self, states, k0, m):
        a, traj = self.adj, self.traj
        failed = midpoint.reverse(*self.prm, *states, traj.h, k0, m, traj.stride, traj.obs, a.dq, a.dv, a.df, a.lq,
                                  a.lv, a.lf, a.g1, a.g2, a.gcon, a.gdrv, a.gdash, self.gminv, self.gdamp, self.form,
                                  self._mv)
        self.failed(failed, "the adjoint's linear solve")

    def end(self, checkpoints):
        a = self.adj
        self.reverse_start(self.args, self.terms)
        return Raw(a.g1, a.g2, self.gminv, self.gdamp, a.gcon, a.gdrv, a.lq, a.lv, a.gdash)

    def tangent(self, directions, rec, TQ, TV, TF):
        traj, raw = self.traj, self.raw
        q, v, f = raw.q0.copy(), raw.v0.copy(), np.empty(self.n)
        _, failed = midpoint.tangent(
            *self.prm, midpoint.NEWTON_RTOL, q, v, f, traj.t0, traj.h, traj.nsteps, traj.stride, traj.obs,
            *(stack(raw, directions, k) for k in ("t1", "t2", "con", "drv", "dash", "minv", "damp", "q0", "v0")),
            rec.q, rec.v, rec.f, TQ, TV, TF, self.mv)
        self.failed(failed, "Newton's iteration or the tangent's linear solve")


# ---------------------------------------------------------------- the one table

#: each integrator's generic steps
GENERIC = {"verlet": Verlet, "splitting": Split, "midpoint": Midpoint}
#: the fast paths: (integrator, model form) → steps, taken where their ``applies`` holds
ACCELERATORS = {
    ("verlet", "chain_uniform"): UniformChain,
    ("verlet", "chain"): ChainColumns,
    ("verlet", "grid_uniform"): UniformSheet,
    ("splitting", "chain_uniform"): UniformChainSplit,
    ("splitting", "grid_uniform"): UniformSheetSplit,
}


def model_forms(traj, raw, form: tuple) -> tuple[str, ...]:
    """The model's forms, most specialised first: a chain-ordered chain's columns ("chain"; with
    one law for every hinge and site, "chain_uniform"), a grid sheet's ("grid"; "grid_uniform"),
    else its own tables ("tables")."""
    if form[0] == sweeps.FORM_CHAIN:
        return ("chain_uniform", "chain") if form[2].size else ("chain",)
    if form[0] == sweeps.FORM_GRID:
        uniform = traj.uniform_sweeps and sheet_uniform(raw.t1, raw.t2) is not None
        return ("grid_uniform", "grid") if uniform else ("grid",)
    return ("tables",)


def family(integrator: str) -> str:
    """The steps family of a differentiable integrator (``gradient.DIFFERENTIABLE``)."""
    return {"velocity_verlet": "verlet", "implicit_midpoint": "midpoint"}.get(integrator, "splitting")


def steps_of(traj, raw: Raw) -> Steps:
    """The steps of ``traj``'s integrator at ``raw``: the first fast path of its model's forms
    (``ACCELERATORS``) that applies to the run, else the integrator's generic steps."""
    form = traj.form(raw)
    kind = family(traj.integrator)
    for model in model_forms(traj, raw, form):
        cls = ACCELERATORS.get((kind, model))
        if cls is not None and cls.applies(traj, raw, form):
            return cls(traj, raw, form)
    return GENERIC[kind](traj, raw, form)
