"""ω–k power spectra of a run's saved field, with the model's linear bands (``flexmm analyze --spectrum``).

A field f(t, x) sampled on uniform frames and sites (a chain, or the (row, col) grid of a sheet) is
Fourier transformed over time and space,

    P(ω, k) = |Σ_t Σ_n w(t) (f(t, n) − f̄(n)) e^{iωt − ikn}|²,

with f̄ the time mean of each site and w a Hann window in time (it keeps the leakage of a line to a
few bins). A plane wave e^{i(kn − ωt)} with ω > 0 lands at (ω, k): a wave moving right at k > 0.
ω is in rad/s on the bins 2πj/(N_t Δt), k in rad per site on 2πj/N_x (fftshifted to [−π, π)).
Only ω ≥ 0 is kept: a real field's spectrum is symmetric under (ω, k) → (−ω, −k).

The linear bands of a 1D model come from its Bloch eigenproblem (``flexmm.linear.dispersion``,
built on a short copy of the lattice), unfolded to k per site when the cell holds several sites; a
sheet's, for the kinds in ``SHEET_BANDS``, from its cell's Bloch matrix at (k_x, 0) and (0, k_y) —
the two cuts the figure draws.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from flexmm.errors import FlexmmError

@dataclass
class Spectrum:
    """power (n_ω, n_k) for a chain or (n_ω, n_ky, n_kx) for a sheet; omega (n_ω,) rad/s; k: one
    (n,) array per space axis, rad per site; bands: ω (rad/s) of each branch on ``band_k`` (a chain);
    cut_bands: a sheet's, along k_x (k_y = 0) and along k_y (k_x = 0), each (n_band_k, n_b)."""

    field: str
    omega: np.ndarray
    k: list[np.ndarray]
    power: np.ndarray
    band_k: np.ndarray | None = None
    bands: np.ndarray | None = None
    note: str = ""
    extra: dict = field(default_factory=dict)
    cut_bands: list[np.ndarray] | None = None

    def cuts(self) -> list[tuple[np.ndarray, np.ndarray, np.ndarray | None, str]]:
        """(k, power (n_ω, n_k), bands on ``band_k`` or None, axis label) of each ω–k plane drawn:
        a chain's one; a sheet's k_x cut at k_y = 0 and k_y cut at k_x = 0."""
        if self.power.ndim == 2:
            return [(self.k[0], self.power, self.bands, "k (rad/site)")]
        ky, kx = self.k
        bands = self.cut_bands or [None, None]
        return [(kx, self.power[:, np.argmin(np.abs(ky)), :], bands[0], "k_x (rad/site), k_y = 0"),
                (ky, self.power[:, :, np.argmin(np.abs(kx))], bands[1], "k_y (rad/site), k_x = 0")]

    @property
    def d_omega(self) -> float:
        return float(self.omega[1] - self.omega[0]) if self.omega.size > 1 else float("nan")

    def peak_omega(self) -> np.ndarray:
        """The ω (rad/s) of the largest power at each k of a chain, (n_k,)."""
        return self.omega[np.argmax(self.power, axis=0)]

    def band_power_fraction(self, bins: float = 2.0) -> float:
        """Fraction of the power (k ≠ 0) within ``bins`` frequency bins of a linear band, over the
        ω–k planes that have bands (``cuts``)."""
        inside = total = 0.0
        for k, power, bands, _ in self.cuts():
            if bands is None:
                continue
            near = np.zeros(power.shape, bool)
            for b in range(bands.shape[1]):
                w = np.interp(np.abs(k), self.band_k, bands[:, b])
                near |= np.abs(self.omega[:, None] - w[None, :]) <= bins * self.d_omega
            keep = np.broadcast_to(k != 0, power.shape)
            inside, total = inside + float(power[near & keep].sum()), total + float(power[keep].sum())
        return inside / total if total > 0 else float("nan")


def power_spectrum(values: np.ndarray, dt: float) -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
    """(omega (n_ω,), [k per space axis], power) of ``values`` (n_t, n_x) or (n_t, n_y, n_x) sampled
    every ``dt`` s (see the module docstring)."""
    v = np.asarray(values, float)
    n_t = v.shape[0]
    if n_t < 4:
        raise ValueError(f"an ω–k spectrum needs at least 4 frames (got {n_t})")
    v = (v - v.mean(axis=0)) * np.hanning(n_t).reshape((-1,) + (1,) * (v.ndim - 1))
    axes = tuple(range(1, v.ndim))
    f = np.fft.ifft(np.fft.fftn(v, axes=axes), axis=0) * n_t  # e^{+iωt}: ω > 0 with k > 0 moves right
    n_w = n_t // 2 + 1
    power = np.fft.fftshift(np.abs(f[:n_w]) ** 2, axes=axes)
    omega = 2 * math.pi * np.arange(n_w) / (n_t * dt)
    ks = [np.fft.fftshift(2 * math.pi * np.fft.fftfreq(v.shape[a])) for a in axes]
    return omega, ks, power


