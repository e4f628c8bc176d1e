"""Matplotlib figures of an analysis (PNG, Agg backend, small files).

space_time: field against position and time with the fitted pulse/front trajectories;
profile: a measured spatial profile, its sech/sech² fits and the theory profile;
speed_amplitude: measured (amplitude, speed) points of several runs on the theory curve;
front_position: 50 % crossing position against time; spectrum: far-end spectrum of a driven run;
omega_k: ω–k power spectrum of a run's field with the linear bands;
transmission: transmission against drive frequency over several runs, with theory pass bands.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from flexmm.analysis.features.profiles import SHAPES  # noqa: E402

DPI = 110


def _save(fig, path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=DPI, bbox_inches="tight")
    plt.close(fig)
    return path


def _cycle():
    """Overlay colours that stay visible on the diverging colour map, repeated as needed."""
    while True:
        yield from ("k", "#1b9e77", "#d95f02", "#7570b3", "#e7298a", "#66a61e")


def _label(view) -> str:
    return f"{view.spec} ({view.units})" if view.units else view.spec


def space_time(view, path, *, pulses=(), fronts=(), title: str = "", max_frames: int = 1200) -> Path:
    """Field on the (position, time) plane; pulse arrival fits and front tracks overlaid."""
    step = max(1, view.n_time // max_frames)
    vals, t = view.values[::step], view.time[::step]
    lim = float(np.nanmax(np.abs(vals))) or 1.0
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    h = view.spacing_m
    im = ax.imshow(vals, origin="lower", aspect="auto", cmap="RdBu_r", vmin=-lim, vmax=lim,
                   extent=(view.site[0] - 0.5, view.site[-1] + 0.5, t[0] * 1e3, t[-1] * 1e3),
                   interpolation="nearest")
    fig.colorbar(im, ax=ax, label=_label(view))
    for p, color in zip(pulses, _cycle()):
        ax.plot(p.sites, p.arrival_time_s * 1e3, ".", color=color, ms=2.5, mec="none")
        ax.plot([], [], ".", color=color, label=f"pulse {p.index}: {p.speed_m_s:.4g} m/s")
    for f, color in zip(fronts, _cycle()):
        ax.plot(f.track_pos_m / h + view.site[0] - view.x[0] / h, f.track_time_s * 1e3, "-", color=color, lw=1)
        ax.plot([], [], "-", color=color, label=f"front {f.index}: {f.speed_m_s:.4g} m/s")
    if pulses or fronts:
        ax.legend(loc="upper left", fontsize=8, framealpha=0.8)
    ax.set(xlabel="site", ylabel="time (ms)", title=title)
    return _save(fig, path)


def profile(pulse, path, *, theory=None, theory_label: str = "theory", title: str = "") -> Path:
    """Measured profile at one instant with the fitted shapes and an optional theory curve."""
    x, y = pulse.profile_x_m, pulse.profile_values
    fig, ax = plt.subplots(figsize=(5.6, 3.6))
    ax.plot(x * 1e3, y, "ko", ms=3.5, label=f"measured, t = {pulse.profile_time_s * 1e3:.4g} ms")
    xf = np.linspace(x.min(), x.max(), 600)
    for shape, style in (("sech", "C0-"), ("sech2", "C2:")):
        f = pulse.profile_fits.get(shape)
        if f is not None and f.ok:
            ax.plot(xf * 1e3, SHAPES[shape](xf, f.amplitude, f.center, f.W), style, lw=1.2,
                    label=f"{shape} fit, W = {f.W * 1e3:.3g} mm")
    if theory is not None:
        ax.plot(xf * 1e3, theory(xf), "C3--", lw=1.5, label=theory_label)
    ax.set(xlabel="position (mm)", ylabel=f"{pulse.field} ({pulse.units})", title=title)
    ax.legend(fontsize=8)
    return _save(fig, path)


def speed_amplitude(points, path, *, curve=None, units: str = "rad", title: str = "",
                    rel_panel: bool = True) -> Path:
    """Speed against |amplitude|: ``points`` = [(A, v, v_err, label)], ``curve`` = (A, v) arrays."""
    A = np.array([abs(p[0]) for p in points])
    v = np.array([p[1] for p in points])
    err = np.array([p[2] for p in points])
    two = rel_panel and curve is not None
    fig, axes = plt.subplots(2 if two else 1, 1, figsize=(5.6, 5.2 if two else 3.6), sharex=True,
                             gridspec_kw={"height_ratios": [3, 1]} if two else None)
    ax = axes[0] if two else axes
    if curve is not None:
        ax.plot(np.abs(curve[0]), curve[1], "C0-", lw=1.5, label="exact continuum law")
    ax.errorbar(A, v, yerr=err, fmt="o", color="C3", ms=4, label="simulation")
    ax.set(ylabel="speed (m/s)", title=title)
    ax.legend(fontsize=8)
    if two:
        order = np.argsort(np.abs(curve[0]))
        pred = np.interp(A, np.abs(curve[0])[order], curve[1][order], left=np.nan, right=np.nan)
        axes[1].axhspan(-1, 1, color="0.9")
        axes[1].plot(A, 100 * (v - pred) / pred, "o", color="C3", ms=4)
        axes[1].text(0.99, 0.05, "shaded: ±1 %", transform=axes[1].transAxes, ha="right", fontsize=7)
        axes[1].axhline(0, color="C0", lw=1)
        rel = 100 * (v - pred) / pred
        lim = (-2, 2) if not np.isfinite(rel).any() else (min(-2, np.nanmin(rel) - 0.5), max(2, np.nanmax(rel) + 0.5))
        axes[1].set(ylabel="diff. (%)", ylim=lim)
        axes[1].set_xlabel(f"amplitude ({units})")
    else:
        ax.set_xlabel(f"amplitude ({units})")
    return _save(fig, path)


def front_position(fronts, path, *, title: str = "") -> Path:
    """50 % crossing position against time, with the speed fit through the switching times."""
    fig, ax = plt.subplots(figsize=(5.6, 3.6))
    for f in fronts:
        ax.plot(f.track_time_s * 1e3, f.track_pos_m, "-", lw=1, label=f"front {f.index}")
        ax.plot(f.switch_time_s * 1e3, f.x_m, ".", ms=3, label=f"switch times: {f.speed_m_s:.4g} m/s")
    ax.set(xlabel="time (ms)", ylabel="front position (m)", title=title)
    ax.legend(fontsize=8)
    return _save(fig, path)


def spectrum(driven, path, *, title: str = "") -> Path:
    """Far-end amplitude spectrum with the drive frequency and its harmonics marked."""
    fig, ax = plt.subplots(figsize=(5.6, 3.6))
    ax.semilogy(driven.spectrum_hz, np.maximum(driven.spectrum, 1e-300), "k-", lw=1)
    for n in range(1, driven.harmonics.size + 1):
        ax.axvline(n * driven.frequency_hz, color="C3", lw=0.8, ls=":")
    ax.set(xlabel="frequency (Hz)", ylabel="far-end amplitude", title=title,
           xlim=(0, (driven.harmonics.size + 0.5) * driven.frequency_hz))
    return _save(fig, path)


def omega_k(spec, path, *, title: str = "") -> Path:
    """log10 of an ω–k power spectrum (``analysis.dispersion_spectrum``) with the linear bands
    drawn over it; a sheet's ω–k_x (k_y = 0) and ω–k_y (k_x = 0) cuts (``Spectrum.cuts``)."""
    cuts = spec.cuts()
    fig, axes = plt.subplots(1, len(cuts), figsize=(5.6 * len(cuts), 4.2), squeeze=False)
    for ax, (k, p, bands, xlabel) in zip(axes[0], cuts):
        logp = np.log10(np.maximum(p, np.max(p) * 1e-12 if np.max(p) > 0 else 1e-300))
        dk = k[1] - k[0] if k.size > 1 else 1.0
        im = ax.imshow(logp, origin="lower", aspect="auto", cmap="magma", interpolation="nearest",
                       extent=(k[0] - dk / 2, k[-1] + dk / 2, 0, spec.omega[-1]), vmin=logp.max() - 8)
        fig.colorbar(im, ax=ax, label="log10 power")
        top = spec.omega[-1]
        if bands is not None:
            for b in range(bands.shape[1]):
                for sign in (1, -1):
                    ax.plot(sign * spec.band_k, bands[:, b], "c--", lw=0.8,
                            label="linear bands" if (b, sign) == (0, 1) else None)
            ax.legend(loc="upper right", fontsize=8)
            if np.isfinite(bands).any():  # up to the bands, not the frames' Nyquist
                top = min(top, 1.3 * float(np.nanmax(bands)))
        ax.set(xlabel=xlabel, ylabel="ω (rad/s)", title=title, ylim=(0, top))
    return _save(fig, path)


