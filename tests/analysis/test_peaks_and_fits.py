"""The analysis's own peak finding and profile fits against scipy's (the reference they replace:
importing scipy.signal, and curve_fit's finite-difference Jacobians, cost more than the analysis).

scipy is the independent oracle here: the same definitions, computed by other code.
"""

from __future__ import annotations

import subprocess
import sys
import warnings

import numpy as np
import pytest
from scipy.optimize import curve_fit
from scipy.signal import find_peaks, peak_widths, savgol_filter

from flexmm.analysis.features import peaks
from flexmm.analysis.features.profiles import SHAPES, fit_profile, fit_profiles, shape_jacobian


def _signals(n_cases: int = 400, seed: int = 5):
    """Random signals, half of them small integers (flat tops, ties, plateaus at the ends)."""
    rng = np.random.default_rng(seed)
    for k in range(n_cases):
        n = int(rng.integers(3, 50))
        yield rng.integers(0, 5, n).astype(float) if k % 2 else rng.standard_normal(n)


def test_local_maxima_and_filtered_peaks_match_scipy():
    rng = np.random.default_rng(1)
    for x in _signals():
        assert np.array_equal(peaks.local_maxima(x), find_peaks(x)[0]), x
        level = float(rng.uniform(0.0, 3.0))
        want = find_peaks(x, height=level, prominence=0.5 * level)[0]
        assert np.array_equal(peaks.find_peaks(x, height=level, prominence_min=0.5 * level), want), (x, level)


def test_local_maxima_of_every_row_at_once():
    """Rows with and without flat tops (the row's own search), as scipy finds them row by row."""
    rng = np.random.default_rng(2)
    for k in range(60):
        v = rng.integers(0, 4, (6, int(rng.integers(3, 40)))).astype(float) if k % 2 else rng.standard_normal((6, 25))
        v[0] = rng.standard_normal(v.shape[1])
        got = peaks.local_maxima_rows(v)
        assert len(got) == v.shape[0]
        for row, idx in zip(v, got):
            assert np.array_equal(idx, find_peaks(row)[0]), row


def test_peak_widths_match_scipy_at_every_index():
    """Width and both crossings, bit for bit, at every sample (peaks, slopes, plateaus, ends)."""
    for x in _signals():
        for k in range(x.size):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # scipy warns on zero widths and prominences
                w, _, left, right = peak_widths(x, [k], rel_height=0.5)
            assert peaks.peak_width(x, k) == (w[0], left[0], right[0]), (x, k)


def test_cubic_smoothing_matches_savgol():
    for x in _signals():
        if x.size >= 7:
            assert np.allclose(peaks.smooth_cubic7(x), savgol_filter(x, 7, 3), rtol=0, atol=1e-12)
    with pytest.raises(ValueError):
        peaks.smooth_cubic7(np.ones(6))


@pytest.mark.parametrize("shape", sorted(SHAPES))
def test_shape_jacobian_matches_central_differences(shape):
    x = np.linspace(-30.0, 30.0, 121)  # far tails too: sech written without cosh
    p = np.array([0.7, 0.3, 1.4] + ([0.3] if shape == "kg" else []))
    f, J = shape_jacobian(shape, x, p)
    assert np.allclose(f, SHAPES[shape](x, *p), rtol=1e-14, atol=0)
    h = 1e-6
    numeric = np.stack([(SHAPES[shape](x, *(p + d)) - SHAPES[shape](x, *(p - d))) / (2 * h)
                        for d in np.eye(p.size) * h], axis=1)
    assert np.allclose(J, numeric, rtol=1e-6, atol=1e-9)


@pytest.mark.parametrize("shape", sorted(SHAPES))
def test_fits_agree_with_a_tightly_converged_curve_fit(shape):
    """Noisy profiles from rough guesses: W, centre, amplitude (and b) within 1e-6 of curve_fit's
    bounded solution converged to 1e-15, W's standard error within 1e-4."""
    rng = np.random.default_rng({"sech": 1, "sech2": 2, "kg": 3}[shape])
    for _ in range(30):
        n = int(rng.integers(12, 60))
        x = np.sort(rng.uniform(-6.0, 6.0, n))
        true = [rng.uniform(0.2, 2.0) * rng.choice([-1, 1]), rng.uniform(-1, 1), rng.uniform(0.8, 3.0)]
        true += [rng.uniform(-1.0, 0.6)] if shape == "kg" else []
        y = SHAPES[shape](x, *true) + 0.02 * rng.standard_normal(n)
        guess = (true[0] * rng.uniform(0.8, 1.2), true[1] + rng.uniform(-0.3, 0.3), true[2] * rng.uniform(0.7, 1.4))
        ours = fit_profile(x, y, shape, guess)
        p0 = list(guess) + ([0.0] if shape == "kg" else [])
        lo = [-np.inf, x.min(), 1e-3 * guess[2]] + ([-20.0] if shape == "kg" else [])
        hi = [np.inf, x.max(), 1e3 * guess[2]] + ([0.95] if shape == "kg" else [])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ref, cov = curve_fit(SHAPES[shape], x, y, p0=p0, bounds=(lo, hi), maxfev=40000,
                                 ftol=1e-15, xtol=1e-15, gtol=1e-15)
        assert ours.ok
        assert ours.W == pytest.approx(abs(ref[2]), rel=1e-6)
        assert ours.center == pytest.approx(ref[1], abs=1e-6 * abs(ref[2]))
        assert ours.amplitude == pytest.approx(ref[0], rel=1e-6)
        if shape == "kg":
            assert ours.b == pytest.approx(ref[3], abs=1e-5)
        assert ours.W_stderr == pytest.approx(np.sqrt(cov[2, 2]), rel=1e-4)


