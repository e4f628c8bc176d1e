"""Files written by ``flexmm fit`` and ``flexmm design``: datasets, the result as a scene, figures."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from flexmm.design.objectives import kinetic
from flexmm.design.variables import element_values, unit_field
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
    """Before/after: the design profile of each per-element variable (a 2D field: start and best
    maps), each objective term's observable over time (force on the region, or its kinetic
    energy; a share: the region's and the reference's), start vs best, and on a sheet with an
    energy objective the time-mean kinetic energy of every unit, start and best, regions outlined."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    profiles = [v for v in dp.design.variables if v.target is not None]
    energy_terms = [t for t in dp.objective.terms if not t.reads_forces]
    sheet_map = bool(energy_terms) and dp.problem.system.site_grid()[1].max() > 0
    n_rows = len(profiles) + len(dp.objective.terms) + int(sheet_map)
    fig = plt.figure(figsize=(9, 2.5 * n_rows + 0.4))
    grid = fig.add_gridspec(n_rows, 2)
    r = 0
    lattice = dp.design.base["lattice"]
    for var in profiles:
        fields = [unit_field(dp.design, var, dp.design.split(x)[dp.design.variables.index(var)])
                  for x in (x_start, x_best)]
        if fields[0] is not None:  # a sheet's map (a hinge target of profile each: each unit's hinges' mean)
            lo, hi = min(f.min() for f in fields), max(f.max() for f in fields)
            for k, (f, label) in enumerate(zip(fields, ("start", "best"))):
                ax = fig.add_subplot(grid[r, k])
                im = ax.imshow(f, origin="lower", aspect="auto", vmin=lo, vmax=hi, cmap="viridis")
                hinges = " of its hinges" if var.profile == "each" and f.size != var.size else ""
                ax.set_title(f"{var.target}{hinges} ({label}; mean {f.mean():.4g})", fontsize=9)
                ax.set_xlabel("column")
                ax.set_ylabel("row")
                _outline(ax, dp)
            fig.colorbar(im, ax=ax)
        else:
            ax = fig.add_subplot(grid[r, :])
            for x, style, label in ((x_start, "--", "start"), (x_best, "-", "best")):
                values = element_values(lattice, var, dp.design.split(x)[dp.design.variables.index(var)])
                ax.plot(np.arange(values.size), values, style, marker=".", label=label)
            ax.set_xlabel("element" if var.profile == "each" else {"x": "unit (column)", "y": "row"}[var.axis])
            ax.set_ylabel(var.target)
            ax.legend(fontsize=7)
        r += 1
    sc = dp.problem.system.scales
    t = dp.traj.times * sc.time_s * 1e3
    recs = {"start": dp.records(x_start), "best": dp.records(x_best)}
    raws = {"start": dp.design.raw(x_start), "best": dp.design.raw(x_best)}
    for term in dp.objective.terms:
        ax = fig.add_subplot(grid[r, :])
        for label, style in (("start", "--"), ("best", "-")):
            rec, raw = recs[label], raws[label]
            if term.reads_forces:
                ax.plot(t, rec.f[:, term.cols].sum(axis=1) * term.to_si, style, lw=1, label=label)
                ax.set_ylabel("force on region (N)")
                continue
            ax.plot(t, kinetic(rec, raw, term.cols, term.dofs)[2] * sc.energy, style, lw=1, color="tab:blue",
                    label=f"region, {label}")
            if term.ref_cols is not None:
                ax.plot(t, kinetic(rec, raw, term.ref_cols, term.ref_dofs)[2] * sc.energy, style, lw=1,
                        color="tab:gray", label=f"reference, {label}")
            ax.set_ylabel("kinetic energy (J)")
        v0, v1 = (term.value(recs[k], raws[k], dp.objective.times)[0] for k in ("start", "best"))
        how = f" (p = {term.spec.sharpness:g} norm over time)" if term.spec.kind.startswith("peak") else ""
        ax.set_title(f"{term.spec.kind}{how}: start {_fmt(dp, term, recs['start'], raws['start'])}, "
                     f"best {_fmt(dp, term, recs['best'], raws['best'])} (x{v1 / v0 if v0 else np.nan:.3g})", fontsize=9)
        ax.set_xlabel("time (ms)")
        ax.legend(fontsize=7)
        r += 1
    if sheet_map:
        maps = [_mean_energy_map(dp, x) * sc.energy for x in (x_start, x_best)]
        top = max(m.max() for m in maps)
        for k, (m, label) in enumerate(zip(maps, ("start", "best"))):
            ax = fig.add_subplot(grid[r, k])
            im = ax.imshow(m, origin="lower", aspect="auto", vmin=0.0, vmax=top, cmap="magma")
            ax.set_title(f"time-mean kinetic energy per unit ({label})", fontsize=9)
            ax.set_xlabel("column")
            ax.set_ylabel("row")
            _outline(ax, dp)
        fig.colorbar(im, ax=ax, label="J")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _outline(ax, dp) -> None:
    """Outline the objective's regions (and references) on a sheet map."""
    from matplotlib.patches import Rectangle

    col, row = dp.problem.system.site_grid()
    for term in dp.objective.terms:
        for dofs, color in ((term.dofs, "white"), (term.ref_dofs, "0.6")):
            if dofs is None:
                continue
            sites = np.unique(np.asarray(dofs) % dp.problem.system.n_sites)
            c, rr = col[sites], row[sites]
            ax.add_patch(Rectangle((c.min() - 0.5, rr.min() - 0.5), c.max() - c.min() + 1, rr.max() - rr.min() + 1,
                                   fill=False, ec=color, lw=1))


def _mean_energy_map(dp, x: np.ndarray) -> np.ndarray:
    """(rows, cols) time-mean kinetic energy of every unit over the design's run (model units)."""
    from flexmm.design.gradient import Trajectory

    s = dp.problem.system
    tr = dp.traj
    full = Trajectory(tr.args, tr.terms, tr.h, tr.nsteps, tr.stride, np.arange(s.ndof), tr.t0,
                      integrator=tr.integrator)
    raw = dp.design.raw(x)
    rec, _ = full.run(raw, segment=tr.nsteps + 1)
    mass = np.where(raw.minv > 0, 1.0 / np.where(raw.minv > 0, raw.minv, 1.0), 0.0)
    e = 0.5 * (rec.v**2 * mass).mean(axis=0)
    per_site = e[: len(s.fields) * s.n_sites].reshape(len(s.fields), s.n_sites).sum(axis=0)
    col, row = s.site_grid()
    out = np.zeros((row.max() + 1, col.max() + 1))
    np.add.at(out, (row, col), per_site)
    return out


def _fmt(dp, term, rec, raw) -> str:
    from flexmm.design.objectives import UNITS

    unit = UNITS[term.spec.kind]
    return f"{term.value(rec, raw, dp.objective.times)[0] * term.to_si:.4g}" + (f" {unit}" if unit != "1" else "")
