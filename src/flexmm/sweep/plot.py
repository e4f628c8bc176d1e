"""Plot a sweep: each observable against the first varied parameter, with theory where known.

Panels: speed, |amplitude| and width (and transmission for driven runs) against the first
varied parameter (one line per value of any other grid parameter; hollow markers = theory at the
measured amplitude), and — when the model has a speed law (``flexmm.sweep.theory.speed_at``) —
speed against measured |amplitude| with the theory curve. Points without a measurement (no pulse,
failed) are left out and counted in the title. The amplitude gap (rotating squares) is drawn as
a dashed line.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from flexmm.sweep.store import RESULT


def is_sweep(path: str | Path) -> bool:
    """True for a sweep directory (one holding sweep.nc or points/) or a combined sweep.nc file."""
    p = Path(path)
    return (p.is_dir() and ((p / RESULT).is_file() or (p / "points").is_dir())) or (p.is_file() and p.name == RESULT)


def open_sweep(path: str | Path):
    """The combined sweep dataset of a sweep directory (or its sweep.nc)."""
    import xarray as xr

    p = Path(path)
    if p.is_dir():
        p = p / RESULT
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no combined sweep dataset (run `flexmm sweep` to completion first)")
    return xr.load_dataset(p, engine="h5netcdf")


def _label(ds, name: str) -> str:
    v = ds[name]
    u = v.attrs.get("units", "")
    return f"{v.attrs.get('parameter', name)}" + (f" ({u})" if u and u != "1" else "")


def _series(ds):
    """(x name, [(legend label, selection dict)]) for the first varied parameter."""
    if ds.attrs.get("sweep_mode") == "zip":
        params = [c for c in ds.coords if c != "point"]
        return params[0], [("", {})]
    dims = list(ds["speed"].dims)
    x, rest = dims[0], dims[1:]
    combos = itertools.product(*(range(ds.sizes[d]) for d in rest))
    out = []
    for combo in combos:
        sel = dict(zip(rest, combo))
        label = ", ".join(f"{d}={ds[d].values[i]}" for d, i in sel.items())
        out.append((label, sel))
    return x, out


def speed_curves(ds) -> list[tuple[np.ndarray, np.ndarray]]:
    """Theory speed against |amplitude| over the measured range, per polarity: [(|A|, c)]."""
    import yaml

    from flexmm.sweep.theory import speed_at

    if "amplitude" not in ds or "base_config" not in ds.attrs:
        return []
    config = yaml.safe_load(ds.attrs["base_config"])
    units = ds["amplitude"].attrs.get("units", "")
    amp = np.asarray(ds["amplitude"].values, float).ravel()
    amp = amp[np.isfinite(amp) & (amp != 0)]
    out = []
    for sign in (+1, -1):
        a = np.abs(amp[np.sign(amp) == sign])
        if a.size == 0:
            continue
        grid = np.linspace(0.5 * a.min(), 1.1 * a.max(), 200)
        c = speed_at(config, units, sign * grid)
        if np.isfinite(c).any():
            out.append((grid, c))
    return out


def plot_sweep(sweep_dir: str | Path, out_png: str | Path) -> Path:
    """Plot SWEEP_DIR/sweep.nc to ``out_png``; returns the path written."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ds = open_sweep(sweep_dir)
    curves = speed_curves(ds)
    has_theory = "speed_theory" in ds and bool(np.isfinite(ds["speed_theory"].values).any())
    vs_amplitude = bool(curves) or (ds.attrs.get("measured") == "pulse"
                                    and np.isfinite(np.asarray(ds["speed"].values, float)).sum() > 1)
    units = ds["amplitude"].attrs.get("units", "")
    panels = [("speed", "speed (m/s)"), ("amplitude", f"|amplitude| ({units})"), ("width", "width (m)")]
    if "transmission" in ds:
        panels.append(("transmission", "transmission"))
    n = len(panels) + (1 if vs_amplitude else 0)
    fig, axes = plt.subplots(1, n, figsize=(4.2 * n, 3.6), squeeze=False)
    x, series = _series(ds)
    for ax, (var, ylabel) in zip(axes[0], panels):
        _against_parameter(ax, ds, x, series, var, ylabel)
    if vs_amplitude:
        _speed_against_amplitude(axes[0][-1], ds, curves, has_theory)
    if len(series) > 1 or has_theory:
        axes[0][0].legend(fontsize=7)
    status = np.asarray(ds["status"].values).ravel()
    measured = np.isfinite(np.asarray(ds["speed"].values, float)).ravel()
    fig.suptitle(f"{ds.attrs.get('title', '')}: {status.size} points, {int(measured.sum())} measured, "
                 f"{int(np.sum(status == 'failed'))} failed", fontsize=10)
    fig.tight_layout()
    out = Path(out_png)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.stem}.tmp{out.suffix}")
    fig.savefig(tmp, dpi=120)
    plt.close(fig)
    tmp.replace(out)
    return out


