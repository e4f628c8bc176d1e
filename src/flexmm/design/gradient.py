"""Exact gradients of trajectory objectives through a run of velocity Verlet (``sweeps``), of a
symplectic splitting, PEFRL or Blanes–Moan's 6th-order method (``splitting``), or of the implicit
midpoint rule (``midpoint``: its Newton iteration run to round-off).

The differentiable inputs of a built problem are its *raw* arrays (``Raw``): the model's two
parameter tables (``kernels.param_tables``), the inverse masses and on-site damping per DOF,
the contact and drive parameter rows (ground friction's among them), the initial state and the
dashpot coefficients. ``Trajectory`` runs a problem with its integrator (``DIFFERENTIABLE``;
velocity Verlet by default, with velocity-dependent forces at the engine's predicted velocity)
and records (q, v, f) at the observed DOFs every ``stride`` steps; ``gradient`` returns an
objective and its gradient with respect to every raw array by one
forward run with checkpoints and one reverse sweep; ``sensitivities`` returns the records'
derivatives along a few raw directions (forward mode, for least-squares Jacobians).

Memory: a run whose states fit in ``MEMORY_MB`` keeps them all; a longer one keeps
checkpoints every ``segment`` steps (default ⌈√nsteps⌉, on chains at most ``SEGMENT_MB`` of
replayed states) of (q, v, f) and the reverse sweep replays one segment at a time, so a run of
N steps keeps about 2√N states, plus the records (a 1e6-step run of a 100-unit chain: 10 MB
instead of 4.8 GB).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Callable

import numpy as np

from flexmm.design import midpoint, splitting, sweeps
from flexmm.design.kernels import (N_CA, N_F, N_R, N_V, adjoint_kernels_of, chain_add_columns, chain_columns,
                                   chain_ordered, chain_uniform, param_tables, sheet_grid, sheet_grid_add,
                                   sheet_grid_columns, sheet_uniform, sheet_uniform_scratch, with_tables)
from flexmm.errors import FlexmmError
from flexmm.integrators import verlet_chain
from flexmm.integrators.common import ACC_HEADER, MODE_FRICTION, Terms, has_velocity_terms
from flexmm.models.hinge import H_SIGN, S_KG
from flexmm.models.loads import LoadedChainArgs
from flexmm.models.sheet_kernels import grid_scratch


#: a run whose states fit in this many MB keeps them all (no replay); larger runs checkpoint
MEMORY_MB = 256.0
#: the column sweeps keep every state only if they fit in this many MB (a cache's size)
CACHE_MB = 4.0
#: chains of this many sites or more run forward with the engine's time-blocked kernel when it
#: gives the same bits (``Trajectory._engine_run``)
ENGINE_SITES = 4096
#: ... if it stops (checkpoints, records) at most every this many steps
ENGINE_MIN_STEPS = 8
#: a chain's default segment is shortened so that its replayed states take at most this many MB
#: (they are read back by the reverse sweep from cache, not memory), down to ``ENGINE_MIN_STEPS``
#: steps and as long as the checkpoints stay within the memory budget
SEGMENT_MB = 8.0
#: a uniform chain of this many sites or more (without contacts or loads) replays and sweeps back
#: each segment of ``TILE_STEPS`` steps in windows of ``TILE_SITES`` sites plus halos
#: (``sweeps.chain_uniform_tiles``): longer segments than the whole chain's states in cache allow
TILE_MIN_SITES = 8192
TILE_SITES = 2048
TILE_STEPS = 32


class GradientError(FlexmmError):
    """A problem whose run cannot be differentiated (an unsupported model or term)."""


@dataclass
class Raw:
    """The differentiable arrays of a problem (nondimensional): model tables ``t1``, ``t2``,
    ``minv`` and ``damp`` (ndof,), contact rows ``con`` (C, 3), drive rows ``drv`` (D, 4; ground
    friction's rows (F₊, v_ε, F₋, 0) among them), the initial state ``q0``, ``v0``, and the
    dashpot coefficients ``dash`` (P,; last, and empty by default, so arrays built without it
    still construct: ``Trajectory.bind`` checks its size against the dashpots). A gradient has
    the same structure."""

    t1: np.ndarray
    t2: np.ndarray
    minv: np.ndarray
    damp: np.ndarray
    con: np.ndarray
    drv: np.ndarray
    q0: np.ndarray
    v0: np.ndarray
    dash: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def zeros(self) -> Raw:
        return Raw(*(np.zeros_like(getattr(self, f.name)) for f in fields(self)))

    def items(self):
        return ((f.name, getattr(self, f.name)) for f in fields(self))

    def dot(self, other: Raw) -> float:
        return float(sum(np.vdot(a, getattr(other, k)) for k, a in self.items()))

    def axpy(self, a: float, other: Raw) -> Raw:
        return Raw(*(x + a * getattr(other, k) for k, x in self.items()))

    def slope(self, other: Raw, step: float) -> Raw:
        """(self − other) / step, zero where the two are equal (also equal infinities)."""
        return Raw(*(np.where(x == getattr(other, k), 0.0, (x - getattr(other, k)) / step)
                     for k, x in self.items()))


def raw_of(system, terms: Terms, damp: np.ndarray) -> Raw:
    """The raw arrays of a built system (copies)."""
    t1, t2 = param_tables(system.args)
    return Raw(t1.copy(), t2.copy(), system.inv_mass.copy(), np.asarray(damp, float).copy(),
               terms.con_prm.copy(), terms.drv_prm.copy(), system.q0.copy(), system.v0.copy(),
               np.asarray(terms.dash_c, float).copy())


def check_differentiable(system, terms: Terms) -> None:
    """Refuse models without gradient kernels, magnets or joints of the sheet, and a run that
    is not differentiable because of anisotropic ground friction.

    Dashpots and ground friction are differentiated (``integrators.verlet.step_force``). The friction law
    −F tanh(v/v_ε) is smooth, except that with F₊ ≠ F₋ its slope jumps at v = 0: a DOF at rest
    (v = 0 exactly, as every site of a run that starts at rest is until the wave reaches it)
    then moves either way under a perturbation, with different slopes, and the run has no
    derivative. So anisotropic friction is differentiated only if each of its DOFs is free and
    starts moving (v0 ≠ 0); velocities then cross zero at isolated instants, between steps.
    """
    try:
        adjoint_kernels_of(type(system.args))
    except TypeError as err:
        raise GradientError(f"model {system.model!r}: {err}") from None
    args = system.args
    if hasattr(args, "dipoles") and args.dipoles[0].shape[0] and not np.array_equal(args.dipoles[4], args.theta0):
        raise GradientError(f"model {system.model!r}: the magnets' rest angles differ from the units' θ0 "
                            "(gradients take θ0 as one parameter per unit)")
    rows = (terms.drv_mode == MODE_FRICTION) & (terms.drv_prm[:, 0] != terms.drv_prm[:, 2])
    dofs = terms.drv_dof[rows]
    still = dofs[(system.v0[dofs] == 0.0) | (system.inv_mass[dofs] == 0.0)]
    if still.size:
        raise GradientError(
            f"anisotropic ground friction (backward force ≠ forward force) on {still.size} DOF(s) that start at "
            f"rest or are held (first: DOF {int(still[0])}): its slope jumps at v = 0, so the run has no gradient "
            "there; use isotropic friction (no backward_force_n) or start every friction site moving")


#: the time steppers whose runs are differentiated (``Trajectory.integrator``)
DIFFERENTIABLE = ("velocity_verlet", *splitting.SPLITTINGS, "implicit_midpoint")


def check_integrator(name: str, terms: Terms) -> None:
    """Refuse an integrator without an adjoint, and a splitting with velocity-dependent terms."""
    if name not in DIFFERENTIABLE:
        raise GradientError(f"integrator {name!r} has no adjoint: gradients are exact for "
                            f"{', '.join(DIFFERENTIABLE)} (set solver.integrator to one of them)")
    if name in splitting.SPLITTINGS and (terms.dash_ij.shape[0] or np.any(terms.drv_mode == MODE_FRICTION)):
        raise GradientError(f"{name}: with dashpots or ground friction its kicks are RK4 flows, which are not "
                            "differentiated; gradients are exact for its exact (on-site damped) kicks only")


@dataclass
class Records:
    """(q, v, f) at the observed DOFs, one row per recorded step (nondimensional)."""

    q: np.ndarray
    v: np.ndarray
    f: np.ndarray


#: an objective maps the records (and the raw arrays) to (value, dJ/dq, dJ/dv, dJ/df, dJ/draw or None)
Objective = Callable[[Records, Raw], tuple]


@dataclass
class Trajectory:
    """What a differentiated run needs besides the raw arrays: the system's args and terms (their
    non-differentiable parts), the step ``h``, ``nsteps``, the recording ``stride`` and the
    observed DOFs ``obs``, and the start time ``t0``.

    The model part of the reverse step takes column form where it can (``form``): a
    chain-ordered rotating-squares chain, loaded or not, with contacts (a striker) or not (whose
    forward run and replay then use the column force, ``sweeps.chain_forward``/``chain_replay``:
    the same trajectory bit for bit; with dashpots or ground friction the general run, which
    keeps each step's f_a, and the column form in the reverse step only — a uniform chain's by
    its fused kernels) and a grid sheet; the gradient is the same to rounding, at a third to a
    half of the cost (``python benchmarks/run.py gradient``). A uniform chain (``kernels.chain_uniform``)
    replays and reverses with scalar parameters (``sweeps.chain_uniform_*``: ~0.7 of the column
    sweeps' cost), and a long damped one runs forward with the engine's fused kernel
    (``_engine_run``); ``uniform_sweeps=False``, ``engine_forward=False`` keep the column path.
    A uniform grid sheet (``kernels.sheet_uniform``) reverses with its shared hinge law as
    scalars (``sweeps.sheet_uniform_reverse``; ``uniform_sweeps=False``: the grid columns).
    ``column_sweeps=False`` runs the model's own adjoint kernel always."""

    args: tuple
    terms: Terms
    h: float
    nsteps: int
    stride: int
    obs: np.ndarray
    t0: float = 0.0
    #: run the column sweeps where they apply (``columns``); False: the general sweeps always
    column_sweeps: bool = True
    #: a uniform chain's or grid sheet's sweeps with scalar parameters (``sweeps.chain_uniform_*``,
    #: ``sheet_uniform_reverse``, a uniform chain's reverse step in every sweep, the splittings'
    #: uniform path ``splitting.Uniform``) where they apply; False: the column sweeps' (for comparisons)
    uniform_sweeps: bool = True
    #: the forward run by the engine's fused chain kernel where it gives the same bits and is
    #: faster (``_engine_run``); False: ``sweeps.chain_forward`` always
    engine_forward: bool = True
    #: a long uniform chain's replay and reverse sweep window by window (``sweeps.chain_uniform_tiles``)
    #: where they apply (``_tiled``); False: over the whole chain each step
    tiles: bool = True
    #: the time stepper (``DIFFERENTIABLE``): velocity Verlet, a splitting (``design.splitting``) or the
    #: implicit midpoint rule (``design.midpoint``)
    integrator: str = "velocity_verlet"

    def __post_init__(self):
        self.obs = np.asarray(self.obs, np.int64)
        check_integrator(self.integrator, self.terms)
        self._split = splitting.coefficients(self.integrator) if self.integrator in splitting.SPLITTINGS else None
        self._scratch: dict[str, np.ndarray] = {}  # ``_scratch_array``
        if self.nsteps % self.stride:
            raise ValueError(f"nsteps ({self.nsteps}) must be a multiple of the stride ({self.stride})")
        chain = self.args.chain if isinstance(self.args, LoadedChainArgs) else self.args
        ndof = 2 * chain.site_prm.shape[0] if hasattr(chain, "site_prm") else -1
        #: a chain-ordered chain (loaded or not; contacts, a striker's DOFs, velocity terms allowed)
        self._ordered = chain_ordered(chain, ndof)
        self._nchain = ndof // 2
        #: dashpots or ground friction: the reverse step reads each step's f_a (``integrators.verlet.step_force``)
        self._vdep = has_velocity_terms(self.terms)
        nsite = self.args.theta0.shape[0] if hasattr(self.args, "theta0") else -1
        self._grid = sheet_grid(self.args, 3 * nsite)

    def form(self, raw: Raw) -> tuple:
        """The ``form`` argument of the reverse sweep (``sweeps._force_adjoint``): a chain-ordered
        chain's columns, a grid sheet's hinge families, or the model's own adjoint kernel."""
        e1, e2, ei = np.zeros(0), np.zeros((0, 0)), np.zeros(0, np.int64)
        if self.columns(raw):
            n = self._nchain
            cols, with_kg, ldof, lval = self._columns(raw)
            u = chain_uniform(cols) if self.uniform_sweeps else None  # a uniform chain: fused kernels
            return (sweeps.FORM_CHAIN, int(with_kg), e1 if u is None else u, cols, e2, np.zeros((N_CA, n)), e2, e1, np.empty((N_R, n + 1)),
                    np.empty(raw.q0.size), ldof, lval, np.zeros(ldof.size))
        if self.column_sweeps and self._grid and raw.q0.size == 3 * raw.t2.shape[0]:
            nc, y0 = self._grid
            n = raw.t2.shape[0]
            xc, yc = sheet_grid_columns(raw.t1, n, nc, y0)
            return (sweeps.FORM_GRID, nc, raw.t2, xc, yc, np.zeros((6, n - 1)), np.zeros((6, n - nc)), np.zeros(n),
                    np.empty((N_F + 2, n)), e1, ei, e1, e1)
        return (sweeps.FORM_TABLES, 0, e1, e2, e2, e2, e2, e1, e2, e1, ei, e1, e1)

    def columns(self, raw: Raw) -> bool:
        """Whether the reverse step takes a chain's column form (``sweeps.FORM_CHAIN``): a
        chain-ordered chain, loaded or not, with or without contacts (a striker's DOFs after the
        chain's 2N) and velocity terms."""
        return self.column_sweeps and self._ordered and raw.q0.size >= 2 * self._nchain

    def _column_run(self, raw: Raw) -> bool:
        """Whether the run and its replay take the column force too (``sweeps.chain_forward``,
        ``chain_replay``; the reverse step then takes each state's force again): without velocity
        terms (their forward run is the general one, which keeps each state's G)."""
        return self.columns(raw) and not self._vdep

    def _columns(self, raw: Raw) -> tuple:
        """(columns, lateral stretch?, load DOFs, load values) of a chain-ordered chain; a loaded
        chain's t2 is its site table then its loads' values (``kernels_extra.loaded_chain_pack``)."""
        n = self._nchain
        sprm = raw.t2[: 3 * n].reshape(n, 3)
        if isinstance(self.args, LoadedChainArgs):
            ldof, lval = self.args.loads[0], raw.t2[3 * n :]
        else:
            ldof, lval = np.zeros(0, np.int64), np.zeros(0)
        return chain_columns(raw.t1, sprm), bool(np.any(sprm[:, S_KG] != 0.0)), ldof, lval

    def _uniform(self, form: tuple, kick, pre, post) -> tuple | None:
        """(parameters, integrator factors) of the uniform chain's reverse sweep, or None: the
        uniform law ``form`` found (``form``, slot 2) and the factors (K_u, K_θ, S_u, S_θ, P_u, P_θ)
        as scalars if constant on each field, else as per-field columns. Not with velocity terms,
        nor with DOFs past the chain's (a striker's)."""
        if not (form[0] == sweeps.FORM_CHAIN and form[2].size and not self._vdep and kick.size == 2 * self._nchain):
            return None
        return form[2], _field_factors(kick, pre, post, 2)

    def _tiled(self, form: tuple, seg: int) -> bool:
        """Whether a uniform chain's segments of ``seg`` steps replay and sweep back window by
        window (``sweeps.chain_uniform_tiles``): a chain of ``TILE_MIN_SITES`` sites or more,
        without contacts or constant loads, and segments short enough that a window's halos
        (``sweeps.tile_halo``) add at most half its interior (a longer segment — asked for, or
        forced by the memory budget — runs over the whole chain)."""
        return (self.tiles and self._nchain >= TILE_MIN_SITES and self.terms.con_ij.shape[0] == 0
                and form[10].size == 0 and 4 * sweeps.tile_halo(seg) <= TILE_SITES)

    def _windows(self, seg: int) -> tuple[np.ndarray, int]:
        """The tiles of a chain's sites for segments of ``seg`` steps (``sweeps.tile_windows``)
        and their windows' length."""
        halo = sweeps.tile_halo(seg)
        windows = sweeps.tile_windows(self._nchain, TILE_SITES, halo)
        return windows, min(self._nchain, TILE_SITES + 2 * halo)

    def _sheet_uniform(self, raw: Raw, form: tuple, kick, pre, post) -> tuple | None:
        """(shared law, x and y shear signs, integrator factors) of a uniform grid sheet's reverse
        sweep (``sweeps.sheet_uniform_reverse``: no contacts, no velocity terms), or None."""
        if not (self.uniform_sweeps and form[0] == sweeps.FORM_GRID and self.terms.con_ij.shape[0] == 0
                and not has_velocity_terms(self.terms)):
            return None
        p = sheet_uniform(raw.t1, raw.t2)
        if p is None:
            return None
        return p, form[3][H_SIGN].copy(), form[4][H_SIGN].copy(), _field_factors(kick, pre, post, 3)

    @property
    def n_samples(self) -> int:
        return self.nsteps // self.stride + 1

    @property
    def times(self) -> np.ndarray:
        return self.t0 + self.h * self.stride * np.arange(self.n_samples)

    # -- the arrays a sweep takes -----------------------------------------------------------
    def bind(self, raw: Raw) -> tuple:
        args = with_tables(self.args, raw.t1, raw.t2)
        if raw.dash.shape != self.terms.dash_c.shape:
            raise ValueError(f"raw.dash has shape {raw.dash.shape}; the problem has {self.terms.dash_c.size} dashpots")
        terms = self.terms._replace(con_prm=raw.con, drv_prm=raw.drv, dash_c=raw.dash)
        h = self.h
        g = raw.damp * raw.minv
        kick = 0.5 * h * raw.minv
        pre = 1.0 - 0.5 * h * g
        post = 1.0 / (1.0 + 0.5 * h * g)
        return args, terms, kick, pre, post

    def _buffers(self, ndof: int, rows: int, reuse: str = "") -> tuple:
        """(Q, V, F, T) for ``rows`` states; named by ``reuse``: kept for the next call
        (``_scratch_array``)."""
        if reuse:
            shapes = ((rows, ndof),) * 3 + ((rows,),)
            return tuple(self._scratch_array(f"{reuse}.{x}", shape) for x, shape in zip("QVFT", shapes))
        return np.empty((rows, ndof)), np.empty((rows, ndof)), np.empty((rows, ndof)), np.empty(rows)

    def _scratch_array(self, name: str, shape: tuple) -> np.ndarray:
        """An array that a gradient uses only while it runs, kept for the next gradient of this
        trajectory (one shape per name): freshly allocated, its pages are faulted in again on
        every call (10 000 units × 1000 steps: a third of the forward run's time)."""
        a = self._scratch.get(name)
        if a is None or a.shape != shape:
            a = self._scratch[name] = np.empty(shape)
        return a

    def _records(self) -> Records:
        shape = (self.n_samples, self.obs.size)
        return Records(np.empty(shape), np.empty(shape), np.empty(shape))

    # -- runs ----------------------------------------------------------------------------------
    def run(self, raw: Raw, segment: int | None = None, scratch: bool = False) -> tuple[Records, tuple]:
        """Forward run: the records, and the checkpoints (CQ, CV, CF, CT, segment); ``scratch``:
        the checkpoints in arrays the next such run overwrites (``_scratch_array``)."""
        if self._split is not None:
            return self._split_run(raw, segment, scratch)
        if self.integrator == "implicit_midpoint":
            return self._midpoint_run(raw, segment)[:2]
        return self._run(raw, segment, scratch)[:2]

    def _run(self, raw: Raw, segment: int | None, scratch: bool) -> tuple[Records, tuple, np.ndarray]:
        """``run`` of velocity Verlet, and the f_a of every step (``integrators.verlet.step_force``) where the
        gradient's run keeps every state of a run with velocity terms (else no rows)."""
        args, terms, kick, pre, post = self.bind(raw)
        q, v, f = raw.q0.copy(), raw.v0.copy(), np.empty_like(raw.q0)
        sweeps.initial_force(args, terms, q, v, f, self.t0)
        seg = segment or max(1, math.isqrt(max(self.nsteps, 1)))
        rows = self.nsteps // seg + 1
        CQ, CV, CF, CT = self._buffers(q.size, rows, "checkpoints" if scratch else "")
        rec = self._records()
        if self._engine_run(raw, args, terms, q, v, f, seg, CQ, CV, CF, CT, rec):
            pass
        elif self._column_run(raw):
            sweeps.chain_forward(*self._columns(raw), terms, kick, pre, post, q, v, f, self.t0, self.h, self.nsteps,
                                 seg, self.stride, self.obs, CQ, CV, CF, CT, rec.q, rec.v, rec.f)
        else:  # with velocity terms, the gradient's run keeping every state keeps each step's f_a too
            keep_fa = scratch and self._vdep and seg == 1
            CA = self._scratch_array("checkpoints.fa", (rows if keep_fa else 0, q.size))
            sweeps.forward(args, terms, kick, pre, post, q, v, f, self.t0, self.h, self.nsteps, seg,
                           self.stride, self.obs, CQ, CV, CF, CT, CA, rec.q, rec.v, rec.f)
            return rec, (CQ, CV, CF, CT, seg), CA
        return rec, (CQ, CV, CF, CT, seg), np.empty((0, q.size))

    def _engine_run(self, raw: Raw, args, terms, q, v, f, seg, CQ, CV, CF, CT, rec: Records) -> bool:
        """The forward run by the engine's fused, time-blocked chain kernel
        (``integrators.verlet_chain``), stopping at each checkpoint and record, where it gives
        ``chain_forward``'s bits and is faster: a damped chain (undamped, the engine adds the two
        half kicks between steps as one: a different rounding) of ``ENGINE_SITES`` sites or more
        (shorter ones fit in cache, where ``chain_forward`` is as fast), stopping at most every
        ``ENGINE_MIN_STEPS`` steps (each call is blocked in time over its steps). Returns whether
        it ran."""
        n = raw.t2.shape[0]
        if (not (self.engine_forward and self._column_run(raw)) or n < ENGINE_SITES
                or min(seg, self.stride) < ENGINE_MIN_STEPS or not np.any(raw.damp * raw.minv != 0.0)
                or not verlet_chain.fusable(args, q, raw.minv, raw.damp, terms)):
            return False
        tables = verlet_chain.prepare(args, raw.minv, raw.damp, self.h)
        ledger = np.zeros(ACC_HEADER)
        t, k = self.t0, 0
        while True:
            if k % seg == 0:
                CQ[k // seg], CV[k // seg], CF[k // seg], CT[k // seg] = q, v, f, t
            if k % self.stride == 0:
                j = k // self.stride
                rec.q[j], rec.v[j], rec.f[j] = q[self.obs], v[self.obs], f[self.obs]
            if k == self.nsteps:
                return True
            m = min(seg - k % seg, self.stride - k % self.stride, self.nsteps - k)
            t = verlet_chain.chain_verlet_advance_prepared(tables, args, q, v, f, raw.minv, raw.damp, terms, t, self.h,
                                                           m, ledger)
            k += m

    def gradient(self, raw: Raw, objective: Objective, segment: int | None = None,
                 memory_mb: float = MEMORY_MB) -> tuple[float, Raw, Records]:
        """(J, dJ/draw, records) by one forward run and one reverse sweep.

        If every state of the run fits in ``memory_mb`` (the column sweeps: in ``CACHE_MB``, as
        replaying from checkpoints costs less than streaming every state through memory), and no
        ``segment`` is asked for, the forward run keeps them all and the reverse sweep reads
        them; otherwise the forward run keeps checkpoints every ``segment`` steps (default
        ⌈√nsteps⌉) and the reverse sweep replays one segment at a time (one more forward run in
        all, memory ~2√N states).
        """
        if self._split is not None:
            return self._split_gradient(raw, objective, segment, memory_mb)
        if self.integrator == "implicit_midpoint":
            return self._midpoint_gradient(raw, objective, segment, memory_mb)
        n, N = raw.q0.size, self.nsteps
        args, terms, kick, pre, post = self.bind(raw)
        form = self.form(raw)
        column_run = self._column_run(raw)
        budget = min(memory_mb, CACHE_MB) if column_run else memory_mb
        per_state = 4 if self._vdep else 3  # q, v, f (and f_a)
        keep_all = segment is None and (N + 1) * (per_state * n + 1) * 8 <= budget * 1e6
        uniform = self._uniform(form, kick, pre, post) if column_run else None
        tile_seg = segment or _tile_segment(N, n, memory_mb)
        tiled = not keep_all and uniform is not None and self._tiled(form, tile_seg)
        if tiled:
            segment = tile_seg
        elif column_run and not keep_all and segment is None:  # a replayed segment's states (q, v; f, cos/sin)
            segment = _chain_segment(N, n, (4 if uniform is not None else 2) * n * 8, memory_mb)
        rec, (CQ, CV, CF, CT, seg), CA = self._run(raw, 1 if keep_all else segment, scratch=True)
        value, explicit, (dq, dv, df), (lq, lv, lf), (g1, g2, gcon, gdrv, gdash) = self._seed(rec, raw, objective)
        lw = np.zeros(n)
        GK, GV = np.zeros(n), np.zeros(n)
        adjoints = (self.stride, self.obs, dq, dv, df, lq, lv, lf, lw, g1, g2, GK, GV, gcon, gdrv, gdash, form)
        if tiled:
            u, fac = uniform
            windows, length = self._windows(seg)
            ostart, oloc, ocol = sweeps.tile_observed(self.obs, n // 2, windows, length)
            SQ, SV, SF, ST = self._buffers(2 * length, seg + 1, "window")
            SC = self._scratch_array("window.cos/sin", (seg + 1, 2, length))
            tiles = (windows, length, ostart, oloc, ocol, self.stride, dq, dv, df, lq, lv, lf, lw, GK, GV, gcon, gdrv,
                     form[5], form[12], SQ, SV, SF, ST, SC, np.empty((N_V, length + 1)))
        elif uniform is not None:
            u, fac = uniform
            ur = np.empty((N_V, n // 2 + 1))
            urev = (self.stride, self.obs, dq, dv, df, lq, lv, lf, lw, GK, GV, gcon, gdrv, form[5], ur, form[10],
                    form[12])
            SC = self._scratch_array("cos/sin", (0 if keep_all else seg + 1, 2, n // 2))

            def reverse(SQ, SV, SF, ST, SA, k0, m):
                sweeps.chain_uniform_reverse(terms, u, fac, SQ, SV, SF, ST, SC, self.h, k0, m, *urev)
        elif (sheet := self._sheet_uniform(raw, form, kick, pre, post)) is not None:
            p, sgx, sgy, fac = sheet
            nc = form[1]
            sr = sheet_uniform_scratch(n // 3, nc)
            srev = (self.stride, self.obs, dq, dv, df, lq, lv, lf, lw, GK, GV, gdrv, form[5], form[6], form[7], sr)

            def reverse(SQ, SV, SF, ST, SA, k0, m):
                sweeps.sheet_uniform_reverse(terms, p, nc, sgx, sgy, fac, SQ, SV, SF, ST, self.h, k0, m, *srev)
        else:
            def reverse(SQ, SV, SF, ST, SA, k0, m):
                sweeps.reverse(args, terms, kick, pre, post, SQ, SV, SF, ST, SA, self.h, k0, m, *adjoints)
        if keep_all:  # every state was kept by the forward run
            reverse(CQ, CV, CF, CT, CA, 0, N)
        elif tiled:
            for c in range((N - 1) // seg if N else -1, -1, -1):
                sweeps.chain_uniform_tiles(u, form[1] != 0, fac, terms, CQ[c], CV[c], CF[c], CT[c], self.h, c * seg,
                                           min(seg, N - c * seg), *tiles)
        else:
            SQ, SV, SF, ST = self._buffers(n, seg + 1, "segment")  # SF unused by the chain columns
            SA = self._scratch_array("segment.fa", (seg + 1 if self._vdep else 0, n))
            for c in range((N - 1) // seg if N else -1, -1, -1):
                k0, m = c * seg, min(seg, N - c * seg)
                if uniform is not None:
                    sweeps.chain_uniform_replay(u, form[1] != 0, form[10], form[11], fac, terms, CQ[c], CV[c], CF[c],
                                                CT[c], self.h, m, SQ, SV, SF, ST, SC, ur)
                elif column_run:
                    sweeps.chain_replay(form[3], form[1] != 0, form[10], form[11], terms, kick, pre, post, CQ[c], CV[c],
                                        CF[c], CT[c], self.h, m, SQ, SV, ST)
                else:
                    sweeps.replay(args, terms, kick, pre, post, CQ[c], CV[c], CF[c], CT[c], self.h, m, SQ, SV, SF, ST,
                                  SA)
                reverse(SQ, SV, SF, ST, SA, k0, m)
        GK += lw * CF[0]  # the products of the first step's λw with the initial state
        GV += lw * CV[0]
        self._reverse_start(raw, args, terms, lq, lv, lf, g1, g2, gcon, gdrv, gdash, form)
        # K = h/2 m⁻¹, P = 1 − h/2 c m⁻¹, S = 1/(1 + h/2 c m⁻¹); GV = ∂J/∂P + S² ∂J/∂S
        hh = 0.5 * self.h
        g_minv = hh * GK - hh * raw.damp * GV
        g_damp = -hh * raw.minv * GV
        grad = Raw(g1, g2, g_minv, g_damp, gcon, gdrv, lq, lv, gdash)
        if explicit is not None:
            grad = grad.axpy(1.0, explicit)
        return float(value), grad, rec

    def _seed(self, rec: Records, raw: Raw, objective: Objective) -> tuple:
        """The objective's value and explicit gradient, its adjoints of the records (dq, dv, df),
        the state adjoints (λq, λv, λf) at the last step (its records') and zeroed parameter
        adjoints (g1, g2, gcon, gdrv, gdash)."""
        n = raw.q0.size
        value, dq, dv, df, explicit = objective(rec, raw)
        dq, dv, df = (np.ascontiguousarray(np.broadcast_to(a, rec.q.shape), float) for a in (dq, dv, df))
        lq, lv, lf = np.zeros(n), np.zeros(n), np.zeros(n)
        j = self.nsteps // self.stride
        lq[self.obs] += dq[j]
        lv[self.obs] += dv[j]
        lf[self.obs] += df[j]
        params = (np.zeros_like(raw.t1), np.zeros_like(raw.t2), np.zeros_like(raw.con), np.zeros_like(raw.drv),
                  np.zeros_like(raw.dash))
        return value, explicit, (dq, dv, df), (lq, lv, lf), params

    def _reverse_start(self, raw, args, terms, lq, lv, lf, g1, g2, gcon, gdrv, gdash, form) -> None:
        """Reverse of the run's start (prescription, initial force): (lq, lv) become the
        gradients w.r.t. q0, v0; the column forms' parameter adjoints are added to (g1, g2)."""
        q0 = raw.q0.copy()
        v0 = raw.v0.copy()
        sweeps.apply_prescribed_only(terms, q0, v0, self.t0)
        sweeps.reverse_initial(args, terms, q0, v0, self.t0, lq, lv, lf, g1, g2, gcon, gdrv, gdash, form)
        if form[0] == sweeps.FORM_CHAIN:  # a loaded chain's t2: its site table, then its loads' values
            n, flat = self._nchain, g2.reshape(-1)
            chain_add_columns(form[5], g1, flat[: 3 * n].reshape(n, 3))
            flat[3 * n :] += form[12]
        elif form[0] == sweeps.FORM_GRID:
            sheet_grid_add(form[5], form[6], form[7], g1, g2, form[1], self._grid[1])

    # -- the splittings (``design.splitting``) ---------------------------------------------
    def _split_bind(self, raw: Raw, per_field: bool = True) -> tuple:
        """The arrays a splitting sweep takes: args, terms, ``uni`` (``_split_uniform``), (kicks,
        drifts, E, G, fsal) and the run's ``form``; ``per_field``: the kick factors as scalars per
        field where they are (``splitting.field_factors``), else per DOF."""
        args = with_tables(self.args, raw.t1, raw.t2)
        terms = self.terms._replace(con_prm=raw.con, drv_prm=raw.drv)
        kicks, drifts, fsal = self._split
        E, G = splitting.kick_factors(kicks, raw.minv, raw.damp, self.h)
        form = self.form(raw)
        uni = self._split_uniform(raw, form)
        if per_field:
            E, G = splitting.field_factors(E, G, {sweeps.FORM_CHAIN: 2, sweeps.FORM_GRID: 3}.get(form[0], 1))
        return args, terms, uni, (kicks, drifts, E, G, fsal), form

    def _split_uniform(self, raw: Raw, form: tuple) -> splitting.Uniform:
        """The ``uni`` argument of the splitting sweeps (``splitting.Uniform``): a uniform chain's
        or grid sheet's law (without contacts or constant loads; the column form's accumulators,
        which ``_reverse_start`` adds to the tables), else UNI_NONE (also with
        ``uniform_sweeps=False``; a loaded uniform chain's reverse step still takes the fused
        kernels, through ``form``)."""
        e1, e2 = np.zeros(0), np.zeros((0, 0))
        if self.uniform_sweeps and self.terms.con_ij.shape[0] == 0:
            n = raw.t2.shape[0]
            if form[0] == sweeps.FORM_CHAIN and form[2].size and form[10].size == 0:  # (form[2]: the uniform law)
                return splitting.Uniform(splitting.UNI_CHAIN, form[1], form[2], e1, e1, form[5], e2, e1,
                                         np.zeros((N_V, self._nchain + 1)), e2, e2, e1)
            if form[0] == sweeps.FORM_GRID and (p := sheet_uniform(raw.t1, raw.t2)) is not None:
                nc = form[1]
                return splitting.Uniform(splitting.UNI_SHEET, nc, p, form[3][H_SIGN].copy(), form[4][H_SIGN].copy(),
                                         form[5], form[6], form[7], sheet_uniform_scratch(n, nc),
                                         grid_scratch(n)[0], raw.t1, raw.t2)
        return splitting.Uniform(splitting.UNI_NONE, 0, e1, e1, e1, e2, e2, e1, e2, e2, e2, e1)

    def _split_run(self, raw: Raw, segment: int | None, scratch: bool = False, FS: np.ndarray | None = None,
                   bound: tuple | None = None) -> tuple[Records, tuple]:
        """``run`` of a splitting; ``FS`` (nsteps, stage forces, ndof): keep every step's stage
        forces there (``splitting.forward``; with ``segment`` = 1); ``bound``: ``_split_bind``'s."""
        args, terms, uni, method, _ = bound or self._split_bind(raw)
        q, v, f = raw.q0.copy(), raw.v0.copy(), np.empty_like(raw.q0)
        sweeps.initial_force(args, terms, q, v, f, self.t0)
        seg = segment or max(1, math.isqrt(max(self.nsteps, 1)))
        CQ, CV, CF, CT = self._buffers(q.size, self.nsteps // seg + 1, "checkpoints" if scratch else "")
        rec = self._records()
        splitting.forward(args, terms, uni, *method, q, v, f, self.t0, self.h, self.nsteps, seg, self.stride,
                          self.obs, CQ, CV, CF, CT, rec.q, rec.v, rec.f,
                          np.empty((1, 0, q.size)) if FS is None else FS)
        return rec, (CQ, CV, CF, CT, seg)

    def _split_gradient(self, raw: Raw, objective: Objective, segment: int | None, memory_mb: float,
                        stages: bool = True) -> tuple[float, Raw, Records]:
        """``gradient`` of a splitting run: the same checkpointing (all states kept if they fit).
        The replay (or the forward run that keeps every state) also keeps each step's stage
        forces for the reverse sweep, which then evaluates none; the memory of a step counts
        them. ``stages`` = False: the reverse sweep recomputes them (the same bits, one more
        forward run). A uniform chain or grid sheet takes the uniform kernels (``uni``)."""
        n, N = raw.q0.size, self.nsteps
        bound = self._split_bind(raw)
        args, terms, uni, method, form = bound
        kicks, drifts, _, _, fsal = method
        ns = splitting.n_stage_forces(drifts, fsal) if stages else 0
        keep_all = segment is None and (N + 1) * ((3 + ns) * n + 1) * 8 <= memory_mb * 1e6
        if not keep_all and segment is None:  # a segment's replayed states and stage forces in cache
            segment = _chain_segment(N, n, (3 + ns) * n * 8, memory_mb)
        FS = self._scratch_array("stages", (N if keep_all else segment, ns, n)) if ns else np.empty((1, 0, n))
        rec, (CQ, CV, CF, CT, seg) = self._split_run(raw, 1 if keep_all else segment, True, FS if keep_all else None,
                                                     bound)
        value, explicit, (dq, dv, df), (lq, lv, lf), (g1, g2, gcon, gdrv, gdash) = self._seed(rec, raw, objective)
        GE, GG = np.zeros((kicks.size, n)), np.zeros((kicks.size, n))
        adjoints = (self.stride, self.obs, dq, dv, df, lq, lv, lf, GE, GG, g1, g2, gcon, gdrv, form)
        if keep_all:
            splitting.reverse(args, terms, uni, *method, CQ, CV, CF, CT, FS, self.h, 0, N, *adjoints)
        else:
            SQ, SV, SF, ST = self._buffers(n, seg + 1, "segment")
            none, no_record = np.empty(0, np.int64), np.empty((1, 0))
            for c in range((N - 1) // seg if N else -1, -1, -1):
                k0, m = c * seg, min(seg, N - c * seg)
                # the segment's replay: its forward run from the checkpoint, every state kept
                splitting.forward(args, terms, uni, *method, CQ[c].copy(), CV[c].copy(), CF[c].copy(), CT[c], self.h,
                                  m, 1, m + 1, none, SQ, SV, SF, ST, no_record, no_record, no_record, FS)
                splitting.reverse(args, terms, uni, *method, SQ, SV, SF, ST, FS, self.h, k0, m, *adjoints)
        self._reverse_start(raw, args, terms, lq, lv, lf, g1, g2, gcon, gdrv, gdash, form)
        g_minv, g_damp = splitting.kick_factor_gradients(kicks, raw.minv, raw.damp, self.h, GE, GG)
        grad = Raw(g1, g2, g_minv, g_damp, gcon, gdrv, lq, lv, gdash)
        if explicit is not None:
            grad = grad.axpy(1.0, explicit)
        return float(value), grad, rec

    def _split_sensitivities(self, raw: Raw, directions: list[Raw]) -> tuple[Records, list[Records]]:
        args, terms, uni, (kicks, drifts, E, G, fsal), _ = self._split_bind(raw, per_field=False)
        nd, n = len(directions), raw.q0.size
        dminv, ddamp = _stack(raw, directions, "minv"), _stack(raw, directions, "damp")
        de_m, de_c, dg_m, dg_c = splitting.kick_factor_partials(kicks, raw.minv, raw.damp, self.h)
        DE = np.ascontiguousarray(de_m[None] * dminv[:, None] + de_c[None] * ddamp[:, None])
        DG = np.ascontiguousarray(dg_m[None] * dminv[:, None] + dg_c[None] * ddamp[:, None])
        rec = self._records()
        shape = (nd, self.n_samples, self.obs.size)
        TQ, TV, TF = np.empty(shape), np.empty(shape), np.empty(shape)
        q, v, f = raw.q0.copy(), raw.v0.copy(), np.empty(n)
        splitting.tangent(args, terms, uni, kicks, drifts, E, G, DE, DG, fsal, q, v, f, self.t0, self.h, self.nsteps,
                          self.stride, self.obs, *(_stack(raw, directions, k) for k in ("t1", "t2", "con", "drv")),
                          _stack(raw, directions, "q0"), _stack(raw, directions, "v0"), rec.q, rec.v, rec.f,
                          TQ, TV, TF)
        return rec, [Records(TQ[m], TV[m], TF[m]) for m in range(nd)]

    # -- the implicit midpoint rule (``design.midpoint``) ----------------------------------
    def _midpoint_bind(self, raw: Raw) -> tuple:
        """args, terms and the arguments of ``midpoint._jv``'s Hessian-vector product: the run's
        ``form`` (fresh accumulators), parameter-adjoint sinks, zero dashpot and drive directions."""
        args, terms = self.bind(raw)[:2]
        sinks = tuple(np.zeros_like(a) for a in (raw.t1, raw.t2, raw.con, raw.drv))
        return args, terms, (self.form(raw), *sinks, np.zeros_like(raw.dash), np.zeros_like(raw.drv))

    def _midpoint_failed(self, step: int, what: str) -> None:
        if step >= 0:
            raise GradientError(
                f"implicit_midpoint: {what} did not converge at step {step} (t = {self.t0 + step * self.h:.6g}); "
                "the engine would split that step into substeps, which the adjoint does not follow (compression "
                "past buckling, or a step far beyond the explicit limit): reduce solver.dt_s")

    def _midpoint_run(self, raw: Raw, segment: int | None, keep_v: bool = False) -> tuple:
        """(records, checkpoints, midpoint velocities of every step if ``keep_v``)."""
        args, terms = self.bind(raw)[:2]
        n, N = raw.q0.size, self.nsteps
        q, v, f = raw.q0.copy(), raw.v0.copy(), np.empty(n)
        sweeps.initial_force(args, terms, q, v, f, self.t0)
        seg = segment or max(1, math.isqrt(max(N, 1)))
        CQ, CV, CF, CT = self._buffers(n, N // seg + 1)
        SW = np.empty((N if keep_v else 0, n))
        rec = self._records()
        _, failed = midpoint.forward(args, terms, raw.minv, raw.damp, midpoint.NEWTON_RTOL, q, v, f, self.t0, self.h,
                                     N, seg, self.stride, self.obs, CQ, CV, CF, CT, SW, rec.q, rec.v, rec.f)
        self._midpoint_failed(failed, "Newton's iteration (to the design tolerance)")
        return rec, (CQ, CV, CF, CT, seg), SW

    def _midpoint_gradient(self, raw: Raw, objective: Objective, segment: int | None,
                           memory_mb: float) -> tuple[float, Raw, Records]:
        """``gradient`` of an implicit-midpoint run: the same checkpointing (all states and
        midpoint velocities kept if they fit), one linear solve per step."""
        n, N = raw.q0.size, self.nsteps
        args, terms, mv = self._midpoint_bind(raw)
        form = self.form(raw)
        keep_all = segment is None and (N + 1) * (4 * n + 1) * 8 <= memory_mb * 1e6
        rec, (CQ, CV, CF, CT, seg), SW = self._midpoint_run(raw, 1 if keep_all else segment, keep_all)
        value, explicit, (dq, dv, df), (lq, lv, lf), (g1, g2, gcon, gdrv, gdash) = self._seed(rec, raw, objective)
        gminv, gdamp = np.zeros(n), np.zeros(n)
        adjoints = (self.stride, self.obs, dq, dv, df, lq, lv, lf, g1, g2, gcon, gdrv, gdash, gminv, gdamp, form, mv)
        prm = (args, terms, raw.minv, raw.damp)
        failed = -1
        if keep_all:
            failed = midpoint.reverse(*prm, CQ, CV, SW, CT, self.h, 0, N, *adjoints)
        else:
            SQ, SV, SF, ST = self._buffers(n, seg + 1)
            SW = np.empty((seg, n))
            none, no_record = np.empty(0, np.int64), np.empty((1, 0))
            for c in range((N - 1) // seg if N else -1, -1, -1):
                k0, m = c * seg, min(seg, N - c * seg)
                midpoint.forward(*prm, midpoint.NEWTON_RTOL, CQ[c].copy(), CV[c].copy(), CF[c].copy(), CT[c], self.h,
                                 m, 1, m + 1, none, SQ, SV, SF, ST, SW, no_record, no_record, no_record)
                failed = midpoint.reverse(*prm, SQ, SV, SW, ST, self.h, k0, m, *adjoints)
                if failed >= 0:
                    break
        self._midpoint_failed(failed, "the adjoint's linear solve")
        self._reverse_start(raw, args, terms, lq, lv, lf, g1, g2, gcon, gdrv, gdash, form)
        grad = Raw(g1, g2, gminv, gdamp, gcon, gdrv, lq, lv, gdash)
        if explicit is not None:
            grad = grad.axpy(1.0, explicit)
        return float(value), grad, rec

    def _midpoint_sensitivities(self, raw: Raw, directions: list[Raw]) -> tuple[Records, list[Records]]:
        args, terms, mv = self._midpoint_bind(raw)
        nd, n = len(directions), raw.q0.size
        rec = self._records()
        shape = (nd, self.n_samples, self.obs.size)
        TQ, TV, TF = np.empty(shape), np.empty(shape), np.empty(shape)
        q, v, f = raw.q0.copy(), raw.v0.copy(), np.empty(n)
        _, failed = midpoint.tangent(
            args, terms, raw.minv, raw.damp, midpoint.NEWTON_RTOL, q, v, f, self.t0, self.h, self.nsteps, self.stride,
            self.obs, *(_stack(raw, directions, k) for k in ("t1", "t2", "con", "drv", "dash", "minv", "damp", "q0",
                                                             "v0")),
            rec.q, rec.v, rec.f, TQ, TV, TF, mv)
        self._midpoint_failed(failed, "Newton's iteration or the tangent's linear solve")
        return rec, [Records(TQ[m], TV[m], TF[m]) for m in range(nd)]

    def value(self, raw: Raw, objective: Objective) -> float:
        rec, _ = self.run(raw, segment=self.nsteps + 1)
        return float(objective(rec, raw)[0])

    def sensitivities(self, raw: Raw, directions: list[Raw]) -> tuple[Records, list[Records]]:
        """Records and their derivatives along each raw direction (one forward tangent run)."""
        if self._split is not None:
            return self._split_sensitivities(raw, directions)
        if self.integrator == "implicit_midpoint":
            return self._midpoint_sensitivities(raw, directions)
        args, terms, kick, pre, post = self.bind(raw)
        nd, n = len(directions), raw.q0.size
        hh = 0.5 * self.h

        def stack(name):
            return _stack(raw, directions, name)

        dminv, ddamp = stack("minv"), stack("damp")
        dg = ddamp * raw.minv + raw.damp * dminv  # d(c m⁻¹)
        DK = hh * dminv
        DP = -hh * dg
        DS = -(post * post) * hh * dg
        rec = self._records()
        shape = (nd, self.n_samples, self.obs.size)
        TQ, TV, TF = np.empty(shape), np.empty(shape), np.empty(shape)
        q, v, f = raw.q0.copy(), raw.v0.copy(), np.empty(n)
        sweeps.tangent(args, terms, kick, pre, post, q, v, f, self.t0, self.h, self.nsteps, self.stride, self.obs,
                       stack("t1"), stack("t2"), DK, DP, DS, stack("con"), stack("drv"), stack("dash"), stack("q0"),
                       stack("v0"),
                       rec.q, rec.v, rec.f, TQ, TV, TF)
        return rec, [Records(TQ[m], TV[m], TF[m]) for m in range(nd)]


def _chain_segment(nsteps: int, ndof: int, state_bytes: int, memory_mb: float) -> int:
    """A chain's checkpoint segment: ⌈√nsteps⌉ steps, or fewer so that a segment's replayed states
    (``state_bytes`` a step) take at most ``SEGMENT_MB``, but not fewer than ``ENGINE_MIN_STEPS``
    nor than keeps the checkpoints ((q, v, f) every segment) within ``memory_mb``."""
    seg = max(1, math.isqrt(max(nsteps, 1)))
    fit = max(ENGINE_MIN_STEPS, int(SEGMENT_MB * 1e6 // state_bytes))
    bounded = -(-(nsteps + 1) * 3 * ndof * 8 // int(memory_mb * 1e6))  # ceil: checkpoints within the budget
    return min(seg, max(fit, bounded))


def _tile_segment(nsteps: int, ndof: int, memory_mb: float) -> int:
    """A tiled chain's checkpoint segment: ``TILE_STEPS`` steps (a window's halo grows with it;
    fewer checkpoints cut the forward run's time blocks less often), at most the run, but not
    fewer than keeps the checkpoints within ``memory_mb``."""
    seg = max(1, min(nsteps, TILE_STEPS))
    rows = int(memory_mb * 1e6 // (3 * ndof * 8))  # checkpoints (q, v, f) the budget holds
    bounded = -(-nsteps // (rows - 1)) if rows > 1 else nsteps  # nsteps // seg + 1 <= rows
    return max(seg, bounded)


def _field_factors(kick, pre, post, nf: int) -> tuple:
    """The integrator factors (K per field, then S, then P) of ``nf`` equal fields of DOFs:
    scalars if each is constant on every field, else per-field columns."""
    n = kick.size // nf
    fields = [a[i * n : (i + 1) * n] for a in (kick, post, pre) for i in range(nf)]
    if all(np.all(a == a[0]) for a in fields):
        return tuple(float(a[0]) for a in fields)
    return tuple(np.ascontiguousarray(a) for a in fields)


def _stack(raw: Raw, directions: list[Raw], name: str) -> np.ndarray:
    """The directions' arrays ``name`` stacked (first axis: the direction)."""
    return np.ascontiguousarray(np.stack([getattr(d, name) for d in directions]) if directions else
                                np.zeros((0,) + getattr(raw, name).shape))


def trajectory_of(problem, nsteps: int | None = None, stride: int = 1, obs=None, h: float | None = None,
                  integrator: str | None = None) -> tuple[Trajectory, Raw]:
    """The Trajectory and raw arrays of a built problem (``assemble.Problem``).

    ``integrator`` defaults to the scene's (``solver.integrator``; ``GradientError`` if it has no
    adjoint); ``nsteps`` defaults to the problem's duration in steps of ``h`` (default: its dt), rounded
    up to a multiple of ``stride``; ``obs`` defaults to every DOF.
    """
    s = problem.system
    check_differentiable(s, problem.terms)
    h = problem.dt if h is None else h
    if nsteps is None:
        nsteps = max(1, math.ceil(problem.duration / h - 1e-9))
    nsteps = stride * math.ceil(nsteps / stride)
    obs = np.arange(s.ndof) if obs is None else obs
    traj = Trajectory(s.args, problem.terms, h, nsteps, stride, obs,
                      integrator=problem.scene.solver.integrator if integrator is None else integrator)
    return traj, raw_of(s, problem.terms, problem.damp)