def chain_bands(system, k: np.ndarray) -> tuple[np.ndarray, str]:
    """ω (rad/s) of each linear branch of a built 1D ``system`` at |k| (rad per site), (n_k, n_b),
    and how they were found. The cell is 1 site, else 2: its phase per cell is then 2k, and its
    branches are every mode of wavenumber k modulo π. ValueError if neither fits."""
    from flexmm.linalg import bloch_frequencies
    from flexmm.linear.dispersion import chain_cell

    err = None
    for c in (1, 2):
        try:
            cell = chain_cell(system, cell_sites=c)
        except ValueError as exc:
            err = exc
            continue
        w = bloch_frequencies(cell, c * np.abs(np.asarray(k, float))) / system.scales.time_s
        return w, f"linear bands of the model's Bloch cell ({c} site{'s' if c > 1 else ''})"
    raise ValueError(f"no periodic cell of 1 or 2 sites: {err}")


def run_spectrum(ctx, spec: str | None = None, row: int | None = None) -> Spectrum:
    """The ω–k spectrum of a run's field ``spec`` (default: the displacement ``u``/``x``, else θ),
    with the model's linear bands for a chain (``note`` says why there are none)."""
    from flexmm.analysis.features.fields import displacement_field, field_view

    ds = ctx.ds
    t = np.asarray(ds["time"].values, float)
    dts = np.diff(t)
    if dts.size < 3 or not np.allclose(dts, dts[0], rtol=1e-6, atol=0):
        raise ValueError("an ω–k spectrum needs at least 4 uniformly spaced frames")
    dt = float(dts[0])
    if spec is None:
        spec = displacement_field(ds) if any(n in ds.data_vars for n in ("u", "x")) else "theta"
    grid = _sheet_grid(ds, spec) if row is None else None
    if grid is not None:
        omega, ks, power = power_spectrum(grid, dt)
        out = Spectrum(spec, omega, ks, power, band_k=np.linspace(0.0, math.pi, 257))
        try:
            out.cut_bands, how = model_sheet_bands(ctx, out.band_k)
            out.note = f"sheet: ω–k_y–k_x spectrum; {how}"
        except (ValueError, KeyError, ArithmeticError, FlexmmError) as exc:  # FlexmmError: no scene recorded
            out.band_k, out.note = None, f"sheet: ω–k_y–k_x spectrum; no linear bands: {exc}"
        return out
    view = field_view(ds, spec, row=row)
    omega, ks, power = power_spectrum(view.values, dt)
    out = Spectrum(view.spec, omega, ks, power)
    try:
        out.band_k = np.linspace(0.0, math.pi, 257)
        out.bands, out.note = model_chain_bands(ctx, out.band_k)
    except (ValueError, KeyError, ArithmeticError) as exc:
        out.band_k, out.bands, out.note = None, None, f"no linear bands: {exc}"
    return out


def _sheet_grid(ds, name: str) -> np.ndarray | None:
    """The field ``name`` of a sheet as (n_t, n_rows, n_cols), when its sites fill a whole
    rectangle of (row, col) once each; None for a chain, a derived field or a masked sheet."""
    if name not in ds.data_vars:
        return None
    var = ds[name]
    if var.dims == ("time", "row", "col"):
        return np.asarray(var.values, float)
    if var.dims != ("time", "site") or "row" not in ds.coords or "col" not in ds.coords:
        return None
    rows, cols = (np.asarray(ds[c].values, np.int64) for c in ("row", "col"))
    rows, cols = rows - rows.min(), cols - cols.min()
    shape = (int(rows.max()) + 1, int(cols.max()) + 1)
    if shape[0] < 2 or rows.size != shape[0] * shape[1] or np.unique(rows * shape[1] + cols).size != rows.size:
        return None
    out = np.empty((var.shape[0],) + shape)
    out[:, rows, cols] = np.asarray(var.values, float)
    return out


def model_chain_bands(ctx, k: np.ndarray) -> tuple[np.ndarray, str]:
    """``chain_bands`` of the run's model, built on a 32-unit copy of its lattice."""
    from flexmm.models import MODELS

    lat = ctx.scene().lattice
    if "n_units" not in type(lat).model_fields:
        raise ValueError(f"{ctx.model} is not a chain with n_units")
    system = MODELS[lat.kind].build(lat.model_copy(update={"n_units": 32}))
    return chain_bands(system, k)


def _squares_sheet_bands(lat, k_site):
    from flexmm.linear.sheet import site_bands

    return site_bands(lat, k_site)


#: lattice kinds whose sheet bands are drawn: kind -> f(lattice config, k (…, 2) rad per site) -> ω (…, n_b) rad/s
SHEET_BANDS = {"rotating_squares_sheet": _squares_sheet_bands}


def model_sheet_bands(ctx, k: np.ndarray) -> tuple[list[np.ndarray], str]:
    """A sheet's bands (``SHEET_BANDS``) at |k| along k_x (k_y = 0) and along k_y (k_x = 0)."""
    lat = ctx.scene().lattice
    bands = SHEET_BANDS.get(lat.kind)
    if bands is None:
        raise ValueError(f"no Bloch cell registered for a {lat.kind} (bands of: {', '.join(SHEET_BANDS)})")
    zero = np.zeros_like(k)
    cuts = [bands(lat, np.stack(pair, axis=-1)) for pair in ((k, zero), (zero, k))]
    return cuts, "linear bands of the sheet's two-unit Bloch cell along k_x and k_y"
