"""Predictions for chains of masses (docs/physics.md §2), registered for ``mass_chain`` in ``compare``.

The relation functions take a measurement plus SI parameters and return Comparison rows; the
``pulse``/``front``/``analysis`` entry points read the parameters from the run's MassChain config
and apply a relation only where its assumptions hold: a uniform chain (no variation), no
on-site terms for solitary waves, zero law offsets, one bistable cubic on-site term with linear
coupling and a viscous damping coefficient for fronts. Strains in the dataset are bond
elongations per spacing, so the bond elongation is D = strain · a.
"""

from __future__ import annotations

import math

import numpy as np

from flexmm.analysis.context import Comparison, ModelTheory
from flexmm.models import launch_chains
from flexmm.theory import chains as th


def softening_pulse(p_meas, k1: float, k2: float, m: float, a: float) -> list[Comparison]:
    """sech² solitary wave of T(D) = k1 D + k2 D²: speed and W at the measured strain peak."""
    wave = th.softening_solitary_wave(k1, k2, p_meas.amplitude * a, m, a)
    return [
        Comparison("", "speed", p_meas.speed_m_s, wave.v, "m/s", "v = c0 sqrt(1 + 2k2Dm/(3k1))"),
        Comparison("", "width W (sech² fit)", p_meas.width_sech2_m, wave.W * a, "m", "W = sqrt(k1/(2k2Dm)) sites"),
    ]


def fpu_beta_pulse(p_meas, k1: float, k3: float, m: float, a: float) -> list[Comparison]:
    """sech (mKdV) solitary wave of T(D) = k1 D + k3 D³: speed and W at the measured strain peak."""
    v, W = th.fpu_beta_solitary_wave(k1, k3, p_meas.amplitude * a, m, a)
    return [
        Comparison("", "speed", p_meas.speed_m_s, v, "m/s", "FPU-β (mKdV) v = c0 sqrt(1 + k3Dm²/(2k1))"),
        Comparison("", "width W (sech fit)", p_meas.width_sech_m, W * a, "m", "W = sqrt(k1/(6k3))/|Dm| sites"),
    ]


def hertz_pulse(p_meas, A: float, m: float, D: float) -> list[Comparison]:
    """Nesterenko solitary wave: speed at the measured compressive strain peak ξ_m = −strain."""
    xi = -p_meas.amplitude
    if not xi > 0:
        raise ValueError("a Hertz solitary wave is compressive")
    return [
        Comparison("", "speed", p_meas.speed_m_s, th.nesterenko_speed(A, m, D, xi), "m/s",
                   "V = (2/√5) c ξm^(1/4)"),
        Comparison("", "FWHM", p_meas.fwhm_m, 2 * 5 * D / math.sqrt(10) * math.acos(0.5 ** 0.25), "m",
                   "FWHM of ξm cos⁴(√10 x/(5D))"),
    ]


def hertz_precompressed_pulse(p_meas, A: float, m: float, D: float, xi_0: float) -> list[Comparison]:
    """Nesterenko solitary wave on a chain precompressed to strain ξ0: speed at the measured peak
    ξm = ξ0 − strain (the strain measured from the rest state)."""
    xi = -p_meas.amplitude
    if not xi > 0:
        raise ValueError("a Hertz solitary wave is compressive")
    return [Comparison("", "speed", p_meas.speed_m_s, th.nesterenko_precompressed_speed(A, m, D, xi_0, xi_0 + xi),
                       "m/s", f"precompressed solitary wave, ξ0 = {xi_0:.3g}, ξm/ξ0 = {1 + xi / xi_0:.4g}")]


def rest_overlap(ctx, lat) -> float:
    """Overlap δ0 (m) of a Hertz chain's contacts at rest: ``precompression_m`` less the rest
    elongation (the median over the saved bonds of the dataset's rest state: a static load
    compresses the chain, a free chain lets a precompression go). ValueError when the chain may be
    precompressed and the run's rest state is not at hand."""
    from flexmm.analysis.features.rest import rest_fields

    bond = lat.bond
    rest = rest_fields(ctx) if ctx.ds is not None else None
    if rest is None or rest.get("u") is None or rest["u"].size < 2:
        if bond.precompression_m == 0 and lat.static_load_n == 0:
            return 0.0
        raise ValueError("the precompression of this Hertz chain needs the run's rest state")
    z = float(np.median(np.diff(rest["u"]))) / ctx.scene().output.site_stride
    return max(bond.precompression_m - z, 0.0)


def bistable_front(f_meas, alpha: float, beta: float, L: float, k: float, m: float, a: float,
                   eta: float) -> list[Comparison]:
    """Damped bistable front: speed v and 10–90 % width w ln 9 of (L/2)(1 − tanh(x/w))."""
    fr = th.bistable_front(alpha, beta, L, k, m, a, eta)
    return [
        Comparison("", "speed", f_meas.speed_m_s, fr.v, "m/s", "v = c0/sqrt(1 + 2η²/(mαL²(1−2β)²))"),
        Comparison("", "width 10–90 %", f_meas.width_10_90_m, fr.w * math.log(9.0), "m", "w ln 9"),
    ]


