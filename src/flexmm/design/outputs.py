"""Files written by ``flexmm fit`` and ``flexmm design``: datasets, the result as a scene, figures."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from flexmm.io.atomic import atomic_target, write_text_atomic
from flexmm.io.provenance import provenance_attrs


def write_scene(data: dict, path: Path, header: str) -> Path:
    """A runnable scene YAML (``flexmm run PATH``) with a comment header."""
    text = "".join(f"# {line}\n" for line in header.splitlines()) + yaml.safe_dump(data, sort_keys=False)
    write_text_atomic(path, text)
    return path


def write_dataset(ds, path: Path, scene) -> Path:
    """netCDF (h5netcdf) with the scene's provenance attrs, written atomically."""
    ds.attrs.update(provenance_attrs(scene))
    with atomic_target(path) as tmp:
        ds.to_netcdf(tmp, engine="h5netcdf")
    return path


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
