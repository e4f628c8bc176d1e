"""Predictions for a generated rigid network (docs/physics.md §1.9) from a run's config: the speed
of a longitudinal pulse along x against the long-wave Bloch speed of the medium it runs in (the
lattice's, or its region's; planar waves: a sheet periodic across its rows, driven along a whole
edge or launched by its initial state), and, across the interface of a network with one region, the
amplitudes of the transmitted and reflected pulses, 2Z₁/(Z₁ + Z₂) and (Z₁ − Z₂)/(Z₁ + Z₂) of the
incident acoustic pulse (Z = ρc of the two media's long-wave modes). The incident pulse is the
forward acoustic part of the run's initial state (``linear.network.bloch_split``): at θ0 ≠ 0 a
launch of the displacement alone also carries optical waves, which the ratios do not apply to.
Networks from a geometry file, random quads and masked sheets get no prediction.
"""

from __future__ import annotations

import numpy as np

from flexmm.analysis.context import Comparison, ModelTheory

_LONGITUDINAL = ("u", "u_dot", "velocity", "velocity:u")


def _media(ctx) -> dict:
    """The run's built network, the long-wave mode of each medium (None: the lattice's, else the
    region's index) and the medium of every unit (cached)."""
    if "network" not in ctx.cache:
        from flexmm.linear.network import long_wave_mode, region_medium
        from flexmm.models.network import build

        scene = ctx.scene()
        lat = scene.lattice
        if lat.geometry is not None or lat.pattern == "random_quads" or lat.mask is not None:
            raise ValueError("no uniform medium: a geometry file, random quads or a mask")
        if lat.n_rows > 1 and lat.bottom != "periodic":
            raise ValueError("the bulk medium's waves are the planar waves of a sheet periodic across its rows")
        if scene.excitation.kind != "none" and scene.excitation.planar_issue() is not None:
            raise ValueError(scene.excitation.planar_issue())
        system = build(lat)
        medium = np.full(system.n_sites, -1)
        for r, spec in enumerate(lat.regions):
            medium[system.site_groups[spec.units]] = r
        modes = {-1: long_wave_mode(region_medium(lat))}
        modes |= {r: long_wave_mode(region_medium(lat, spec)) for r, spec in enumerate(lat.regions)}
        ctx.cache["network"] = {"lat": lat, "system": system, "medium": medium, "modes": modes}
    return ctx.cache["network"]


def _incident(ctx, media) -> tuple[int, float, int] | None:
    """(medium of the launch, the u amplitude of its forward acoustic pulse (m), its direction ±1
    along x) from the run's initial state, or None without one or without a single interface."""
    from flexmm.linear.network import bloch_split, region_medium, uniform_sheet
    from flexmm.models.network import build

    lat, system, medium = media["lat"], media["system"], media["medium"]
    ds = ctx.ds
    if len(lat.regions) != 1 or ds is None or "u_initial" not in ds.coords:
        return None
    n = system.n_sites
    if not np.any(ds["u_initial"].values):  # a driven run: no launch to split
        return None
    peak = int(np.argmax(np.abs(ds["u_initial"].values)))
    near = int(medium[peak])
    x = system.unit_shapes().centres[:, 0]
    direction = 1 if x[medium != near].mean() > x[peak] else -1
    spec = None if near < 0 else lat.regions[near]
    uniform = build(uniform_sheet(lat, spec))  # the launch's medium everywhere
    a, t = uniform.scales.length_m, uniform.scales.time_s
    q = np.concatenate([ds[f"{f}_initial"].values / s for f, s in (("u", a), ("v", a), ("theta", 1.0))])
    v = np.concatenate([ds[f"{f}_dot_initial"].values * t / s for f, s in (("u", a), ("v", a), ("theta", 1.0))])
    mode = media["modes"][near]
    split = bloch_split(region_medium(lat, spec), uniform, q, v, mode, (direction, 0.0))
    u = split.field[:n]
    return near, float(u[np.argmax(np.abs(u))]) * a, direction


def pulse(ctx, p_meas) -> list[Comparison]:
    """The speed row of a longitudinal pulse along x; amplitude rows across a single interface."""
    from flexmm.linear.network import NotPeriodic

    if p_meas.field not in _LONGITUDINAL:
        return []
    try:
        media = _media(ctx)
    except NotPeriodic as exc:  # no uniform periodic medium to compare with
        raise ValueError(str(exc)) from exc
    sites = np.asarray(p_meas.sites, int)
    here = int(np.bincount(media["medium"][sites] + 1).argmax()) - 1
    mode = media["modes"][here]
    where = "the lattice" if here < 0 else f"region {media['lat'].regions[here].units!r}"
    rows = [Comparison("", "speed", float(p_meas.speed_m_s), mode.speed_m_s, "m/s",
                       f"long-wave Bloch speed of {where} (docs/physics.md §1.9)")]
    launch = _incident(ctx, media) if p_meas.field == "u" else None
    if launch is not None:
        near, amplitude, direction = launch
        z1 = media["modes"][near].impedance_kg_per_m_s
        z2 = media["modes"][-1 if near >= 0 else 0].impedance_kg_per_m_s
        if here != near:
            ratio, what = 2 * z1 / (z1 + z2), "transmitted: 2Z₁/(Z₁ + Z₂)"
        elif p_meas.direction != direction:
            ratio, what = (z1 - z2) / (z1 + z2), "reflected: (Z₁ − Z₂)/(Z₁ + Z₂)"
        else:
            ratio, what = 1.0, "incident"
        rows.append(Comparison("", "amplitude", float(p_meas.amplitude), ratio * amplitude, "m",
                               f"{what} of the launch's forward acoustic pulse (docs/physics.md §1.9)"))
    return rows


#: the theory registered for ``rigid_network`` (``config.lattice.MODELS``)
THEORY = ModelTheory(pulse=pulse, pulse_field="u")