@pytest.mark.parametrize("shape", sorted(SHAPES))
def test_profiles_fitted_together_are_those_fitted_alone(shape):
    """fit_profiles on 12 noisy profiles of different lengths (the shorter padded in the batch),
    one of them empty and one non-finite: each fit as fit_profile gives it alone (the same
    minimum: W, centre, amplitude within 1e-7), the bad ones failed."""
    rng = np.random.default_rng({"sech": 11, "sech2": 12, "kg": 13}[shape])
    xs, ys, guesses = [], [], []
    for _ in range(12):
        n = int(rng.integers(12, 70))
        x = np.sort(rng.uniform(-6.0, 6.0, n))
        true = [rng.uniform(0.2, 2.0) * rng.choice([-1, 1]), rng.uniform(-1, 1), rng.uniform(0.8, 3.0)]
        true += [rng.uniform(-1.0, 0.6)] if shape == "kg" else []
        xs.append(x)
        ys.append(SHAPES[shape](x, *true) + 0.02 * rng.standard_normal(n))
        guesses.append((true[0] * rng.uniform(0.8, 1.2), true[1] + rng.uniform(-0.3, 0.3), true[2] * rng.uniform(0.7, 1.4)))
    xs[3], ys[3] = np.zeros(0), np.zeros(0)
    ys[7] = ys[7].copy()
    ys[7][2] = np.nan
    together = fit_profiles(xs, ys, shape, guesses)
    for j, (x, y, g, f) in enumerate(zip(xs, ys, guesses, together)):
        if j in (3, 7):
            assert not f.ok
            continue
        alone = fit_profile(x, y, shape, g)
        assert f.ok and alone.ok
        assert f.W == pytest.approx(alone.W, rel=1e-7)
        assert f.center == pytest.approx(alone.center, abs=1e-7 * alone.W)
        assert f.amplitude == pytest.approx(alone.amplitude, rel=1e-7)


def test_a_fit_at_its_bound_is_bounded():
    """A profile wider than 1000 × the guess: the width stays at its bound, as curve_fit's does."""
    x = np.linspace(-5.0, 5.0, 41)
    f = fit_profile(x, np.ones_like(x), "sech", (1.0, 0.0, 1e-3))
    assert f.ok and f.W <= 1.0 + 1e-12


def test_the_pulse_analysis_imports_neither_scipy_signal_nor_stats():
    code = ("import sys; import flexmm.analysis.report.analyze, flexmm.analysis.report.summary; "
            "print(sorted(m for m in sys.modules if m.startswith(('scipy.signal', 'scipy.stats', 'scipy.optimize', "
            "'scipy.ndimage'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_line_fit_slope_error_and_degenerate_abscissae():
    """The slope and its standard error against numpy's covariance; points that share one
    abscissa (arrivals in one column of a sheet) have no line: NaN, not an exception."""
    from flexmm.analysis.measure.arrivals import line_fit

    x = np.array([0.0, 1.0, 2.0, 3.0, 4.0])
    y = 2.0 * x + 1.0 + np.array([0.1, -0.1, 0.05, 0.0, -0.05])
    slope, intercept, err = line_fit(x, y)
    coef, cov = np.polyfit(x, y, 1, cov=True)
    assert slope == pytest.approx(coef[0]) and intercept == pytest.approx(coef[1])
    assert err == pytest.approx(np.sqrt(cov[0, 0])) and 0 < err < 0.1
    assert np.isnan(line_fit(np.array([1.0, 2.0]), np.array([0.0, 1.0]))[2])
    assert all(np.isnan(v) for v in line_fit(np.full(4, 2.5), np.array([0.0, 1.0, 2.0, 3.0])))