def front_kinetic_energy(ds, f_meas, m: float, dphi: float, eta: float, a: float) -> list[Comparison]:
    """K = m v Δφ/(2 η a) against the median kinetic energy while the front crosses its middle half."""
    t = f_meas.track_time_s
    lo, hi = t[0] + 0.25 * (t[-1] - t[0]), t[0] + 0.75 * (t[-1] - t[0])
    time = np.asarray(ds["time"].values)
    sel = (time >= lo) & (time <= hi)
    K = float(np.median(ds["kinetic_energy"].values[sel]))
    return [Comparison("", "kinetic energy", K, th.front_kinetic_energy(m, f_meas.speed_m_s, dphi, eta, a),
                       "J", "K = m v Δφ/(2 η a) at the measured v")]


def toda_kappa(strain_peak: float, b_per_m: float, spacing: float) -> float:
    """κ of the Toda soliton whose peak bond strain is ``strain_peak`` (< 0): e^(−b r_m) − 1 = sinh²κ."""
    r_m = strain_peak * spacing
    if not r_m < 0:
        raise ValueError("a Toda soliton compresses the bonds (b > 0)")
    return math.asinh(math.sqrt(math.expm1(-b_per_m * r_m)))


def toda_collision(c, b_per_m: float, spacing: float) -> list[Comparison]:
    """Forward shifts of two Toda solitons after a head-on collision, at their measured κ."""
    if c.kind != "head-on":
        raise ValueError("the Toda shift relation here is for head-on collisions")
    ka, kb = toda_kappa(c.amplitude_a, b_per_m, spacing), toda_kappa(c.amplitude_b, b_per_m, spacing)
    da, db = th.toda_head_on_shifts(ka, kb)
    note = f"Toda two-soliton shift −ln A12/(2κ), κ = {ka:.4g}, {kb:.4g}"
    return [Comparison("", f"space shift of pulse {c.pulse_a}", c.shift_a_m, da * spacing, "m", note),
            Comparison("", f"space shift of pulse {c.pulse_b}", c.shift_b_m, db * spacing, "m", note)]


def toda_pulse(p_meas, a_n: float, b_per_m: float, m: float, spacing: float) -> list[Comparison]:
    """Toda soliton speed at the measured bond stretch peak r_m = strain · a (< 0, compressive).

    e^(−b r_m) − 1 = sinh²κ gives κ; speed = sqrt(ab/m) sinh κ/κ sites per unit time (§2).
    """
    kappa = toda_kappa(p_meas.amplitude, b_per_m, spacing)
    return [Comparison("", "speed", p_meas.speed_m_s, th.toda_speed(a_n, b_per_m, m, kappa) * spacing, "m/s",
                       f"Toda soliton, κ = {kappa:.4g}")]


# ---------------------------------------------------------------- mass_chain entry points
MULTISTABLE = ("bistable_cubic", "phi4", "raney2016", "sine")


def _chain(ctx):
    lat = ctx.scene().lattice  # a mass_chain: the kind whose theory hook this is
    if lat.variation or lat.bond2 is not None:
        raise ValueError("relations of docs/physics.md §2 need a uniform nearest-neighbour chain")
    return lat


def analysis(ctx) -> str:
    """'front' for chains with a multistable on-site term, else 'pulse'."""
    lat = ctx.scene().lattice
    return "front" if any(law.law in MULTISTABLE for law in getattr(lat, "onsite", [])) else "pulse"


def pulse(ctx, p_meas) -> list[Comparison]:
    """Solitary-wave speed (and width) of the chain's bond law at the measured strain peak."""
    lat = _chain(ctx)
    bond, a, m = lat.bond, lat.spacing_m, lat.mass_kg
    if lat.onsite or bond.offset_m != 0 or p_meas.units != "1":
        raise ValueError("no solitary-wave relation for this chain or field")
    if bond.law == "polynomial" and bond.k3_n_per_m3 == 0 and bond.k2_n_per_m2 != 0:
        return softening_pulse(p_meas, bond.k1_n_per_m, bond.k2_n_per_m2, m, a)
    if bond.law == "polynomial" and bond.k2_n_per_m2 == 0 and bond.k3_n_per_m3 > 0:
        return fpu_beta_pulse(p_meas, bond.k1_n_per_m, bond.k3_n_per_m3, m, a)
    if bond.law == "hertz" and bond.exponent == 1.5:
        xi_0 = rest_overlap(ctx, lat) / a
        if xi_0 > 0:  # a precompressed chain: not the sonic vacuum
            return hertz_precompressed_pulse(p_meas, bond.stiffness_n_per_m_p, m, a, xi_0)
        return hertz_pulse(p_meas, bond.stiffness_n_per_m_p, m, a)
    if bond.law == "toda":
        return toda_pulse(p_meas, bond.a_n, bond.b_per_m, m, a)
    if bond.law == "linear":
        return [Comparison("", "speed", p_meas.speed_m_s, a * math.sqrt(bond.k_n_per_m / m), "m/s",
                           "linear long-wave speed c0 = a sqrt(k/m)")]
    raise ValueError(f"no solitary-wave relation for a {bond.law} bond")


