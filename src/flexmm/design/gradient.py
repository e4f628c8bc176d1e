"""Exact gradients of trajectory objectives through a run of velocity Verlet, of a symplectic
splitting (PEFRL, Blanes–Moan's 6th-order method) or of the implicit midpoint rule (its Newton
iteration run to round-off).

The differentiable inputs of a built problem are its *raw* arrays (``Raw``): the model's two
parameter tables (``kernels.param_tables``), the inverse masses and on-site damping per DOF,
the contact and drive parameter rows (ground friction's among them), the initial state and the
dashpot coefficients. ``Trajectory`` runs a problem with its integrator (``DIFFERENTIABLE``;
velocity Verlet by default, with velocity-dependent forces at the engine's predicted velocity)
and records (q, v, f) at the observed DOFs every ``stride`` steps; ``gradient`` returns an
objective and its gradient with respect to every raw array by the checkpointing tape
(``design.tape``: one forward run with checkpoints, one reverse sweep); ``sensitivities``
returns the records' derivatives along a few raw directions (forward mode, for least-squares
Jacobians). The integrator's steps and their fast paths are ``design.steps``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flexmm.design import splitting, sweeps
from flexmm.design.kernels import (N_CA, N_F, N_R, adjoint_kernels_of, chain_columns, chain_ordered, chain_uniform, param_tables,
                                   sheet_grid, sheet_grid_columns, with_tables)
from flexmm.design.steps import steps_of
from flexmm.design.tape import MEMORY_MB, GradientError, Objective, Raw, Records, default_segment
from flexmm.design.tape import gradient as tape_gradient
from flexmm.design.tape import sensitivities as tape_sensitivities
from flexmm.integrators.common import MODE_FRICTION, Terms, has_velocity_terms
from flexmm.models.hinge import S_KG
from flexmm.models.loads import LoadedChainArgs

__all__ = ["DIFFERENTIABLE", "GradientError", "Objective", "Raw", "Records", "Trajectory", "check_differentiable",
           "raw_of", "trajectory_of"]


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
class Trajectory:
    """What a differentiated run needs besides the raw arrays: the system's args and terms (their
    non-differentiable parts), the step ``h``, ``nsteps``, the recording ``stride`` and the
    observed DOFs ``obs``, and the start time ``t0``.

    The model part of the reverse step takes column form where it can (``form``): a
    chain-ordered rotating-squares chain, loaded or not, with contacts (a striker) or not, and a
    grid sheet; the gradient is the same to rounding, at a third to a half of the cost
    (``python benchmarks/run.py gradient``). The integrator's steps and their fast paths (the
    column run of a chain, a uniform chain's or sheet's scalar-parameter sweeps, the engine's
    fused forward kernel, tiles) are chosen by ``steps.steps_of``; the flags below turn them off
    for comparisons (``column_sweeps=False``: the model's own adjoint kernel always)."""

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
    #: faster (``steps.ChainColumns._engine_run``); False: ``sweeps.chain_forward`` always
    engine_forward: bool = True
    #: a long uniform chain's replay and reverse sweep window by window (``sweeps.chain_uniform_tiles``)
    #: where they apply (``steps.UniformChain._tiled``); False: over the whole chain each step
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
    def steps(self, raw: Raw):
        """The integrator's steps at ``raw`` (``steps.steps_of``: its fast path where one applies)."""
        return steps_of(self, raw)

    def run(self, raw: Raw, segment: int | None = None, scratch: bool = False) -> tuple[Records, tuple]:
        """Forward run: the records, and the checkpoints (CQ, CV, CF, CT, segment) every ``segment``
        steps (default ⌈√nsteps⌉); ``scratch``: the checkpoints in arrays the next such run
        overwrites (``_scratch_array``)."""
        return self.steps(raw).forward(segment or default_segment(self.nsteps), scratch)

    def gradient(self, raw: Raw, objective: Objective, segment: int | None = None,
                 memory_mb: float = MEMORY_MB) -> tuple[float, Raw, Records]:
        """(J, dJ/draw, records) by one forward run and one reverse sweep (``tape.gradient``: every
        state kept if they fit in ``memory_mb``, and no ``segment`` is asked for; else checkpoints
        every ``segment`` steps and one segment replayed at a time)."""
        return tape_gradient(self.steps(raw), objective, segment, memory_mb)

    def value(self, raw: Raw, objective: Objective) -> float:
        rec, _ = self.run(raw, segment=self.nsteps + 1)
        return float(objective(rec, raw)[0])

    def sensitivities(self, raw: Raw, directions: list[Raw]) -> tuple[Records, list[Records]]:
        """Records and their derivatives along each raw direction (one forward tangent run)."""
        return tape_sensitivities(self.steps(raw), directions)


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
