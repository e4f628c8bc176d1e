"""Driven (shaker) runs: steady-state response per site, transmission, harmonics, bands.

The steady window is the last ``steady_fraction`` of the run, trimmed to a whole number of drive
periods. A site is *reached* when the wave had arrived there before the window: its displacement
had already come to ``REACHED`` of its amplitude in the window (ahead of a wave that has not
arrived, only its precursor moves the site), or its amplitude is below ``FLOOR`` of the largest.
Only the reached sites next to the drive, above ``DECAY_FLOOR`` of its amplitude, enter the
decay fit (a log-linear fit of the fundamental's amplitude against the site; an evanescent
decay is fitted only down to the level of what else moves the sites, ``_above_floor``), and the transmission and the
far-end spectrum are measured only when the far end is reached (NaN otherwise: ``far_reached``
False). Amplitude of harmonic n at a site = 2|⟨(y − ȳ) e^{−i n ω t}⟩| over the window (a lock-in
average; exact for a stationary signal over whole periods). Transmission = fundamental amplitude
at the far end / at the driven end. The far-end spectrum is a Hann-windowed one-sided amplitude
spectrum (scipy.signal.periodogram). A set of runs at different frequencies gives transmission
against frequency; frequencies whose transmission is above ``pass_level`` (relative to the best)
form the pass bands.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from flexmm.errors import FlexmmError

REACHED = 0.5
FLOOR = 1e-9
#: the decay is fitted over sites whose amplitude is above this fraction of the driven site's:
#: an evanescent response falls to the round-off of the field within tens of sites, and a log fit
#: that runs into that floor flattens (0.25 per site measured for a true 1.40)
DECAY_FLOOR = 1e-8


class NotDriven(FlexmmError):
    """The run has no harmonic drive (or no drive frequency could be found)."""


@dataclass
class DrivenMeasurement:
    """Steady response of one driven run; SI units, amplitudes in the field's units."""

    field: str
    units: str
    frequency_hz: float
    drive_site: int
    far_site: int
    window_s: tuple[float, float]
    amplitude_drive: float
    amplitude_far: float
    transmission: float
    decay_per_site: float
    dominant_far_hz: float
    harmonics: np.ndarray  # (n_harmonics,) amplitude of n f at the far end, n = 1..
    amplitude: np.ndarray  # (n_pos,) fundamental amplitude per site
    spectrum_hz: np.ndarray
    spectrum: np.ndarray
    reached_sites: int = 0  # sites from the drive whose response is steady over the window
    far_reached: bool = True

    def scalars(self) -> dict:
        d = {k: v for k, v in asdict(self).items() if not isinstance(v, (np.ndarray, tuple))}
        d["window_start_s"], d["window_end_s"] = self.window_s
        for n, a in enumerate(self.harmonics, start=1):
            d[f"harmonic_{n}_ratio"] = float(a / self.harmonics[0]) if self.harmonics[0] > 0 else np.nan
        return d


def steady_window(time: np.ndarray, frequency_hz: float, steady_fraction: float = 0.4) -> np.ndarray:
    """Indices of the last ``steady_fraction`` of the run, cut to whole drive periods."""
    t_end = time[-1]
    period = 1.0 / frequency_hz
    span = steady_fraction * (t_end - time[0])
    n_per = max(1, int(span / period))
    return np.flatnonzero(time >= t_end - n_per * period - 1e-12 * period)


def lockin(y: np.ndarray, t: np.ndarray, frequency_hz: float) -> np.ndarray:
    """Amplitude of the component at ``frequency_hz`` of y (n_t, ...) sampled at times t (n_t,)."""
    # trapezoid weights: the average over whole periods, also for non-uniform sampling
    wt = np.zeros_like(t)
    wt[1:] += 0.5 * np.diff(t)
    wt[:-1] += 0.5 * np.diff(t)
    wt /= wt.sum()
    yc = y - np.tensordot(wt, y, axes=(0, 0))
    z = np.tensordot(wt * np.exp(-2j * np.pi * frequency_hz * t), yc, axes=(0, 0))
    return 2 * np.abs(z)