def _against_parameter(ax, ds, x: str, series, var: str, ylabel: str) -> None:
    """One observable against the first varied parameter; theory as hollow markers."""
    import matplotlib.ticker

    for label, sel in series:
        sub = ds.isel(sel) if sel else ds
        xv = np.asarray(sub[x].values)
        yv = np.asarray(sub[var].values, float)
        ax.plot(xv, np.abs(yv) if var == "amplitude" else yv, "o-", ms=4, label=label or "measured")
        theory = f"{var}_theory"
        if theory in sub and np.isfinite(sub[theory].values).any():
            ax.plot(xv, np.asarray(sub[theory].values, float), "o", mfc="none", color="k", ms=6,
                    label="theory at measured amplitude" if not label else None)
    if var == "amplitude":
        _gap_lines(ax, ds, horizontal=True)
        _log_if_wide(ax, np.abs(np.asarray(ds[var].values, float)))
    ax.set_xlabel(_label(ds, x))
    ax.set_ylabel(ylabel)
    _widen_if_flat(ax, np.asarray(ds[var].values, float))
    if ds[x].attrs.get("scale") == "log":
        ax.set_xscale("log")
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.grid(alpha=0.3)


def _speed_against_amplitude(ax, ds, curves, has_theory: bool) -> None:
    """Measured speed against measured |amplitude|, with the model's speed law where known."""
    amp = np.abs(np.asarray(ds["amplitude"].values, float)).ravel()
    ax.plot(amp, np.asarray(ds["speed"].values, float).ravel(), "o", ms=4, label="measured")
    if not curves and has_theory:
        ax.plot(amp, np.asarray(ds["speed_theory"].values, float).ravel(), "o", mfc="none", color="k",
                ms=6, label="theory at measured amplitude")
    for k, (a, c) in enumerate(curves):
        ax.plot(a, c, "-", color="k", lw=1, label="theory (speed law of the model)" if k == 0 else None)
    _gap_lines(ax, ds, horizontal=False)
    ax.set_xlabel(f"|amplitude| ({ds['amplitude'].attrs.get('units', '')})")
    ax.set_ylabel("speed (m/s)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)


def _widen_if_flat(ax, values: np.ndarray, rel: float = 1e-6) -> None:
    """A constant observable (e.g. a front's fixed jump) gets a ±10 % axis, not offset ticks."""
    v = np.abs(values[np.isfinite(values)])
    if v.size and ax.get_yscale() == "linear" and np.ptp(v) <= rel * v.max() and v.max() > 0:
        ax.set_ylim(0.9 * v.max(), 1.1 * v.max())


def _log_if_wide(ax, values: np.ndarray, ratio: float = 20.0) -> None:
    v = values[np.isfinite(values) & (values > 0)]
    if v.size and v.max() > ratio * v.min():
        ax.set_yscale("log")


def _gap_lines(ax, ds, horizontal: bool) -> None:
    gaps = {ds.attrs.get("theory_amplitude_gap_positive_rad"), ds.attrs.get("theory_amplitude_gap_negative_rad")}
    for k, g in enumerate(sorted(g for g in gaps if g is not None and np.isfinite(g) and g > 0)):
        line = ax.axhline if horizontal else ax.axvline
        line(g, ls="--", color="gray", lw=1, label="amplitude gap A_min (theory)" if k == 0 else None)


def main(argv: list[str] | None = None) -> None:
    """``python -m flexmm.sweep.plot SWEEP_DIR OUT_PNG`` (used by ``make figures``)."""
    import sys

    args = sys.argv[1:] if argv is None else argv
    if len(args) != 2:
        raise SystemExit("usage: python -m flexmm.sweep.plot SWEEP_DIR OUT_PNG")
    print(plot_sweep(args[0], args[1]))


if __name__ == "__main__":
    main()
