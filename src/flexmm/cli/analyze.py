"""``flexmm analyze RUN_DIR [RUN_DIR ...]``: measure runs and print them against theory.

A sweep directory (``flexmm sweep`` output) is summarised instead: its combined dataset is
tabulated and plotted against the varied parameters, with theory curves where available.

Exit status: 0 when every run was measured, 1 when some run has no pulse/front/drive to
measure, 2 for user errors (missing run directory, unknown field or analysis).
"""

from __future__ import annotations

import csv
import io
import math
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from flexmm.cli.common import EXIT_FAILED_RUN, EXIT_USER_ERROR, error, writing

if TYPE_CHECKING:
    from rich.table import Table


def _fmt(x) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "—"
    return f"{x:.4g}"


def _rel(x) -> str:
    return "—" if x is None else f"{100 * x:+.2f} %"


def run_table(res) -> Table:
    """Measured against predicted for one run."""
    from rich.table import Table

    t = Table(title=f"{res.name} — {res.ctx.model}, {res.kind} analysis of {res.view.spec}",
              title_justify="left", header_style="bold")
    for col, just in (("item", "left"), ("quantity", "left"), ("measured", "right"),
                      ("predicted", "right"), ("rel. diff", "right"), ("units", "left"), ("note", "left")):
        t.add_column(col, justify=just, overflow="fold")
    for c in res.comparisons:
        t.add_row(c.item, c.quantity, _fmt(c.measured), _fmt(c.predicted), _rel(c.rel_diff), c.units, c.note)
    return t


def energy_line(res) -> str | None:
    e = res.energy
    if e is None:
        return None
    work = f"work {e.work_j:.4g} J" if e.work_recorded else f"work {e.work_j:.4g} J (inferred: prescribed drive)"
    check = (f"; balance error ≤ {100 * e.max_relative_balance_error:.2g} %" if e.work_recorded else "")
    return (f"energy: initial {e.initial_total_j:.4g} J, {work}, final kinetic "
            f"{e.final_kinetic_j:.4g} J + potential {e.final_potential_j:.4g} J, dissipated "
            f"{e.dissipated_j:.4g} J{check}")


SUMMARY = {
    "pulse": ("amplitude", "speed", "width W (sech fit)"),
    "front": ("speed", "width 10–90 %", "distance"),
    "driven": ("drive frequency", "transmission", "decay per site"),
    "modes": ("speed", "polarisation"),
}


def summary_tables(results) -> list[Table]:
    """Per analysis kind, one line per run and feature with the headline numbers side by side."""
    from rich.table import Table

    tables = []
    for kind, quantities in SUMMARY.items():
        rows = [r for r in results if r.kind == kind]
        if not rows:
            continue
        t = Table(title=f"{kind} runs", title_justify="left", header_style="bold")
        for col in ("run", "field", "item"):
            t.add_column(col)
        for q in quantities:
            for col in (q, "predicted", "rel. diff"):
                t.add_column(col, justify="right")
        for r in rows:
            by_item: dict[str, dict] = {}
            for c in r.comparisons:
                by_item.setdefault(c.item, {})[c.quantity] = c
            for item, qs in by_item.items():
                cells = []
                for q in quantities:
                    c = qs.get(q)
                    cells += [_fmt(c.measured if c else None), _fmt(c.predicted if c else None),
                              _rel(c.rel_diff if c else None)]
                t.add_row(r.name, r.view.spec, item, *cells)
        tables.append(t)
    return tables


def _write_text(target: str, text: str) -> None:
    if target == "-":
        sys.stdout.write(text)
    else:
        with writing(target):
            Path(target).write_text(text)


def _csv_text(results) -> str:
    from flexmm.analysis.report import export as out_ds

    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=out_ds.CSV_COLUMNS)
    w.writeheader()
    w.writerows(out_ds.csv_rows(results))
    return buf.getvalue()


#: the command-line option of each field of ``AnalysisOptions``
OPTION_OF = {"kind": "analysis", "field": "field", "row": "row", "threshold_fraction": "threshold", "jump": "jump"}


def analysis_options(**given):
    """The ``AnalysisOptions`` of the options given (None: not given), validated like a config
    (a mistake names the option, the field and what was expected: a ConfigError)."""
    from flexmm.config.analysis import AnalysisOptions
    from flexmm.config.loader import validate

    data = {f: given[o] for f, o in OPTION_OF.items() if given[o] is not None}
    lines = {(f,): f"--{OPTION_OF[f]} {v}" for f, v in data.items()}
    return validate(AnalysisOptions, data, lines=lines, source="flexmm analyze")


