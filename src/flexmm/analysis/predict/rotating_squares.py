"""Predictions for the rotating-squares chain (docs/physics.md §1.3, §1.4) from a run's config.

Nondimensional theory (flexmm.theory.rotating) is converted with the model's own scales:
lengths in units of a (X = x/a), speeds in c0 = a sqrt(k_l/m), frequencies in sqrt(k_l/m).
θ pulses: exact speed law c(A) at the measured amplitude, W of §1.3 at that speed (compared with
the sech fit for θ0 = 0, with the §1.3-profile fit otherwise), FWHM and temporal FWHM of the
exact (non-truncated) soliton. Below the amplitude gap, and for longitudinal pulses without a
rotational soliton, the linear long-wave speed. Strain pulses riding on a θ soliton (a vector
soliton): the soliton speed and the strain peak U' = η G(A)/(c² − η²). A predeformed chain is
compared with the prestressed theory about its rest rotation (flexmm.theory.prestressed), its
fields having been measured from the rest state (analysis.features.rest).
"""

from __future__ import annotations

import math

import numpy as np

from flexmm.analysis.context import Comparison, ModelTheory
from flexmm.theory import rotating as rt


def params(ctx) -> tuple[rt.RotatingChainND, float, float]:
    """(nondimensional parameters, length unit a [m], time unit sqrt(m/k_l) [s]) of the run.

    A chain gives its own n_v, s_v. A sheet periodic across the rows carries planar waves, which
    are the chain with n_v = 2, s_v = 1 (docs/physics.md §1.2), when the excitation is planar
    (``planar_issue``); other sheets and localised drives: ValueError.
    """
    if "rot" not in ctx.cache:
        lat = ctx.scene().lattice
        if lat.kind == "rotating_squares_chain":
            m, J, n_v, s_v = lat.mass_kg, lat.inertia_kg_m2, lat.n_lateral, int(lat.lateral_stretch)
        elif lat.kind == "rotating_squares_sheet":
            plain = lat.ligament_length_m == 0 and lat.magnets is None and not lat.variation
            if not (plain and lat.top == lat.bottom == "periodic"):
                raise ValueError("chain theory applies to planar waves of a plain, row-periodic sheet only")
            issue = ctx.scene().excitation.planar_issue()
            if issue is not None:  # a localised push: its wave is not the planar wave the chain theory is
                raise ValueError(f"chain theory applies to planar waves only: {issue}")
            m, J, n_v, s_v = lat.unit_mass_kg, lat.unit_inertia_kg_m2, 2, 1
        else:
            raise ValueError(f"no rotating-squares theory for {lat.kind}")
        p = rt.RotatingChainND.from_si(lat.a_m, lat.theta0_rad, lat.k_long_n_per_m, lat.k_shear_n_per_m,
                                       lat.k_rot_n_m_per_rad, m, J, n_v, s_v)
        if getattr(lat, "predeform", None) is not None:
            p = _prestressed(ctx, p)
        ctx.cache["rot"] = (p, lat.a_m, math.sqrt(m / lat.k_long_n_per_m))
    return ctx.cache["rot"]