def _above_floor(a: np.ndarray, n_reached: int) -> np.ndarray:
    """(n_pos,) bool, sites in order from the drive: an evanescent response decays until it meets
    the floor of what else moves the sites (a transient ringing on in an undamped chain, whose
    lock-in leak is a level, not a decay): when the amplitudes fall monotonically to below a tenth
    of the floor's level (the median over the far half of the reached sites) over 3+ sites, only
    that stretch is kept; otherwise (a wave in the pass band, damped or not) every site."""
    keep = np.ones(a.size, bool)
    if n_reached < 8:
        return keep
    floor = float(np.median(a[n_reached // 2 : n_reached]))
    k = 0
    while k + 1 < n_reached and a[k + 1] < a[k] and a[k + 1] > 10 * floor:
        k += 1
    if k >= 2:
        keep[k + 1 :] = False
    return keep


def reached(t: np.ndarray, y: np.ndarray, t0: float, amp: np.ndarray) -> np.ndarray:
    """(n_pos,) bool: the site's displacement from its first value reached REACHED of its window
    amplitude ``amp`` before the window starts at ``t0`` (the wave had arrived), or ``amp`` is
    below FLOOR of the largest (a response at round-off, far out in an evanescent decay, is as
    steady as it gets). ``t`` (n_t,), ``y`` (n_t, n_pos): the whole run."""
    early = t < t0
    if not early.any():
        return np.ones(y.shape[1], bool)
    seen = np.max(np.abs(y[early] - y[0]), axis=0)
    return (seen >= REACHED * amp) | (amp <= FLOOR * amp.max())


def drive_frequency(config: dict | None) -> tuple[float | None, str]:
    """(frequency_hz, driven end) from a resolved config dict, or (None, 'left')."""
    exc = (config or {}).get("excitation") or {}
    if exc.get("kind") != "shaker":
        return None, exc.get("end", "left")
    return float(exc["frequency_hz"]), exc.get("end", "left")


def measure_driven(view, frequency_hz: float | None = None, *, end: str = "left",
                   steady_fraction: float = 0.4, n_harmonics: int = 5) -> DrivenMeasurement:
    """Steady-state response of a driven FieldView (frequency from the config or given)."""
    from scipy.signal import periodogram  # here: scipy.signal is slow to import

    t, y = view.time, view.values
    drive, far = (0, view.n_pos - 1) if end == "left" else (view.n_pos - 1, 0)
    if frequency_hz is None:
        f, p = periodogram(y[:, drive] - y[:, drive].mean(), fs=1.0 / float(np.median(np.diff(t))))
        if not np.any(p > 0):
            raise NotDriven(f"no drive frequency: {view.spec!r} does not move at the driven end")
        frequency_hz = float(f[np.argmax(p)])
    win = steady_window(t, frequency_hz, steady_fraction)
    if win.size < 8:
        raise NotDriven(f"too few frames ({win.size}) in the steady window to resolve {frequency_hz:g} Hz")
    tw, yw = t[win], y[win]
    amp = lockin(yw, tw, frequency_hz)
    order = np.arange(view.n_pos) if end == "left" else np.arange(view.n_pos)[::-1]
    steady = reached(t, y, float(tw[0]), amp)[order]
    n_reached = int(np.argmin(steady)) if not steady.all() else view.n_pos
    far_reached = n_reached == view.n_pos
    harm = np.array([float(lockin(yw[:, far], tw, n * frequency_hz)) for n in range(1, n_harmonics + 1)])
    fs = 1.0 / float(np.median(np.diff(tw)))
    fsp, psd = periodogram(yw[:, far], fs=fs, window="hann", scaling="spectrum")
    spec = np.sqrt(2 * psd)
    if not far_reached:  # the far end's response is the precursor of a wave still on its way
        harm, spec = np.full_like(harm, np.nan), np.full_like(spec, np.nan)
    good = (amp[order] > DECAY_FLOOR * max(amp[drive], 1e-300)) & (np.arange(view.n_pos) < n_reached)
    good &= _above_floor(amp[order], n_reached)
    k = np.arange(view.n_pos)[good]
    decay = float(-np.polyfit(k, np.log(amp[order][good]), 1)[0]) if k.size >= 2 else np.nan
    transmission = float(amp[far] / amp[drive]) if amp[drive] > 0 and far_reached else np.nan
    return DrivenMeasurement(
        field=view.spec, units=view.units, frequency_hz=float(frequency_hz), drive_site=int(view.site[drive]),
        far_site=int(view.site[far]), window_s=(float(tw[0]), float(tw[-1])),
        amplitude_drive=float(amp[drive]), amplitude_far=float(amp[far]) if far_reached else np.nan,
        transmission=transmission, decay_per_site=decay,
        dominant_far_hz=float(fsp[1:][np.argmax(spec[1:])]) if fsp.size > 1 and far_reached else np.nan,
        harmonics=harm, amplitude=amp, spectrum_hz=fsp, spectrum=spec, reached_sites=n_reached,
        far_reached=far_reached,
    )


def pass_bands(frequency_hz, transmission, pass_level: float = 0.1) -> list[tuple[float, float]]:
    """Frequency intervals where transmission ≥ pass_level × its maximum (runs sorted by f)."""
    f = np.asarray(frequency_hz, float)
    tr = np.asarray(transmission, float)
    order = np.argsort(f)
    f, tr = f[order], tr[order]
    ok = tr >= pass_level * np.nanmax(tr)
    bands, start = [], None
    for fi, o in zip(f, ok):
        if o and start is None:
            start = fi
        if not o and start is not None:
            bands.append((start, prev))
            start = None
        prev = fi
    if start is not None:
        bands.append((start, f[-1]))
    return bands