def collision(ctx, c) -> list[Comparison]:
    """Collision shifts where the chain's bond law has a relation (Toda, head-on)."""
    lat = _chain(ctx)
    if lat.onsite or lat.bond.law != "toda" or lat.bond.offset_m != 0:
        raise ValueError("no collision relation for this chain")
    return toda_collision(c, lat.bond.b_per_m, lat.spacing_m)


def _viscous_eta(ctx, lat) -> float:
    vis = ctx.scene().damping.viscous
    if vis is None or vis.coefficient_n_s_per_m is None:
        raise ValueError("the front relation needs damping.viscous.coefficient_n_s_per_m")
    return vis.coefficient_n_s_per_m


def kink_front(ctx, lat, f_meas) -> list[Comparison]:
    """Kink of a sine or phi4 substrate driven by a constant force against viscous damping: its
    terminal speed (energy balance; McLaughlin–Scott for sine-Gordon, docs/physics.md §2)."""
    kink, _, force = launch_chains.chain_kink(lat)
    if force == 0:
        raise ValueError("an undriven kink has no terminal speed")
    v = th.driven_kink_speed(kink, force, _viscous_eta(ctx, lat))
    name = "McLaughlin–Scott" if kink.law == "sine" else "φ⁴ energy balance"
    return [Comparison("", "speed", abs(f_meas.speed_m_s), v, "m/s",
                       f"driven damped kink ({name}): v = Q/sqrt(1 + (Q/c)²), Q = F Δu/(η M)"),
            Comparison("", "width 10–90 %", f_meas.width_10_90_m, kink.width_10_90(v), "m",
                       "the kink's profile, Lorentz-contracted at that speed")]


def front(ctx, f_meas) -> list[Comparison]:
    """Damped bistable front (one bistable_cubic on-site term, linear coupling): v, width, K; a
    driven sine or phi4 kink: its terminal speed (``kink_front``)."""
    lat = _chain(ctx)
    if any(law.law in ("sine", "phi4") for law in lat.onsite):
        return kink_front(ctx, lat, f_meas)
    (law,) = lat.onsite
    if law.law != "bistable_cubic" or law.offset_m != 0 or lat.bond.law != "linear" or lat.bond.offset_m != 0:
        raise ValueError("no front relation for this chain")
    eta = _viscous_eta(ctx, lat)
    args = (law.alpha_n_per_m3, law.beta, law.jump_m, lat.bond.k_n_per_m, lat.mass_kg, lat.spacing_m, eta)
    rows = bistable_front(f_meas, *args)
    if ctx.ds is not None and "kinetic_energy" in ctx.ds:
        dphi = law.alpha_n_per_m3 * law.jump_m**4 * (1 - 2 * law.beta) / 12
        rows += front_kinetic_energy(ctx.ds, f_meas, lat.mass_kg, dphi, eta, lat.spacing_m)
    return rows


def _linear_stiffness(law) -> float:
    """The stiffness (N/m) of a law's linear part at zero elongation; ValueError if not linear there."""
    if law.law == "linear":
        return law.k_n_per_m
    if law.law == "polynomial" and law.k1_n_per_m > 0:
        return law.k1_n_per_m
    raise ValueError(f"no linear theory for a {law.law} law")


def driven(ctx, d) -> list[Comparison]:
    """The linear evanescent decay per site of a drive outside the pass band of an undamped uniform
    chain (one linear or polynomial bond, at most one linear on-site spring; ``th.evanescent_decay``)."""
    lat = _chain(ctx)
    if ctx.scene().damping.viscous is not None or len(lat.onsite) > 1:
        raise ValueError("the evanescent law is the undamped chain's with at most one on-site spring")
    k_on = _linear_stiffness(lat.onsite[0]) if lat.onsite else 0.0
    kappa, _ = th.evanescent_decay(_linear_stiffness(lat.bond), lat.mass_kg, 2 * math.pi * d.frequency_hz, k_on)
    return [Comparison("", "decay per site", d.decay_per_site, kappa, "1/site",
                       "linear chain outside its pass band: evanescent decay (docs/physics.md §2)")]


#: the ``theory`` hook of the chain of masses (``flexmm.config.lattice.MODELS``)
MASS_CHAIN = ModelTheory(pulse=pulse, front=front, analysis=analysis, collision=collision, driven=driven)
