"""Synthetic run datasets with known answers, laid out like ``flexmm run`` outputs.

Used by the tests (and handy for trying the analysis): travelling pulses of a given shape,
speed, width and amplitude (several at once for trains and collisions; lobes that form and die
out), collisions with known
shifts and outcomes, a transition front
between two wells, and a driven chain with a known steady amplitude per site.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import xarray as xr

from flexmm.analysis.features.profiles import SHAPES


@dataclass(frozen=True)
class SynthPulse:
    """A pulse ``amplitude · shape((x − x0 − v t)/W)``; SI units (m, m/s); optionally forming
    (amplitude growing linearly over ``formation_m`` of travel), breathing, and living only
    between ``starts_s`` and ``ends_s``."""

    amplitude: float
    speed_m_s: float
    width_m: float
    x0_m: float
    shape: str = "sech"
    attenuation_per_m: float = 0.0
    formation_m: float = 0.0  # amplitude rises linearly from ``start_fraction`` over this distance
    start_fraction: float = 0.6
    breathing: float = 0.0  # relative amplitude of a breathing 1 + b sin(2π t / period)
    breathing_period_s: float = 1.0
    starts_s: float = -np.inf  # the pulse fades in around this time and out around ``ends_s``
    ends_s: float = np.inf  # (over ``fade_s``): a lobe that forms and dies out
    fade_s: float = 1.0


def _dataset(time, x, fields: dict, units: dict, attrs: dict | None = None) -> xr.Dataset:
    ds = xr.Dataset(
        {k: (("time", "site"), v, {"units": units.get(k, ""), "long_name": k}) for k, v in fields.items()},
        coords={"time": ("time", time, {"units": "s"}), "site": np.arange(x.size),
                "x": ("site", x, {"units": "m"})},
    )
    h = float(x[1] - x[0]) if x.size > 1 else 1.0
    ds.attrs.update({"model": "synthetic", "spacing_m": h, "status": "finished", **(attrs or {})})
    return ds


def pulse_dataset(pulses: list[SynthPulse], *, n_sites: int = 200, spacing_m: float = 1.0,
                  duration_s: float = 100.0, n_frames: int = 401, noise: float = 0.0, seed: int = 0,
                  field: str = "theta", units: str = "rad") -> xr.Dataset:
    """Dataset whose ``field`` is the sum of travelling pulses plus white noise of std ``noise``."""
    time = np.linspace(0.0, duration_s, n_frames)
    x = np.arange(n_sites) * spacing_m
    vals = np.zeros((n_frames, n_sites))
    for p in pulses:
        c = p.x0_m + p.speed_m_s * time[:, None]
        d = np.abs(c - p.x0_m)
        amp = p.amplitude * np.exp(-p.attenuation_per_m * d)
        if p.formation_m > 0:
            amp = amp * (p.start_fraction + (1 - p.start_fraction) * np.minimum(d / p.formation_m, 1.0))
        amp = amp * (1 + p.breathing * np.sin(2 * np.pi * time[:, None] / p.breathing_period_s))
        with np.errstate(invalid="ignore"):  # inf/inf: a pulse that lives for ever
            life = 0.25 * (1 + np.tanh((time - p.starts_s) / p.fade_s)) * (1 - np.tanh((time - p.ends_s) / p.fade_s))
        amp = amp * np.nan_to_num(life, nan=1.0)[:, None]
        vals += amp * SHAPES[p.shape](x[None, :], 1.0, c, p.width_m)
    rng = np.random.default_rng(seed)
    vals += noise * rng.standard_normal(vals.shape)
    return _dataset(time, x, {field: vals}, {field: units})


@dataclass(frozen=True)
class SynthLeg:
    """A pulse entering or leaving a collision at (t_c, x_c): ``amplitude · shape((x − X(t))/W)``
    with X(t) = x_c + d · shift_m + v (t − t_c), d = sign(v): a leaving pulse shifted forward
    along its motion by ``shift_m`` (an entering one has shift 0: it aims at x_c)."""

    amplitude: float
    speed_m_s: float
    width_m: float
    shift_m: float = 0.0
    shape: str = "sech"


def collision_dataset(incoming: tuple[SynthLeg, SynthLeg], outgoing: list[SynthLeg], *, t_c: float,
                      x_c: float, n_sites: int = 240, spacing_m: float = 1.0, duration_s: float = 200.0,
                      n_frames: int = 801, switch_s: float = 1.0, noise: float = 0.0, seed: int = 0,
                      field: str = "theta", units: str = "rad") -> xr.Dataset:
    """Two pulses meeting at (t_c, x_c) and the pulses that leave it (known shifts, amplitude and
    speed changes, passing or reflected); the incoming pulses fade out and the outgoing ones in
    over ``switch_s`` around t_c, while they overlap."""
    time = np.linspace(0.0, duration_s, n_frames)
    x = np.arange(n_sites) * spacing_m
    before = 0.5 * (1 - np.tanh((time - t_c) / switch_s))[:, None]
    vals = np.zeros((n_frames, n_sites))
    for legs, weight in ((incoming, before), (outgoing, 1 - before)):
        for leg in legs:
            c = x_c + np.sign(leg.speed_m_s) * leg.shift_m + leg.speed_m_s * (time[:, None] - t_c)
            vals += weight * SHAPES[leg.shape](x[None, :], leg.amplitude, c, leg.width_m)
    vals += noise * np.random.default_rng(seed).standard_normal(vals.shape)
    return _dataset(time, x, {field: vals}, {field: units})


def front_dataset(*, n_sites: int = 200, spacing_m: float = 1.0, jump: float = 1.0,
                  speed_m_s: float = 1.0, width_m: float = 3.0, x0_m: float = -10.0,
                  arrest_m: float | None = None, creep_m_s: float = 0.0, duration_s: float = 150.0,
                  n_frames: int = 301, noise: float = 0.0, seed: int = 0) -> xr.Dataset:
    """u = (L/2)(1 − tanh((x − X(t))/w)) (docs/physics.md §2), X(t) = x0 + v t, stopping at ``arrest_m``
    (or slowing there to ``creep_m_s``);
    displacement from the initial state (start the front outside the chain, x0 < −2w, for a
    chain that is uniform at t = 0)."""
    time = np.linspace(0.0, duration_s, n_frames)
    x = np.arange(n_sites) * spacing_m
    pos = x0_m + speed_m_s * time
    if arrest_m is not None:  # stops there, or creeps on at ``creep_m_s``
        t_stop = (arrest_m - x0_m) / speed_m_s
        pos = np.where(time < t_stop, pos, arrest_m + creep_m_s * (time - t_stop))
    u = 0.5 * jump * (1 - np.tanh((x[None, :] - pos[:, None]) / width_m))
    u = u - u[0]
    u += noise * np.random.default_rng(seed).standard_normal(u.shape)
    return _dataset(time, x, {"u": u}, {"u": "m"})


def driven_dataset(*, n_sites: int = 60, spacing_m: float = 1.0, frequency_hz: float = 1.0,
                   amplitude_m: float = 1.0, decay_per_site: float = 0.02, harmonic: float = 0.0,
                   duration_s: float = 40.0, n_frames: int = 2001) -> xr.Dataset:
    """u_n(t) = A e^{−κn} sin(ωt − qn) + h A e^{−κn} sin(2ωt), driven at the left end."""
    time = np.linspace(0.0, duration_s, n_frames)
    n = np.arange(n_sites)
    w = 2 * np.pi * frequency_hz
    env = amplitude_m * np.exp(-decay_per_site * n)[None, :]
    u = env * (np.sin(w * time[:, None] - 0.3 * n[None, :]) + harmonic * np.sin(2 * w * time[:, None]))
    cfg = ("excitation:\n  kind: shaker\n  end: left\n"
           f"  frequency_hz: {frequency_hz}\n  amplitude_m: {amplitude_m}\n")
    return _dataset(time, n * spacing_m, {"u": u}, {"u": "m"}, {"config": cfg})
