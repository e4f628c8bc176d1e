"""Oblique planar waves on a skew-periodic sheet: the pulses they separate into.

A sheet of ``n_rows`` rows whose bottom/top wrap is shifted by ``skew_cols`` columns carries plane
waves along φ = atan(skew_cols/n_rows); every unit sits at the distance ζ = col cosφ + row sinφ
(in lattice spacings) along the propagation direction. The translational kinetic energy of the
units is binned onto ζ (one-spacing bins) and smoothed over ``smooth`` spacings; the peaks of that
energy profile are tracked through the frames (flexmm.analysis.features.detect), and every track that
travels far enough is a *group*: its speed (line fit of position against time over the frames it
is seen in), its energy share, and its polarisation — the angle ψ, measured from the propagation
direction, of the principal axis of the (u̇, v̇) velocities inside the group (ψ = 0: longitudinal,
±90°: transverse).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
import yaml

from flexmm._blas import single_blas_thread
from flexmm.analysis.context import Comparison, RunContext
from flexmm.analysis.features.detect import track_peaks
from flexmm.errors import FlexmmError


@dataclass(frozen=True)
class WaveGroup:
    """One pulse (or packet) of an oblique planar wave."""

    speed_m_s: float
    speed_c0: float
    position_m: float          # along ζ at the last frame it was seen
    energy_fraction: float     # of the summed translational kinetic energy of the groups, last frame
    polarisation_deg: float    # principal axis of (u̇, v̇) relative to the propagation direction
    n_frames: int

    def scalars(self) -> dict:
        return {k: float(v) for k, v in asdict(self).items()}


def speed_unit(lat) -> float:
    """c0 = a sqrt(k_l/m) of a sheet lattice config (m/s)."""
    return lat.a_m * math.sqrt(lat.k_long_n_per_m / lat.unit_mass_kg)


def propagation_angle(ds) -> float:
    """φ (rad) of a skew-periodic sheet's plane waves, from the dataset's resolved config."""
    lat = yaml.safe_load(ds.attrs["config"])["lattice"]
    if lat.get("kind") != "rotating_squares_sheet" or lat.get("bottom") != "periodic":
        raise ValueError("oblique waves need a rotating_squares_sheet with periodic bottom/top edges")
    return math.atan2(lat.get("skew_cols", 0), lat["n_rows"])


def _zeta_bins(ds, phi: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Bin index of every unit along ζ, the bin centres (m) and the spacing (m)."""
    col, row = ds.col.values, ds.row.values
    h = float(np.median(np.diff(np.unique(ds.x.values))))
    zeta = col * math.cos(phi) + row * math.sin(phi)
    idx = np.floor(zeta - zeta.min()).astype(np.int64)
    centres = (np.arange(idx.max() + 1) + 0.5 + zeta.min()) * h
    return idx, centres, h


def _polarisation(ud: np.ndarray, vd: np.ndarray, phi: float) -> float:
    """Principal axis of the velocity vectors, degrees from the propagation direction, in (−90, 90]."""
    cov = np.array([[ud @ ud, ud @ vd], [ud @ vd, vd @ vd]])
    with single_blas_thread():
        w, vec = np.linalg.eigh(cov)
    ex, ey = vec[:, 1]
    return fold_axis(math.degrees(math.atan2(ey, ex) - phi))


def fold_axis(deg: float) -> float:
    """An axis direction (degrees, defined modulo 180) folded into [−90, 90)."""
    return (deg + 90.0) % 180.0 - 90.0


def wave_groups(ds, *, smooth: float = 15.0, threshold_fraction: float = 0.15, min_travel: float = 40.0,
                t_from: float | None = None, c0_m_s: float | None = None) -> list[WaveGroup]:
    """The groups an oblique planar wave separates into (fastest first); see the module docstring.

    ``t_from`` (s): ignore earlier frames (default: the second half of the run, once the pulses
    have left the drive). ``c0_m_s``: speed unit for ``speed_c0`` (default ``speed_unit`` of the
    run's lattice).
    """
    phi = propagation_angle(ds)
    idx, centres, h = _zeta_bins(ds, phi)
    time = ds.time.values
    t_from = 0.5 * time[-1] if t_from is None else t_from
    frames = np.flatnonzero(time >= t_from)
    ud, vd = ds.u_dot.values[frames], ds.v_dot.values[frames]
    nb = centres.size
    energy = np.stack([np.bincount(idx, 0.5 * (a * a + b * b), minlength=nb) for a, b in zip(ud, vd)])
    from scipy.ndimage import uniform_filter1d  # here: slow to import, and only oblique waves need it

    energy = uniform_filter1d(energy, size=max(1, int(round(smooth))), axis=1, mode="constant")
    thr = threshold_fraction * float(energy.max())
    tracks = [tr for tr in track_peaks(energy, time[frames], centres, threshold=(thr, np.inf),
                                       gate=3.0 * smooth * h)
              if tr.polarity > 0 and tr.travel >= min_travel * h and len(tr.pos) >= 4]
    if c0_m_s is None:
        c0_m_s = speed_unit(RunContext.from_dataset(ds).scene().lattice)
    last = energy[-1]
    groups = []
    for tr in tracks:
        _, t, pos, _ = tr.arrays()
        speed = float(np.polyfit(t, pos, 1)[0])
        x_last = tr.predict(time[frames][-1])
        inside = np.abs(centres - x_last) <= smooth * h
        sel = np.isin(idx, np.flatnonzero(inside))
        groups.append(dict(speed=speed, pos=x_last, e=float(last[inside].sum()),
                           pol=_polarisation(ud[-1][sel], vd[-1][sel], phi), n=len(pos)))
    total = sum(g["e"] for g in groups) or 1.0
    out = [WaveGroup(g["speed"], g["speed"] / c0_m_s, g["pos"], g["e"] / total, g["pol"], g["n"]) for g in groups]
    return sorted(out, key=lambda g: -g.speed_m_s)


class NoWaveGroups(FlexmmError):
    """No group travelled far enough to be measured."""


def is_oblique(ctx: RunContext) -> bool:
    """True for a skew-periodic sheet (its plane waves are oblique)."""
    lat = ctx.config.get("lattice") or {}
    return lat.get("kind") == "rotating_squares_sheet" and bool(lat.get("skew_cols"))


def compare_groups(ctx: RunContext, groups: list[WaveGroup]) -> list[Comparison]:
    """Speed and polarisation of each group against the long-wave acoustic mode nearest in polarisation."""
    from flexmm.linear.sheet import acoustic_modes

    lat = ctx.scene().lattice
    modes = acoustic_modes(lat, propagation_angle(ctx.ds))
    c0 = speed_unit(lat)
    out = []
    for i, g in enumerate(groups, 1):
        j = min(range(len(modes)), key=lambda m: abs(fold_axis(g.polarisation_deg - modes[m][1])))
        speed, pol = modes[j]
        name = "fast" if j == 1 else "slow"
        note = f"long-wave {name} acoustic mode; {100 * g.energy_fraction:.0f} % of the groups' energy"
        out += [Comparison(f"group {i}", "speed", g.speed_m_s, speed * c0, "m/s", note),
                Comparison(f"group {i}", "polarisation", g.polarisation_deg, pol, "deg",
                           "in-plane motion, from the propagation direction")]
    return out