def _spectra(runs, options, console, wrote) -> None:
    """``--spectrum``: the ω–k spectrum of each run, a line of what it holds and its figure."""
    from flexmm.analysis.report import figures as plots
    from flexmm.analysis.report import analyze as report
    from flexmm.analysis.context import RunContext
    from flexmm.analysis.measure.dispersion_spectrum import run_spectrum

    for r in runs:
        ds = report.open_dataset(r)
        try:
            spec = run_spectrum(RunContext.from_dataset(ds), options.field, options.row)
        except ValueError as exc:  # an unknown field (FieldError) or frames that are not uniform
            raise error(f"{r}: {exc}") from None
        shape = " × ".join(str(n) for n in spec.power.shape[1:])
        line = (f"{r}: ω–k spectrum of {spec.field}: {spec.power.shape[0]} frequencies × {shape} wavenumbers "
                f"(Δω = {spec.d_omega:.4g} rad/s, Δk = {spec.k[0][1] - spec.k[0][0]:.4g} rad/site); {spec.note}")
        fraction = spec.band_power_fraction()
        if fraction == fraction:  # bands were drawn (NaN: none)
            line += f"; {fraction:.1%} of the power within 2 frequency bins of them"
        console.print(line)
        where = Path(r) if Path(r).is_dir() else Path(r).parent
        with writing(where):
            wrote(plots.omega_k(spec, where / f"spectrum_{spec.field.replace(':', '_')}.png", title=spec.field))


