"""What a file handed to ``flexmm analyze`` / ``render`` is, and a message when it is not a run.

flexmm writes three kinds of netCDF file: a run's ``dataset.nc`` (``flexmm run``: ``time`` and
``site`` variables, the resolved scene in the ``config`` attribute, the model in ``model``;
the tests' synthetic datasets have the same layout with ``model`` only), an ``analysis.nc``
(``flexmm analyze``: attributes ``analysis`` and ``source``, the run it measured) and a sweep's
``sweep.nc`` (``flexmm sweep``: attribute ``sweep_spec``). ``kind_of`` tells them apart from
the attributes and variable names alone (read with h5py, no data loaded); anything else that
opens is ``foreign``. ``run_dataset(path)`` is the one gate of the reading commands: it returns
the dataset of a run directory (or the file itself) when it is a run's dataset, and otherwise
raises ``RunNotFound`` saying what the file is and what was expected — a missing path, a
directory without a dataset (a sweep directory named as such), a file that is not netCDF/HDF5
or is truncated, another flexmm file, a foreign netCDF.
"""

from __future__ import annotations

from pathlib import Path

from flexmm.errors import FlexmmError

RUN, ANALYSIS, SWEEP, FOREIGN = "run", "analysis", "sweep", "foreign"
#: what a reading command expects, for the messages
EXPECTED = "expected a run directory or its dataset.nc (written by `flexmm run`)"


class RunNotFound(FlexmmError):
    """The path is not a run directory (no dataset.nc), or its file is not a readable run dataset."""


def _text(value) -> str:
    return value.decode(errors="replace") if isinstance(value, bytes) else str(value)


def _is_sweep_dir(p: Path) -> bool:
    return p.is_dir() and ((p / "sweep.nc").is_file() or (p / "points").is_dir() or (p / "store").is_dir())


def dataset_path(path: str | Path) -> Path:
    """``RUN_DIR/dataset.nc`` (or the file itself); RunNotFound naming what is missing."""
    p = Path(path)
    nc = p / "dataset.nc" if p.is_dir() else p
    if nc.is_file():
        return nc
    if _is_sweep_dir(p):
        raise RunNotFound(f"{p} is a sweep directory, not a run: `flexmm analyze {p}` summarises it; a point's "
                          f"run is in {p / 'points'}/<point>")
    partial = [q for q in (p.with_name(f"{p.name}.{s}") for s in ("interrupted", "failed", "inaccurate"))
               if (q / "dataset.nc").is_file()]
    hint = f" (an unfinished or inaccurate run is in {partial[0]})" if partial else ""
    what = "no dataset.nc in" if p.is_dir() else "no such run directory or file:"
    raise RunNotFound(f"{what} {p}{hint}")


def read_header(nc: Path) -> tuple[dict, set[str]]:
    """(global attributes, variable names) of a netCDF4/HDF5 file; RunNotFound if it
    cannot be opened (not HDF5, truncated, unreadable)."""
    import h5py

    try:
        with h5py.File(nc, "r") as f:
            attrs = {k: _text(v) if isinstance(v, (str, bytes)) else v for k, v in f.attrs.items()}
            variables = {name for name, obj in f.items() if isinstance(obj, h5py.Dataset)}
    except (OSError, ValueError, KeyError, RuntimeError) as exc:
        raise RunNotFound(f"cannot read {nc}: not a readable flexmm dataset: not a netCDF4/HDF5 file, "
                          f"or a truncated or damaged one ({exc}); {EXPECTED}") from None
    return attrs, variables


def kind_of(attrs: dict, variables: set[str]) -> str:
    """RUN, ANALYSIS, SWEEP or FOREIGN, from a file's header (``read_header``)."""
    if "sweep_spec" in attrs:
        return SWEEP
    if "analysis" in attrs and "source" in attrs:
        return ANALYSIS
    if ("config" in attrs or "model" in attrs) and "time" in variables and "site" in variables:
        return RUN
    return FOREIGN


def file_kind(path: str | Path) -> str | None:
    """``kind_of`` a file (None for a directory, a missing or an unreadable file)."""
    p = Path(path)
    if not p.is_file():
        return None
    try:
        return kind_of(*read_header(p))
    except RunNotFound:
        return None


def _foreign(nc: Path, attrs: dict, variables: set[str]) -> str:
    names = ", ".join(sorted(variables)[:8]) + (", ..." if len(variables) > 8 else "")
    return (f"{nc} is a netCDF file that flexmm did not write as a run (a run's has time and site "
            f"variables and the attributes config and model; this one holds: {names or 'no variables'})")


#: file kind -> what a file of that kind is, for a message: ``say(nc, attrs, variables)``
DESCRIPTIONS = {
    RUN: lambda nc, attrs, variables: "",
    ANALYSIS: lambda nc, attrs, variables: (f"{nc} is an analysis file (written by `flexmm analyze` from "
                                            f"{attrs.get('source')}), not a run's dataset"),
    SWEEP: lambda nc, attrs, variables: (
        f"{nc} is a sweep's combined dataset (written by `flexmm sweep`), not a run's dataset: "
        f"`flexmm analyze {nc}` summarises the sweep; its points' runs are in {nc.parent / 'points'}"),
    FOREIGN: _foreign,
}


def describe(nc: Path, kind: str, attrs: dict, variables: set[str]) -> str:
    """What the file is, for a message (a run's dataset: '')."""
    return DESCRIPTIONS[kind](nc, attrs, variables)


def run_dataset(path: str | Path) -> tuple[Path, dict]:
    """(the run's dataset file, its global attributes) for a run directory or dataset file;
    RunNotFound saying what the path is and what was expected when it is not a run's dataset."""
    nc = dataset_path(path)
    attrs, variables = read_header(nc)
    what = describe(nc, kind_of(attrs, variables), attrs, variables)
    if what:
        raise RunNotFound(f"{what}; {EXPECTED}")
    return nc, attrs


__all__ = ["ANALYSIS", "EXPECTED", "FOREIGN", "RUN", "RunNotFound", "SWEEP", "dataset_path", "describe", "file_kind", "kind_of",
           "read_header", "run_dataset"]