def transmission(freqs, trans, path, *, bands=(), title: str = "") -> Path:
    """Transmission against drive frequency (log scale), theory pass bands shaded."""
    order = np.argsort(freqs)
    f, tr = np.asarray(freqs)[order], np.asarray(trans)[order]
    fig, ax = plt.subplots(figsize=(5.6, 3.6))
    for k, (lo, hi) in enumerate(bands):
        ax.axvspan(lo, hi, color="C0", alpha=0.15, label="linear pass band" if k == 0 else None)
    ax.semilogy(f, np.maximum(tr, 1e-300), "o-", color="C3", ms=4, label="simulation")
    ax.set(xlabel="drive frequency (Hz)", ylabel="transmission (far/drive)", title=title,
           xlim=(0.9 * f.min(), 1.1 * f.max()))
    ax.legend(fontsize=8)
    return _save(fig, path)


# ----------------------------------------------------------------------------------------------
# Figures of analysed runs (RunAnalysis objects from analysis.report.analyze)

def _theory(res):
    from flexmm.analysis.report.theory_comparison import theory_for

    return theory_for(res.ctx)


def run_figures(res, directory=None) -> list[Path]:
    """Figures of one analysed run, written beside its dataset (or in ``directory``)."""
    base = Path(directory) if directory else (res.path if res.path.is_dir() else res.path.parent)
    stem = res.view.spec.replace(":", "_")
    made = [space_time(res.view, base / f"space_time_{stem}.png", pulses=res.pulses, fronts=res.fronts,
                       title=res.name)]
    th = _theory(res)
    for p in res.pulses:
        curve = None
        if th.profile is not None:
            try:
                th.profile(res.ctx, p, p.profile_x_m[:1])
                curve = lambda x, p=p: th.profile(res.ctx, p, x)  # noqa: E731
            except (ValueError, ArithmeticError):
                curve = None
        made.append(profile(p, base / f"profile_{stem}_{p.index}.png", theory=curve,
                            theory_label="exact soliton at measured A", title=f"{res.name}: pulse {p.index}"))
    if res.fronts:
        made.append(front_position(res.fronts, base / f"front_position_{stem}.png", title=res.name))
    if res.driven is not None:
        made.append(spectrum(res.driven, base / f"spectrum_{stem}.png", title=res.name))
    return made


