"""How far waves get in a run: linear group speeds from the Hessian, reach, trimming, absorbing layers.

Group speed. The lattice is linearised about a reference state (rest, or a uniform strain the
excitation is expected to impose, so that contacts without preload — a Hertz chain — get their
loaded stiffness). Hessian columns of a probe cell of 2 sites along x (2×2 in a sheet) come
from ``stability.hessian_operator``; Bloch sums over the sites of each parity class
(``flexmm.linalg.read_cell`` and ``bloch_eigen``) give

    K(k) x = ω² M x,   K_{(g,c'),(f,c)}(k) = Σ_{j ∈ c'} H_{(g,j),(f,c)} exp(i k·(n_j − n_c)),

with n the integer site grid and M the diagonal mass. The cell of two sites per direction
covers the checkerboard of rotating units; folding does not change group speeds. The fastest
signal speed is max |∂ω/∂k_x| over all branches and sampled k (sites per unit time).

Reach. Waves leave the excitation (an end, or the soliton's centre) at most at that speed, so
after the run's duration T they are within c_max T sites; ahead of that front a discrete
lattice responds only with super-exponentially small precursors. The plan keeps
``c_max T (1 + MARGIN) + PAD`` sites beyond the source and trims the rest.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flexmm.errors import PlanError
from flexmm.integrators.common import Terms
from flexmm.linalg import bloch_eigen, read_cell
from flexmm.models.base import System
from flexmm.stability import hessian_operator

MARGIN = 0.10
PAD = 20
TRIM_WASTE = 0.20  # trim (or warn) when more than this fraction of the lattice is never reached


@dataclass(frozen=True)
class Dispersion:
    """Linear bands along x: ``k`` (n_k,) in rad per site, ``omega`` (n_k, n_b), ``group`` (n_k−1, n_b).

    ``group`` holds ∂ω/∂k on the midpoints of ``k`` (sites per unit nondimensional time), for
    each transverse wavenumber sampled (the max over them is kept).
    """

    k: np.ndarray
    omega: np.ndarray
    group: np.ndarray
    stable: bool = True  # False if the reference state has negative stiffness (buckles)

    @property
    def max_group_speed(self) -> float:
        return float(np.max(np.abs(self.group))) if self.group.size else 0.0


def _probe_cell(ix: np.ndarray, iy: np.ndarray) -> list[int]:
    """Sites of a 2 (×2) cell near the middle of the lattice, one per parity class."""
    two_d = iy.max() > 0
    cx = 2 * ((ix.max() // 2) // 2)
    cy = 2 * ((iy.max() // 2) // 2) if two_d else 0
    cell = []
    for dy in ((0, 1) if two_d else (0,)):
        for dx in (0, 1):
            hit = np.flatnonzero((ix == cx + dx) & (iy == cy + dy))
            if hit.size == 0:
                raise PlanError("lattice too small to probe its dispersion (need 2 sites per direction)")
            cell.append(int(hit[0]))
    return cell


def rest_state(system: System) -> np.ndarray | None:
    """The state the lattice is linearised about: a predeformed equilibrium, else None (q = 0)."""
    rest = system.rest_state
    return None if rest is None else np.concatenate([rest, system.q0[rest.size:]])


def bloch_dispersion(system: System, terms: Terms, q_ref: np.ndarray | None = None,
                     n_k: int = 257, n_ky: int = 9) -> Dispersion:
    """Linear dispersion along x of a built system about ``q_ref`` (default: its rest state)."""
    n, nf = system.n_sites, len(system.fields)
    q_ref = rest_state(system) if q_ref is None else q_ref
    ix, iy = system.site_grid()
    two_d = iy.max() > 0
    cell = _probe_cell(ix, iy)
    cls = (ix % 2) + (2 * (iy % 2) if two_d else 0)
    dof = np.arange(system.ndof)
    site = dof % n
    dof_class = np.where(dof < nf * n, cls[site] * nf + dof // n, -1)
    cell_dofs = [f * n + c for c in cell for f in range(nf)]
    bloch = read_cell(hessian_operator(system, terms, q_ref), system.ndof, cell_dofs, dof_class,
                      np.stack([ix[site], iy[site]], axis=1), system.mass[cell_dofs], tol=1e-9)
    k = np.linspace(0.0, math.pi, n_k)
    kys = np.linspace(0.0, math.pi, n_ky) if two_d else np.zeros(1)
    omega_all, group, lam_min, lam_max = [], [], 0.0, 0.0
    for ky in kys:
        lam = bloch_eigen(bloch, np.stack([k, np.full(n_k, ky)], axis=1))
        lam_min, lam_max = min(lam_min, lam[:, 0].min()), max(lam_max, lam[:, -1].max())
        om = np.sqrt(np.clip(lam, 0.0, None))
        omega_all.append(om)
        group.append(np.diff(om, axis=0) / np.diff(k)[:, None])
    grp = np.max(np.abs(np.stack(group)), axis=0)
    return Dispersion(k, omega_all[0], grp, stable=lam_min >= -1e-9 * max(lam_max, 1e-300))


def excitation_velocity(scene, system: System) -> float:
    """Velocity scale the excitation imposes on the lattice (nondimensional, ≥ 0)."""
    return scene.excitation.imposed_velocity_m_s() / system.scales.velocity


def strained_state(system: System, strain: float) -> np.ndarray:
    """Uniform longitudinal strain ``strain`` (> 0 compression) about rest, as a state vector."""
    rest = rest_state(system)
    q = np.zeros(system.ndof) if rest is None else rest.copy()
    field = system.longitudinal_field
    x = np.asarray(system.site_coords.get("x", np.arange(system.n_sites) * system.spacing_m), float)
    k = system.field_index(field) * system.n_sites
    q[k : k + system.n_sites] += -strain * (x - x.mean()) / system.scales.length_m
    return q


def max_signal_speed(system: System, terms: Terms, velocity: float = 0.0) -> tuple[float, float]:
    """Fastest linear group speed (sites per unit time) and the strain it was evaluated at.

    At rest, and — when the excitation imposes a velocity ``velocity`` (nondimensional) — about
    the uniform strain ε with ε = V / c(ε) (fixed point, both signs), since stiffening contacts
    carry faster waves under load. A strained state that buckles (negative stiffness) is not a
    state the waves travel in and is skipped.
    """
    c_rest = bloch_dispersion(system, terms).max_group_speed
    best, at = c_rest, 0.0
    if velocity <= 0:
        return best, at
    spacing = system.spacing_m / system.scales.length_m
    for sign in (1.0, -1.0):
        eps = velocity / (c_rest * spacing) if c_rest > 1e-6 else min(velocity, 0.1) ** 0.8
        eps = min(eps, 0.3)
        c = 0.0
        for _ in range(6):
            disp = bloch_dispersion(system, terms, strained_state(system, sign * eps), n_k=129, n_ky=5)
            c = disp.max_group_speed if disp.stable else 0.0
            if c <= 1e-9:
                break
            new = min(velocity / (c * spacing), 0.3)
            done = abs(new - eps) < 0.02 * eps
            eps = new
            if done:
                break
        if c > best:
            best, at = c, sign * eps
    return best, at


@dataclass(frozen=True)
class Reach:
    """Where waves can be at the end of the run (site indices along x)."""

    speed_sites: float  # fastest linear group speed, sites per unit nondimensional time
    speed_m_s: float
    strain: float  # strain the speed was evaluated at (0: rest)
    duration: float  # nondimensional
    sites_reached: float  # c_max · T
    n_declared: int
    keep: tuple[int, int] | None  # inclusive site range along x to keep, None if no bound

    @property
    def n_needed(self) -> int:
        return self.n_declared if self.keep is None else self.keep[1] - self.keep[0] + 1

    @property
    def waste(self) -> float:
        """Fraction of the declared units the waves never reach."""
        return 1.0 - self.n_needed / self.n_declared


def _sources(scene, ix: np.ndarray) -> list[int] | None:
    """x indices where waves start (excited ends, soliton centres, seeds); None if everywhere."""
    exc, imp = scene.excitation, scene.imperfection
    if getattr(scene, "initial", None) is not None:
        return None  # an initial state (fields, launched waves, pins, another run) may be anywhere
    if imp is not None and imp.kind != "rotation_seed":
        return None  # random imperfections: every unit is a source
    points = exc.sources()
    if points is None:
        return None
    last, src = int(ix.max()), []
    for p in points:  # a site index, or the left/right end
        if isinstance(p, str) and p not in ("left", "right"):
            return None
        src.append(int(ix[min(p, ix.size - 1)]) if isinstance(p, int) else 0 if p == "left" else last)
    if imp is not None:
        src += [int(ix[s]) for s in imp.sites]
    return src or None


def wave_reach(scene, system: System, terms: Terms, duration: float, bands: tuple | None = None) -> Reach:
    """Reach of the waves of ``scene`` in ``duration`` (nondimensional) on ``system``.

    Every source (the excited end or soliton centre, rotation seeds) starts waves; the kept
    range covers the light cones of all of them, so the cut lies where nothing ever moves.
    ``bands``: the (system, terms) whose bands give the speed (default ``system``'s; a small copy
    of a uniform lattice has the same bands, and its Hessian columns cost little).
    """
    ix, _ = system.site_grid()
    n_x = int(ix.max()) + 1
    c, strain = max_signal_speed(*(bands or (system, terms)), excitation_velocity(scene, system))
    reach = c * duration
    span = int(math.ceil(reach * (1 + MARGIN))) + PAD
    src = _sources(scene, ix)
    keep = None if src is None else (max(0, min(src) - span), min(n_x - 1, max(src) + span))
    speed_m_s = c * system.spacing_m / system.scales.time_s
    return Reach(c, speed_m_s, strain, duration, reach, n_x, keep)


def length_key(lattice_cfg) -> str | None:
    """Name of the lattice field that counts units along x (its ``ModelSpec.length``), or None."""
    from flexmm.config.lattice import MODELS

    return MODELS[lattice_cfg.kind].length


def trim_scene(scene, keep: tuple[int, int], *, probe: bool = False):
    """A copy of ``scene`` keeping only the sites ``keep[0]..keep[1]`` along x. ``probe``: a copy
    the planner only measures on (the bands, the pilots): it saves nothing (a site stride meant for
    the whole lattice may exceed the copy) and starts from rest (no initial state, whose sites may
    lie beyond it).

    Site indices in the excitation (soliton centres, struck or kicked units) and imperfection
    (seed sites) follow the kept range (2D: sites are row-major with x the fast index); seeds
    outside it are dropped.
    """
    from flexmm.config import scene_from_dict

    key = length_key(scene.lattice)
    if key is None:
        raise PlanError(f"cannot trim lattice kind {scene.lattice.kind!r}: no length field")
    lo, hi = keep
    data = scene.model_dump(mode="json")
    if probe:
        data["initial"] = None
        data["output"]["site_stride"] = 1
    n_x = getattr(scene.lattice, key)
    n_new = hi - lo + 1
    data["lattice"][key] = n_new

    def remap(sites):  # site = row · n_x + column (a chain has one row)
        rows_cols = [divmod(s, n_x) for s in sites]
        return [r * n_new + c - lo for r, c in rows_cols if lo <= c <= hi]

    exc = data.get("excitation") or {}
    if "center_site" in exc:  # a soliton
        exc["center_site"] -= lo
    for p in exc.get("pulses") or []:
        p["center_site"] -= lo
    if exc.get("sites"):
        exc["sites"] = remap(exc["sites"])
    for k in exc.get("kicks") or []:
        if k.get("sites"):
            k["sites"] = remap(k["sites"])
    imp = data.get("imperfection")
    if imp and imp.get("kind") == "rotation_seed":
        imp["sites"] = remap(imp["sites"])
    layer = (data.get("damping") or {}).get("absorbing")
    if layer:  # a layer at a trimmed end is never reached: drop it there
        ends = {"left", "right"} if layer["end"] == "both" else {layer["end"]}
        ends -= {"left"} if lo > 0 else set()
        ends -= {"right"} if hi < n_x - 1 else set()
        if not ends or layer["n_units"] >= hi - lo + 1:
            data["damping"]["absorbing"] = None
        else:
            layer["end"] = "both" if len(ends) == 2 else ends.pop()
    return scene_from_dict(data, source="<plan: trimmed>")