def analyze(
    runs: list[str] = typer.Argument(..., help="Run directories (or dataset.nc files)."),
    field: str = typer.Option(None, "--field", "-f", help="Field: theta, u, u_dot, strain[:NAME], velocity[:NAME]."),
    analysis: str = typer.Option("auto", "--analysis", "-a", help="auto, pulse, front, driven or modes (oblique plane waves on a skew-periodic sheet)."),
    row: int = typer.Option(None, "--row", help="Row of a 2D lattice to analyse (default: middle)."),
    threshold: float = typer.Option(None, "--threshold",
                                    help="Pulse detection level, fraction of the peak, 0.01 to 1 (default 0.25)."),
    jump: float = typer.Option(None, "--jump", help="Well-to-well jump of a front (default: measured)."),
    json_out: str = typer.Option(None, "--json", help="Write a JSON summary to this file ('-': stdout)."),
    csv_out: str = typer.Option(None, "--csv", help="Write the measured/predicted table as CSV ('-': stdout)."),
    plot: bool = typer.Option(False, "--plot", help="Write PNG figures beside each run."),
    plot_dir: str = typer.Option(None, "--plot-dir",
                                 help="Where figures over several runs go (default: their common parent)."),
    save: bool = typer.Option(True, "--save/--no-save", help="Write analysis.nc beside each run."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Only print the paths of the files written."),
    allow_partial: bool = typer.Option(False, "--allow-partial",
                                       help="Also measure failed or interrupted runs (flagged; exit 1)."),
    spectrum: bool = typer.Option(False, "--spectrum",
                                  help="Instead: the ω–k power spectrum of the field (default: the displacement; "
                                       "ω–k_x–k_y on a sheet) with the model's linear bands, as spectrum_FIELD.png "
                                       "beside each run."),
) -> None:
    """Measure pulses, fronts or driven response of runs and compare with theory.

    Failed and interrupted runs are not measured unless --allow-partial; either way the exit
    status is then 1.
    """
    from rich.console import Console

    from flexmm.analysis.report import export as out_ds
    from flexmm.analysis.report import analyze as report
    from flexmm.io.identify import SWEEP, file_kind
    from flexmm.sweep import is_sweep

    if plot:  # matplotlib only when figures are asked for (it costs more than the demo's analysis)
        from flexmm.analysis.report import figures as plots

    options = analysis_options(analysis=analysis, field=field, row=row, threshold=threshold, jump=jump)
    data_to_stdout = json_out == "-" or csv_out == "-"
    console = Console(stderr=data_to_stdout, highlight=False, quiet=quiet)

    def wrote(path) -> None:
        if quiet:
            typer.echo(str(path), err=data_to_stdout)
        else:
            console.print(f"wrote {path}")

    sweeps = [r for r in runs if is_sweep(r) or file_kind(r) == SWEEP]  # a sweep.nc of any name
    for s in sweeps:
        _sweep_summary(s, plot_dir, console, wrote)
    runs = [r for r in runs if r not in sweeps]
    if not runs:
        return
    if spectrum:
        _spectra(runs, options, console, wrote)
        return
    status = {r: report.run_status(r) for r in runs}  # RunNotFound (a user error) before any work
    results, errors = [], []
    for r in runs:
        state, why = status[r]
        if state != "finished":
            note = f"{state} run ({why or 'no reason recorded'})"
            if not allow_partial:
                msg = f"{note}: not measured (--allow-partial measures it anyway)"
                if quiet:
                    typer.echo(f"{r}: {msg}", err=True)
                console.print(f"[bold red]{r}[/]: {msg}")
                errors.append({"run": str(r), "error": msg})
                continue
            label, tail = (("INACCURATE", "measured anyway") if state == "inaccurate"
                           else ("PARTIAL", "measured on the frames it kept"))
            console.print(f"[bold yellow]{r}: {label}[/] {note}: {tail}")
            errors.append({"run": str(r), "error": f"{label.lower()}: {note}"})
        try:
            res = report.analyze_with(r, options)
        except (report.PulseNotFound, report.FrontNotFound, report.NotDriven, report.NoWaveGroups,
                report.RestStateMissing) as exc:
            if quiet:
                typer.echo(f"{r}: {exc}", err=True)
            console.print(f"[bold red]{r}[/]: {exc}")
            errors.append({"run": str(r), "error": str(exc)})
            continue
        except ValueError as exc:  # an unknown field (FieldError) or an analysis that does not apply to the run
            raise error(f"{r}: {exc}") from None
        results.append(res)
        console.print(run_table(res))
        line = energy_line(res)
        if line:
            console.print(line)
        with writing(r):
            if save:
                wrote(out_ds.write_dataset(res))
            if plot:
                for p in plots.run_figures(res):
                    wrote(p)
    if len(results) > 1:
        for table in summary_tables(results):
            console.print(table)
    bands = report.sweep_bands(results)
    if bands:
        fmt = lambda bs: ", ".join(f"{lo:.4g}–{hi:.4g} Hz" for lo, hi in bs) or "none"  # noqa: E731
        console.print(f"pass bands (transmission ≥ {bands['pass_level']:.0%} of max) over "
                      f"{len(bands['frequencies_hz'])} drive frequencies: measured {fmt(bands['measured_hz'])}; "
                      f"linear theory {fmt(bands['predicted_hz'])}")
    if plot and results:
        parents = [str(Path(r.path).resolve().parent) for r in results]
        where = Path(plot_dir) if plot_dir else Path(os.path.commonpath(parents))
        with writing(where):
            for p in plots.set_figures(results, where):
                wrote(p)
    if json_out:
        _write_text(json_out, out_ds.to_json(results, errors, bands=bands))
        if quiet and json_out != "-":
            wrote(json_out)
    if csv_out:
        _write_text(csv_out, _csv_text(results))
        if quiet and csv_out != "-":
            wrote(csv_out)
    if errors:
        raise typer.Exit(EXIT_FAILED_RUN)


def _sweep_summary(sweep_dir: str, plot_dir: str | None, console, wrote) -> None:
    """Print a sweep's combined observables and plot them against the varied parameters."""
    from rich.table import Table

    from flexmm.sweep import open_sweep, plot_sweep

    try:
        ds = open_sweep(sweep_dir)
    except FileNotFoundError as exc:  # not a finished sweep
        raise error(str(exc)) from None
    names = [v for v in ("speed", "speed_theory", "amplitude", "width", "status") if v in ds]
    table = Table(title=f"sweep {sweep_dir}", title_justify="left", header_style="bold")
    flat = ds[names].to_dataframe().reset_index()
    for col in flat.columns:
        table.add_column(str(col), justify="right")
    for _, row in flat.iterrows():
        table.add_row(*(v if isinstance(v, str) else _fmt(v) for v in row.tolist()))
    console.print(table)
    folder = Path(sweep_dir) if Path(sweep_dir).is_dir() else Path(sweep_dir).parent  # a sweep.nc: beside it
    target = Path(plot_dir or folder) / "sweep.png"
    with writing(target.parent):
        target.parent.mkdir(parents=True, exist_ok=True)
        wrote(plot_sweep(sweep_dir, target))


__all__ = ["analyze", "EXIT_USER_ERROR"]
