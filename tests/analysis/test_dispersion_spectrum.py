"""ω–k spectra (``flexmm analyze --spectrum``): a small random state of a linear ring puts its power
on the exact dispersion ω = 2 sqrt(k/m) |sin(q/2)|; plane waves land on their own (ω, k)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from typer.testing import CliRunner

from flexmm.analysis.context import RunContext
from flexmm.analysis.measure.dispersion_spectrum import power_spectrum, run_spectrum
from flexmm.analysis.report.analyze import open_dataset
from flexmm.api import run_scene
from flexmm.cli import app
from flexmm.config import scene_from_dict

K, M = 100.0, 0.01


@pytest.fixture(scope="module")
def ring_run(tmp_path_factory):
    """A ring of 64 masses (linear springs) from 1 µm of frozen normal noise, 512 frames 10 ms apart."""
    sc = scene_from_dict({
        "name": "ring", "solver": {"duration_s": 5.11}, "output": {"n_frames": 512},
        "lattice": {"kind": "mass_chain", "n_units": 64, "spacing_m": 0.01, "mass_kg": M,
                    "left": "periodic", "right": "periodic", "bond": {"law": "linear", "k_n_per_m": K}},
        "initial": {"fields": [{"field": "u", "value": "1e-6 * normal(3)"}]}})
    return run_scene(sc, run_dir=tmp_path_factory.mktemp("ring") / "ring").path


def test_random_state_of_a_linear_ring_peaks_on_the_exact_branch(ring_run):
    spec = run_spectrum(RunContext.from_dataset(open_dataset(ring_run)))
    k = spec.k[0]
    exact = 2 * math.sqrt(K / M) * np.abs(np.sin(k / 2))
    moving = k != 0
    assert spec.d_omega == pytest.approx(2 * math.pi / (512 * 0.01))
    assert np.all(np.abs(spec.peak_omega() - exact)[moving] <= spec.d_omega)  # within one frequency bin
    band = np.interp(np.abs(k), spec.band_k, spec.bands[:, 0])  # the model's Bloch band drawn over it
    assert np.max(np.abs(band - exact)) < 1e-6 * exact.max()
    assert spec.band_power_fraction() > 0.99


def test_plane_waves_land_on_their_frequency_and_signed_wavenumber():
    t = np.arange(256) * 0.01
    n = np.arange(32)
    w, q = 2 * math.pi * 12 / (256 * 0.01), 2 * math.pi * 5 / 32
    right = np.cos(q * n[None, :] - w * t[:, None])  # moving to +x
    omega, (k,), p = power_spectrum(right, 0.01)
    i, j = np.unravel_index(np.argmax(p), p.shape)
    assert omega[i] == pytest.approx(w) and k[j] == pytest.approx(q)
    y = np.arange(16)
    sheet = np.cos(q * n[None, None, :] - 2 * math.pi * 3 / 16 * y[None, :, None] - w * t[:, None, None])
    omega, (ky, kx), p = power_spectrum(sheet, 0.01)
    i, a, b = np.unravel_index(np.argmax(p), p.shape)
    assert omega[i] == pytest.approx(w) and kx[b] == pytest.approx(q) and ky[a] == pytest.approx(-2 * math.pi * 3 / 16)


def test_cli_spectrum_prints_and_draws(ring_run):
    r = CliRunner().invoke(app, ["analyze", str(ring_run.parent), "--spectrum"])
    assert r.exit_code == 0, r.output
    out = " ".join(r.output.split())  # the console wraps at its width
    assert "ω–k spectrum of u" in out and "of the power within 2 frequency bins" in out
    assert (ring_run.parent / "spectrum_u.png").stat().st_size > 1000


def test_a_sheet_dataset_gives_an_omega_kx_ky_spectrum():
    """Sites listed by (row, col) coordinates in any order are put back on their grid."""
    import xarray as xr

    t = np.arange(64) * 0.01
    rows, cols = np.divmod(np.arange(8 * 16), 16)
    order = np.random.default_rng(0).permutation(rows.size)
    w, qx, qy = 2 * math.pi * 5 / 0.64, 2 * math.pi * 3 / 16, 2 * math.pi * 2 / 8
    u = np.cos(qx * cols[order][None, :] + qy * rows[order][None, :] - w * t[:, None])
    ds = xr.Dataset({"u": (("time", "site"), u)}, coords={"time": t, "row": ("site", rows[order]),
                                                          "col": ("site", cols[order])})
    spec = run_spectrum(RunContext(model="sheet", config={}, ds=ds))
    i, a, b = np.unravel_index(np.argmax(spec.power), spec.power.shape)
    assert spec.power.shape == (33, 8, 16) and "sheet" in spec.note
    assert spec.omega[i] == pytest.approx(w) and spec.k[1][b] == pytest.approx(qx) and spec.k[0][a] == pytest.approx(qy)


@pytest.fixture(scope="module")
def sheet_run(tmp_path_factory):
    """A fully periodic 16 x 16 rotating-squares sheet from 1 µm of frozen noise in u, v and 1 µrad in θ."""
    sc = scene_from_dict({
        "name": "sheet_noise", "solver": {"duration_s": 0.1023}, "output": {"n_frames": 1024},
        "lattice": {"kind": "rotating_squares_sheet", "n_rows": 16, "n_cols": 16, "a_m": 0.01, "theta0_rad": 0.2,
                    "k_long_n_per_m": 10000, "k_shear_n_per_m": 3300, "k_rot_n_m_per_rad": 0.002,
                    "areal_density_kg_m2": 20.0, "left": "periodic", "right": "periodic",
                    "bottom": "periodic", "top": "periodic"},
        "initial": {"fields": [{"field": "u", "value": "1e-6 * normal(3)"}, {"field": "v", "value": "1e-6 * normal(4)"},
                               {"field": "theta", "value": "1e-6 * normal(5)"}]}})
    return run_scene(sc, run_dir=tmp_path_factory.mktemp("sheet") / "sheet").path


def test_a_sheets_spectrum_lies_on_its_bloch_bands(sheet_run):
    """The sheet's ω–k_x and ω–k_y cuts get the bands of its two-unit Bloch cell, and a small random
    state's power lies on them (at every k of each cut the strongest ω is within two bins of a band)."""
    spec = run_spectrum(RunContext.from_dataset(open_dataset(sheet_run)))
    assert spec.cut_bands is not None and "Bloch cell" in spec.note
    for k, power, bands, _ in spec.cuts():
        assert bands.shape == (spec.band_k.size, 6)
        moving = k != 0
        top = spec.omega[np.argmax(power, axis=0)]
        on_k = np.stack([np.interp(np.abs(k), spec.band_k, bands[:, b]) for b in range(6)], axis=1)  # (n_k, 6)
        near = np.nanmin(np.abs(top[:, None] - on_k), axis=1)
        assert np.all(near[moving] <= 2 * spec.d_omega), near
    assert spec.band_power_fraction() > 0.9


def test_cli_sheet_spectrum_draws_the_bands(sheet_run):
    r = CliRunner().invoke(app, ["analyze", str(sheet_run.parent), "--spectrum", "--field", "theta"])
    assert r.exit_code == 0, r.output
    out = " ".join(r.output.split())
    assert "Bloch cell" in out and "of the power within 2 frequency bins" in out
    assert (sheet_run.parent / "spectrum_theta.png").stat().st_size > 1000
