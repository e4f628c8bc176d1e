"""Bloch bands of a periodic rigid-unit network (docs/physics.md §1.9), from the exact Hessian of the
energy its runs integrate.

A periodic network (``lattice.left/right`` or ``bottom/top: periodic`` on a generated sheet, or a
geometry file with ``lattice_vectors_m``) is one cell of N units repeated by its lattice vectors
A_p; link k joins unit a_k of a cell to unit b_k of the cell displaced by s_k·A
(``System.periodic``). Its Hessian at rest couples DOF α of unit a to DOF β of the copy of unit b
at R_b + s·A; summing over those partners with the phase of the partner's position,

    D_αβ(k) = Σ K_{α, β(s)} e^{i k·(R_b + s·A − R_a)},    D(k) x = ω² M x,

M the cell's diagonal mass (``flexmm.linalg.read_cell``, ``bloch_frequencies``). The couplings
are read from the Hessian-vector product of the ligament law (``models.ligaments.network_hvp``,
exact, the law the runs integrate) applied to a copy of the cell tiled 3 times along each periodic
direction, where every link's partner (shifts −1, 0, 1) is a distinct unit. Held DOFs (fixed
edges of a strip, ``fixed_units``) are left out of the cell. A generated sheet whose pattern
repeats every two columns and rows is reduced to that 2 × 2 cell (2 columns of a strip); random
quads, networks with regions and geometry files keep their whole cell. Nondimensional: k in 1/a, ω in
1/sqrt(m/k_l) (``System.scales``).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from flexmm.errors import FlexmmError
from flexmm.linalg import BlochCell, bloch_eigen, bloch_frequencies, bloch_matrices, read_cell
from flexmm.models.ligaments import NetworkArgs, network_hvp
from flexmm.models.network import build

#: copies of the cell along each periodic direction in the tiled network the couplings are read from
_TILES = 3


class NotPeriodic(FlexmmError):
    """The network has no periodic direction, so it has no Bloch bands."""


def cell_lattice(lat):
    """The smallest periodic copy of a network config whose Bloch cell gives its bands: a generated
    pattern cut to 2 columns (and 2 rows) along its periodic directions, with no named sets; a
    random-quads sheet, a network with regions or a geometry file as given. NotPeriodic without a
    periodic direction."""
    if lat.geometry is None and not lat.periodic_axes:
        raise NotPeriodic("the network is not periodic: set left/right (and/or bottom/top) to periodic, or give "
                          "the geometry file lattice_vectors_m and ligament shifts")
    if lat.geometry is not None or lat.pattern == "random_quads" or lat.regions:
        return lat
    update = {"unit_sets": {}, "fixed_units": []}
    if "x" in lat.periodic_axes:
        update["n_cols"] = 2
    if "y" in lat.periodic_axes:
        update["n_rows"] = 2
    return lat.model_copy(update=update)


def tiled_args(args: NetworkArgs, shifts: np.ndarray, n: int) -> tuple[NetworkArgs, np.ndarray]:
    """The network of ``_TILES`` copies of the cell along each of its P periodic directions, links
    wrapping on that torus: (its args, the cell index (T, P) of every copy, in −1..1). Copy t holds
    units t·n .. t·n + n − 1; a link of shift s from a unit of copy t joins copy t + s (mod 3)."""
    p = shifts.shape[1]
    tiles = np.array(list(itertools.product(range(_TILES), repeat=p)), np.int64)[:, ::-1]  # first index fastest
    flat = lambda t: (t * _TILES ** np.arange(p)).sum(-1)  # noqa: E731
    ua = np.concatenate([args.unit_a + n * flat(t) for t in tiles])
    ub = np.concatenate([args.unit_b + n * flat((t + shifts) % _TILES) for t in tiles])
    m = n * len(tiles)
    big = NetworkArgs(ua, ub, np.tile(args.ligaments, (len(tiles), 1)), np.zeros(m), np.zeros(m), args.law)
    return big, np.where(tiles == _TILES - 1, -1, tiles)


def network_cell(system) -> BlochCell:
    """The ``BlochCell`` of a built periodic network (its free DOFs, cell DOF order field-major:
    u, v, θ of every free unit), offsets the partners' rest positions in units of a."""
    if system.periodic is None:
        raise NotPeriodic("the network is not periodic (no lattice vectors)")
    n = system.n_sites
    cell, centres = system.periodic, system.unit_shapes().centres
    big, tiles = tiled_args(system.args, cell.link_shifts, n)
    m = big.cos.size
    q, out = np.zeros(3 * m), np.zeros(3 * m)

    def hvp(x):
        network_hvp(q, big, np.asarray(x, float), out)
        return out.copy()

    free = np.flatnonzero(system.inv_mass > 0)  # cell DOFs f·n + unit
    index = np.full(3 * n, -1)
    index[free] = np.arange(free.size)
    dof = np.arange(3 * m)
    field, unit = np.divmod(dof, m)
    dof_class = index[field * n + unit % n]
    positions = centres[unit % n] + tiles[unit // n] @ cell.vectors
    cell_dofs = (free // n) * m + free % n  # copy 0
    return read_cell(hvp, 3 * m, cell_dofs, dof_class, positions, system.mass[free])


def network_bands(lat, k) -> np.ndarray:
    """ω(k) (…, d) ascending, nondimensional, of the periodic network ``lat`` (a ``RigidNetwork``
    config) at wave vectors ``k`` (…, 2) in 1/a; d the free DOFs of its Bloch cell (``cell_lattice``)."""
    return bloch_frequencies(network_cell(build(cell_lattice(lat))), k)


def group_velocity(lat, k, band: int, dk: float = 1e-5) -> np.ndarray:
    """∇_k ω of branch ``band`` at wave vector ``k`` (2,) (central differences of ``network_bands``),
    nondimensional (a sqrt(k_l/m))."""
    cell = network_cell(build(cell_lattice(lat)))
    k = np.asarray(k, float)
    steps = np.array([[dk, 0.0], [0.0, dk]])
    w = bloch_frequencies(cell, np.concatenate([k + steps, k - steps]))[:, band]
    return (w[:2] - w[2:]) / (2 * dk)


def band_path(lat, n_points: int = 64) -> dict:
    """The bands of the periodic network ``lat`` along Γ → ½b₁ → ½(b₁ + b₂) → Γ (one periodic
    direction: Γ → ½b₁), b_p the reciprocal vectors of its Bloch cell (``cell_lattice``), ``n_points``
    wave vectors per segment. SI: {"k_rad_m" (K, 2), "distance_rad_m" (K,) along the path, "labels"
    [(distance, name)], "frequency_hz" (K, d)}; NaN for an unstable branch."""
    small = build(cell_lattice(lat))
    cell = network_cell(small)
    vectors = small.periodic.vectors
    recip = 2 * np.pi * np.linalg.pinv(vectors).T  # (P, 2): b_p · A_q = 2π δ_pq
    corners = [np.zeros(2), 0.5 * recip[0]] + ([0.5 * (recip[0] + recip[1]), np.zeros(2)] if len(recip) > 1 else [])
    names = ["Γ", "X"] + (["M", "Γ"] if len(recip) > 1 else [])
    t = np.linspace(0.0, 1.0, n_points, endpoint=False)
    k = np.concatenate([p + t[:, None] * (q - p) for p, q in zip(corners[:-1], corners[1:])] + [corners[-1][None]])
    step = np.hypot(*np.diff(k, axis=0).T)
    distance = np.concatenate([[0.0], np.cumsum(step)])
    at = [0.0] + [float(distance[(i + 1) * n_points]) for i in range(len(corners) - 1)]
    scales = small.scales
    return {"k_rad_m": k / scales.length_m, "distance_rad_m": distance / scales.length_m,
            "labels": [(d / scales.length_m, name) for d, name in zip(at, names)],
            "frequency_hz": bloch_frequencies(cell, k) / (2 * np.pi * scales.time_s)}


def uniform_sheet(lat, region=None):
    """A generated network (``lat``, a ``RigidNetwork`` config) made of one of its media everywhere:
    ``lat.region_lattice(region)`` (same units, numbering and length scale)."""
    if lat.geometry is not None or lat.pattern == "random_quads":
        raise NotPeriodic("a uniform medium is defined for generated patterns only (not a geometry file or random quads)")
    return lat.region_lattice(region)


def region_medium(lat, region=None):
    """The uniform, doubly periodic 2 × 2 cell of ``uniform_sheet(lat, region)``: the medium whose
    long waves that part of the sheet carries. Unit (row, col) of the sheet copies cell unit
    2·(row mod 2) + col mod 2."""
    return uniform_sheet(lat, region).model_copy(update={
        "n_rows": 2, "n_cols": 2, "left": "periodic", "right": "periodic", "bottom": "periodic", "top": "periodic",
        "unit_sets": {}, "fixed_units": [], "mask": None})


@dataclass(frozen=True)
class LongWaveMode:
    """The long-wave longitudinal Bloch mode along a direction e of a uniform medium
    (docs/physics.md §1.9, "Long waves of a pre-rotated network"): its speed and impedance ρc (ρ
    the mass per area; SI), ``band`` its branch at small k, and the unit motions of a slowly
    varying displacement f(s) along e (s = e·x, f and s in the same length unit): q = ``shape`` f +
    ``gradient`` df/ds, both (3, n) over the cell's units (u, v, θ; ``shape`` the translation e,
    ``gradient`` in that unit per unit strain: rad for θ)."""

    speed_m_s: float
    impedance_kg_per_m_s: float
    band: int
    shape: np.ndarray
    gradient: np.ndarray


def long_wave_mode(medium, direction=(1.0, 0.0), dk: float = 1e-3) -> LongWaveMode:
    """The ``LongWaveMode`` of the periodic network ``medium`` (``region_medium``) along
    ``direction``: the branch at k = dk·e (1/a) whose mode moves the cell's mass most along e, its
    mode x(k) normalised to a unit mean translation along e; shape Re x, gradient Im x / dk (the
    first order in k of x(k) e^{ik·R}: the motion slaved to the strain, e.g. the counter-rotation
    of pre-rotated squares; relative error O(dk²))."""
    system = build(cell_lattice(medium))
    if np.any(system.inv_mass == 0) or system.periodic.vectors.shape[0] != 2:
        raise NotPeriodic("a long-wave mode needs a cell periodic in x and y with no held DOF")
    e = np.asarray(direction, float) / math.hypot(*direction)
    n, mass, sc = system.n_sites, system.mass, system.scales
    lam, vec = bloch_eigen(network_cell(system), dk * e, vectors=True)
    push = np.concatenate([e[0] * mass[:n], e[1] * mass[n:2 * n], np.zeros(n)])  # Σ m e·u of a mode
    band = int(np.argmax(np.abs(push @ vec)))
    x = vec[:, band] * (mass[:n].sum() / (push @ vec[:, band]))
    speed = math.sqrt(max(float(lam[band]), 0.0)) / dk * sc.length_m / sc.time_s
    density = mass[:n].sum() * sc.mass_kg / (abs(float(np.linalg.det(system.periodic.vectors))) * sc.length_m ** 2)
    return LongWaveMode(speed, float(density * speed), band, x.real.reshape(3, n), (x.imag / dk).reshape(3, n))


@dataclass(frozen=True)
class BranchSplit:
    """A state of a generated sheet decomposed into Bloch waves (``bloch_split``): ``forward`` and
    ``backward`` (d,) the energy (nondimensional) running along +e and −e in each band (ascending ω
    at each k); ``mode_forward``, ``mode_backward`` that of the branch of a ``LongWaveMode`` (at each
    k the band whose shape is closest to the mode's), and ``field`` (3N,) the displacements of its
    forward waves with the uniform translation (k = 0) they ride on: the pulse that branch carries."""

    forward: np.ndarray
    backward: np.ndarray
    mode_forward: float
    mode_backward: float
    field: np.ndarray

    @property
    def total(self) -> float:
        return float(self.forward.sum() + self.backward.sum())


def bloch_split(medium, system, q, v, mode: LongWaveMode, direction=(1.0, 0.0)) -> BranchSplit:
    """Split the state (q, v) (3N,) of ``system``, a generated sheet (even ``n_rows`` and ``n_cols``)
    of the uniform ``medium`` (``region_medium``, same scales), into the Bloch waves of its 2 × 2
    cell (docs/physics.md §1.9, "Long waves of a pre-rotated network"). The sheet is read as one
    period of a torus of n_rows/2 × n_cols/2 cells (exact for a state that vanishes near its edges):
    Q(k) = Σ_cells q e^{−ik·R} (R each unit's rest centre) at the wave vectors that fit it; with the
    mass-normalised modes x_b(k), a_b = x_bᴴ M Q, ȧ_b = x_bᴴ M V, the part (a_b + iȧ_b/ω_b)/2 of
    e^{i(k·R − ω_b t)} runs with the group velocity ∇ω_b (sign along e from the Hellmann–Feynman
    derivative xᴴ ∂D x / 2ω), the part (a_b − iȧ_b/ω_b)/2 against it; each carries ω_b²|·|²/C of the
    energy (C the number of cells; the energies sum to the state's). The branch of ``mode``
    (``long_wave_mode`` along e) is, at each k, the band with the largest overlap |x_bᴴ M t| with
    t = shape + i (k·e) gradient."""
    cell_system = build(cell_lattice(medium))
    cell = network_cell(cell_system)
    n = system.n_sites
    nr = system.grid_shape[0] if system.grid_shape else 1
    nc = n // nr
    if nr % 2 or nc % 2 or cell.size != 12 or system.periodic is None and nr > 2:
        raise NotPeriodic("bloch_split reads a generated sheet of even n_rows and n_cols on its 2 × 2 cell")
    e = np.asarray(direction, float) / math.hypot(*direction)
    row, col = np.divmod(np.arange(n), nc)
    unit = 2 * (row % 2) + col % 2
    centres = system.unit_shapes().centres
    recip = 2 * np.pi * np.linalg.inv(cell_system.periodic.vectors).T
    size = (nc // 2, nr // 2)
    mass = cell_system.mass
    forward, backward, along = np.zeros(12), np.zeros(12), np.zeros(2)
    field = np.zeros(3 * n)
    state = [np.asarray(s, float).reshape(3, n) for s in (q, v)]
    for m1, m2 in itertools.product(range(size[0]), range(size[1])):
        k = (m1 / size[0] - (2 * m1 >= size[0])) * recip[0] + (m2 / size[1] - (2 * m2 >= size[1])) * recip[1]
        phase = np.exp(-1j * centres @ k)
        qk, vk = (np.stack([np.bincount(unit, (s[f] * phase).real, 4) + 1j * np.bincount(unit, (s[f] * phase).imag, 4)
                            for f in range(3)]).ravel() for s in state)
        lam, x = bloch_eigen(cell, k, vectors=True)
        h = 1e-6
        slope = (bloch_matrices(cell, k + h * e) - bloch_matrices(cell, k - h * e)) / (2 * h)
        om = np.sqrt(np.clip(lam, 0.0, None))
        moving = om > 1e-6 * float(om.max())  # not a translation (ω² of round-off at k = 0)
        w = np.where(moving, om, 1.0)
        vg = np.where(moving, np.einsum("ib,ij,jb->b", x.conj(), slope, x).real / (2 * w), 0.0)
        a, ad = x.conj().T @ (mass * qk), x.conj().T @ (mass * vk)
        ahead, behind = 0.5 * (a + 1j * ad / w), 0.5 * (a - 1j * ad / w)
        ea, eb = np.where(moving, om**2 * np.abs(ahead) ** 2, 0.0), np.where(moving, om**2 * np.abs(behind) ** 2, 0.0)
        on = vg >= 0
        forward += np.where(on, ea, eb)
        backward += np.where(on, eb, ea)
        parts = np.where(moving, 0.0, a)  # the translation at k = 0
        template = (mode.shape + 1j * float(k @ e) * mode.gradient).ravel()
        b = int(np.argmax(np.abs(x.conj().T @ (mass * template))))
        if moving[b]:
            along += (ea[b], eb[b]) if on[b] else (eb[b], ea[b])
            parts[b] = ahead[b] if on[b] else behind[b]
        field += ((x @ parts).reshape(3, 4)[:, unit] / phase).real.ravel()
    cells = size[0] * size[1]
    return BranchSplit(forward / cells, backward / cells, float(along[0] / cells), float(along[1] / cells),
                       field / cells)