def main_pulses(res, fraction: float = 0.7) -> list:
    """The pulses of a run whose |amplitude| is at least ``fraction`` of its largest one."""
    top = max((abs(p.amplitude) for p in res.pulses), default=0.0)
    return [p for p in res.pulses if abs(p.amplitude) >= fraction * top]


def set_figures(results, directory) -> list[Path]:
    """Figures across runs: speed against amplitude, transmission against frequency."""
    directory = Path(directory)
    made = []
    with_pulses = [r for r in results if r.pulses]
    if len(with_pulses) >= 2:
        pts = [(p.amplitude, p.speed_m_s, p.speed_stderr_m_s, r.name) for r in with_pulses for p in main_pulses(r)]
        curve = None
        th = _theory(with_pulses[0])
        if th.speed_curve is not None:
            amax = max(abs(p[0]) for p in pts)
            A = np.linspace(0.02 * amax, 1.15 * amax, 300) * np.sign(pts[0][0] or 1)
            v = th.speed_curve(with_pulses[0].ctx, with_pulses[0].view.units, A)
            curve = (A, v) if np.isfinite(v).any() else None
        made.append(speed_amplitude(pts, directory / "speed_amplitude.png", curve=curve,
                                    units=with_pulses[0].view.units))
    driven = [r for r in results if r.driven is not None]
    if len(driven) >= 2:
        from flexmm.analysis.report.theory_comparison import bands_for

        bands = bands_for(driven[0].ctx)
        made.append(transmission([r.driven.frequency_hz for r in driven], [r.driven.transmission for r in driven],
                                 directory / "transmission.png", bands=bands))
    return made