def _prestressed(ctx, p: rt.RotatingChainND) -> rt.RotatingChainND:
    """The predeformed chain about its rest rotation θ_s in the middle (flexmm.theory.prestressed)."""
    from flexmm.analysis.features.rest import rest_fields
    from flexmm.config.lattice import MODELS
    from flexmm.theory.prestressed import prestressed_chain

    if not MODELS[ctx.scene().lattice.kind].soliton_on_predeformed:  # the kinds that know the prestressed theory
        raise ValueError("the prestressed theory is for the chain only")
    theta = rest_fields(ctx)["theta"]
    return prestressed_chain(p, float(theta[theta.size // 2]))


def _row(quantity, measured, predicted, units, note=""):
    return Comparison("", quantity, float(measured), float(predicted), units, note)


def _fwhm_exact(p, A: float) -> float:
    """FWHM (X units) of the exact soliton of amplitude A (numerically, on a fine grid)."""
    W = rt.soliton_width(p, float(rt.soliton_speed(p, A)))
    z = np.linspace(0.0, 12 * W, 6001)
    th = np.abs(rt.exact_soliton(p, A, z)[0])
    return 2 * float(np.interp(0.5 * abs(A), th[::-1], z[::-1]))


def soliton_rows(ctx, A: float, p_meas) -> list:
    """Speed, width and FWHM rows for a θ soliton of amplitude A."""
    p, a, T = params(ctx)
    c = float(rt.soliton_speed(p, A))
    W = rt.soliton_width(p, c, "full" if p.theta_s else "constant")  # constant D(c) fails prestressed
    fw = _fwhm_exact(p, A)
    width_q = "width W (sech fit)" if p.theta0 == 0 else "width W (§1.3 fit)"
    width_m = p_meas.width_sech_m if p.theta0 == 0 else p_meas.width_kg_m
    return [
        _row("speed", p_meas.speed_m_s, c * a / T, "m/s", f"exact law c(A) at A = {A:.4g} rad"),
        _row(width_q, width_m, W * a, "m", f"§1.3 W at c(A); Δ = {(width_m - W * a) / (a * p.eta):+.2f} sites"),
        _row("FWHM", p_meas.fwhm_m, fw * a, "m", "exact soliton profile"),
        _row("temporal FWHM", p_meas.temporal_fwhm_s, fw * T / c, "s", "exact profile / c(A)"),
    ]


def _linear_rows(ctx, p_meas, why: str) -> list:
    p, a, T = params(ctx)
    return [_row("speed", p_meas.speed_m_s, rt.long_wave_speed(p) * a / T, "m/s", why)]


def _theta_partner(ctx, p_meas):
    """The θ pulse travelling with a longitudinal pulse (same place mid-way), or None."""
    from flexmm.analysis.features.fields import field_view
    from flexmm.analysis.measure.pulses import PulseNotFound, measure_pulses

    if ctx.ds is None or "theta" not in ctx.ds:
        return None
    if "theta_pulses" not in ctx.cache:
        try:
            ctx.cache["theta_pulses"] = measure_pulses(field_view(ctx.ds, "theta"))
        except PulseNotFound:
            ctx.cache["theta_pulses"] = []
    t0, x0 = p_meas.profile_time_s, float(np.interp(p_meas.profile_time_s, p_meas.track_time_s, p_meas.track_pos_m))
    best = None
    for q in ctx.cache["theta_pulses"]:
        if q.track_time_s[0] <= t0 <= q.track_time_s[-1]:
            d = abs(float(np.interp(t0, q.track_time_s, q.track_pos_m)) - x0)
            if d < 3 * max(q.fwhm_m, p_meas.fwhm_m) and (best is None or d < best[0]):
                best = (d, q)
    return best[1] if best else None


def pulse(ctx, p_meas) -> list:
    """Comparison rows for a pulse of any field of the rotating chain."""
    p, a, T = params(ctx)
    if p_meas.units == "rad":
        A = p_meas.amplitude
        if rt.soliton_exists(p, A):
            return soliton_rows(ctx, A, p_meas)
        if p.theta_s:
            return _linear_rows(ctx, p_meas, "linear long-wave speed (no prestressed soliton of this amplitude)")
        gap = rt.amplitude_gap(p, int(np.sign(A)) or 1)
        return _linear_rows(ctx, p_meas, f"linear long-wave speed (|A| below soliton range, gap {gap:.3g} rad)")
    partner = _theta_partner(ctx, p_meas)
    if partner is not None and rt.soliton_exists(p, partner.amplitude):
        A = partner.amplitude
        c = float(rt.soliton_speed(p, A))
        rows = [_row("speed", p_meas.speed_m_s, c * a / T, "m/s", f"vector soliton, θ amplitude {A:.4g} rad")]
        if p_meas.units == "1":
            strain = p.eta * float(rt.hinge_stretch(p, A)) / (c * c - p.eta**2)
            rows.append(_row("amplitude", p_meas.amplitude, strain, "1", "strain peak ηG(A)/(c² − η²)"))
        return rows
    return _linear_rows(ctx, p_meas, "linear long-wave speed η c0")


def speed_curve(ctx, field_units: str, amplitudes) -> np.ndarray:
    """Exact-law soliton speed (m/s) at each θ amplitude; NaN where no soliton exists."""
    p, a, T = params(ctx)
    A = np.asarray(amplitudes, float)
    if field_units != "rad":
        return np.full(A.shape, np.nan)
    ok = np.array([rt.soliton_exists(p, x) if x != 0 else False for x in A.ravel()]).reshape(A.shape)
    return np.where(ok, rt.soliton_speed(p, A) * a / T, np.nan)


def profile(ctx, p_meas, x_m) -> np.ndarray:
    """Exact soliton θ(x) at the measured amplitude, centred on the fitted centre of the profile."""
    p, a, T = params(ctx)
    if p_meas.units != "rad" or not rt.soliton_exists(p, p_meas.amplitude):
        raise ValueError("no soliton profile for this pulse")
    fit = p_meas.profile_fits.get("sech")
    x_c = fit.center if fit is not None and fit.ok else float(
        p_meas.profile_x_m[np.argmax(np.abs(p_meas.profile_values))])
    return rt.exact_soliton(p, p_meas.amplitude, (np.asarray(x_m) - x_c) / a)[0]


def bands_hz(ctx) -> list[tuple[float, float]]:
    """Linear pass bands (Hz): lower branch [0, lower_max], upper [upper_min, upper_max] (§1.4)."""
    p, a, T = params(ctx)
    e = rt.band_edges(p)
    f = 1.0 / (2 * math.pi * T)
    return [(0.0, e.lower_max * f), (e.upper_min * f, e.upper_max * f)]


def amplitude_gap_lines(ctx) -> dict[str, float]:
    """The amplitude gap A_min of each polarity (docs/physics.md §1.3; NaN where there is none),
    as the ``theory_amplitude_gap_*_rad`` values sweeps store and draw."""
    p, _, _ = params(ctx)
    out = {}
    for sign, name in ((+1, "positive"), (-1, "negative")):
        try:
            out[f"theory_amplitude_gap_{name}_rad"] = rt.amplitude_gap(p, sign)
        except ValueError:
            out[f"theory_amplitude_gap_{name}_rad"] = math.nan
    return out


#: the ``theory`` hooks of the rotating-squares chain and sheet (``flexmm.config.lattice.MODELS``)
CHAIN = ModelTheory(pulse=pulse, speed_curve=speed_curve, profile=profile, bands_hz=bands_hz,
                    reference_lines=amplitude_gap_lines)
SHEET = ModelTheory(pulse=pulse, speed_curve=speed_curve, profile=profile)
