"""Files written by ``flexmm fit`` and ``flexmm design``: datasets, the result as a scene, figures."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from flexmm.io.atomic import write_text_atomic
from flexmm.io.cf import write_netcdf
from flexmm.io.provenance import provenance_attrs


def write_scene(data: dict, path: Path, header: str) -> Path:
    """A runnable scene YAML (``flexmm run PATH``) with a comment header."""
    text = "".join(f"# {line}\n" for line in header.splitlines()) + yaml.safe_dump(data, sort_keys=False)
    write_text_atomic(path, text)
    return path


def write_dataset(ds, path: Path, scene) -> Path:
    """netCDF (h5netcdf) with the scene's provenance attrs and CF metadata, written atomically."""
    ds.attrs.update(provenance_attrs(scene))
    return write_netcdf(ds, path)


def fit_dataset(fit, result, model_start: np.ndarray, model_fit: np.ndarray):
    """xarray Dataset of a fit: data, models at the start and the optimum, residuals, parameters."""
    import xarray as xr

    m = fit.measured
    si_unit = "m" if fit.kind == "length" else "rad"  # the table is in SI
    dims = ("time", "site")
    labels = fit.design.labels
    ds = xr.Dataset(
        {
            "data": (dims, m.values, {"units": si_unit, "long_name": f"measured {fit.spec.data.field}"}),
            "model_start": (dims, model_start, {"units": si_unit, "long_name": "model at the initial parameters"}),
            "model_fit": (dims, model_fit, {"units": si_unit, "long_name": "model at the fitted parameters"}),
            "residual": (dims, (model_fit - m.values) / fit.sigma,
                         {"units": "1", "long_name": "residual (model − data)/σ"}),
            "initial": ("parameter", fit.design.x0, {"units": "SI (per parameter)", "long_name": "initial value"}),
            "value": ("parameter", result.x, {"units": "SI (per parameter)", "long_name": "fitted value"}),
            "stderr": ("parameter", result.stderr,
                       {"units": "SI (per parameter)", "long_name": "Gauss-Newton standard error"}),
            "covariance": (("parameter", "parameter_2"), result.covariance,
                           {"units": "SI (products)", "long_name": "Gauss-Newton covariance s²(JᵀJ)⁻¹"}),
        },
        coords={"time": ("time", m.times, {"units": "s"}), "site": ("site", m.sites, {"units": "1"}),
                "parameter": ("parameter", labels), "parameter_2": ("parameter_2", labels)},
        attrs={"reduced_chi2": result.reduced_chi2, "cost_start": result.cost0, "cost": result.cost,
               "evaluations": result.evaluations, "status": result.status, "sigma_si": fit.sigma},
    )
    return ds


def fit_figure(ds, path: Path) -> Path:
    """Data, start and fitted model at every measured site (one panel each)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sites = ds["site"].values
    fig, axes = plt.subplots(len(sites), 1, figsize=(7, 1.6 * len(sites) + 0.6), sharex=True, squeeze=False)
    t = ds["time"].values * 1e3
    for ax, site in zip(axes[:, 0], sites):
        sel = dict(site=site)
        ax.plot(t, ds["data"].sel(sel), ".", ms=2, color="0.5", label="data")
        ax.plot(t, ds["model_start"].sel(sel), "--", lw=1, color="tab:orange", label="start")
        ax.plot(t, ds["model_fit"].sel(sel), lw=1.2, color="tab:blue", label="fit")
        ax.set_ylabel(f"site {site}\n({ds['data'].attrs['units']})")
    axes[0, 0].legend(loc="upper right", fontsize=7, ncol=3)
    axes[-1, 0].set_xlabel("time (ms)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def design_figure(dp, x_start: np.ndarray, x_best: np.ndarray, path: Path) -> Path:
    """Before/after: the design profile of each per-element variable and each objective term's
    observable over time (force on the region, or its kinetic energy), start vs best."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    profiles = [v for v in dp.design.variables if v.target is not None]
    n_rows = len(profiles) + len(dp.objective.terms)
    fig, axes = plt.subplots(n_rows, 1, figsize=(7, 2.2 * n_rows + 0.4), squeeze=False)
    row = 0
    for var in profiles:
        ax = axes[row, 0]
        for x, style, label in ((x_start, "--", "start"), (x_best, "-", "best")):
            values = element_profile(dp, x, var)
            ax.plot(np.arange(values.size), values, style, marker=".", label=label)
        ax.set_xlabel({"x": "unit (column)", "y": "row"}[var.axis])
        ax.set_ylabel(var.target)
        ax.legend(fontsize=7)
        row += 1
    sc = dp.problem.system.scales
    t = dp.traj.times * sc.time_s * 1e3
    recs = {"start": dp.records(x_start), "best": dp.records(x_best)}
    raws = {"start": dp.design.raw(x_start), "best": dp.design.raw(x_best)}
    for term in dp.objective.terms:
        ax = axes[row, 0]
        for label, style in (("start", "--"), ("best", "-")):
            rec, raw = recs[label], raws[label]
            if term.spec.kind == "peak_force":
                y = rec.f[:, term.cols].sum(axis=1) * term.to_si
                ax.set_ylabel("force on region (N)")
            else:
                minv = raw.minv[term.dofs]
                mass = np.where(minv > 0, 1.0 / np.where(minv > 0, minv, 1.0), 0.0)
                y = 0.5 * (rec.v[:, term.cols] ** 2 * mass).sum(axis=1) * sc.energy
                ax.set_ylabel("kinetic energy\nof region (J)")
            ax.plot(t, y, style, lw=1, label=label)
        ax.set_title(f"{term.spec.kind} (p = {term.spec.sharpness:g} norm over time): start {_fmt(dp, term, recs['start'], raws['start'])}, "
                     f"best {_fmt(dp, term, recs['best'], raws['best'])}", fontsize=9)
        ax.set_xlabel("time (ms)")
        ax.legend(fontsize=7)
        row += 1
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _fmt(dp, term, rec, raw) -> str:
    from flexmm.design.objectives import UNITS

    return f"{term.value(rec, raw, dp.objective.times)[0] * term.to_si:.4g} {UNITS[term.spec.kind]}"


def element_profile(dp, x: np.ndarray, var) -> np.ndarray:
    """Per-unit values of a per-element variable in the design ``x`` (SI)."""
    from flexmm.design.variables import spline_values

    from flexmm.design.variables import profile_lines

    vals = dp.design.split(x)[dp.design.variables.index(var)]
    n = len(profile_lines(dp.design.base["lattice"], var.axis))
    if var.profile == "spline":
        return spline_values(vals, n)
    return np.linspace(vals[0], vals[-1], n)
