"""CF-style metadata that every netCDF file flexmm writes carries (docs/architecture.md, "Datasets").

Globals: ``Conventions`` (CF-1.10) and ``history`` (one timestamped line per program that wrote
or rewrote the file, the command line included). Every variable, coordinates included, has
``long_name`` and ``units`` (``"1"`` for dimensionless numbers, counts, indices, flags and
text); the coordinates ``time``, ``x`` and ``y`` carry their CF ``axis``. Writers give units
and long names where they know them; ``describe`` fills the rest from the variable's name
(suffixes ``_m``, ``_s``, ``_m_s``, ``_hz``, ``_j``, ``_rad``, ...), so one set of rules
applies to the run dataset, analysis.nc, sweep.nc, workprecision.nc and the design and fit
histories alike. ``write_netcdf`` writes an xarray Dataset that way (atomically);
``DatasetWriter`` (the streaming run writer) uses the same functions.
"""

from __future__ import annotations

import shlex
import sys
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

CONVENTIONS = "CF-1.10"
DIMENSIONLESS = "1"

#: coordinate name -> CF axis
AXES = {"time": "T", "x": "X", "y": "Y"}

#: name suffix -> units, longest suffixes first (``_m_s`` before ``_s``)
SUFFIX_UNITS = (
    ("_n_m_per_rad", "N m/rad"), ("_n_s_per_m", "N s/m"), ("_n_m_s", "N m s"),
    ("_rad_per_s", "rad/s"), ("_rad_s", "rad/s"), ("_m_s", "m/s"), ("_n_per_m", "N/m"), ("_per_m", "1/m"),
    ("_kg_m2", "kg m2"), ("_n_m", "N m"), ("_kg", "kg"), ("_hz", "Hz"), ("_deg", "degree"),
    ("_rad", "rad"), ("_j", "J"), ("_n", "N"), ("_m", "m"), ("_s", "s"),
)


def units_from_name(name: str) -> str | None:
    """SI units a variable's name declares by its suffix (``speed_m_s`` -> ``m/s``), else None."""
    low = name.lower()
    for suffix, units in SUFFIX_UNITS:
        if low.endswith(suffix):
            return units
    return None


def variable_attrs(name: str, attrs: dict, dtype=None) -> dict:
    """``attrs`` completed with ``long_name``, ``units`` and (for time, x, y) ``axis``.

    Given values win; an empty ``units`` counts as missing. Missing units come from the name's
    suffix, else ``"1"`` (dimensionless; also for text and flags, which have no physical unit).
    """
    out = dict(attrs)
    if not out.get("long_name"):
        out["long_name"] = name.replace("_", " ")
    if not out.get("units"):
        kind = np.dtype(dtype).kind if dtype is not None else "f"
        out["units"] = (units_from_name(name) if kind in "fiuc" else None) or DIMENSIONLESS
    if name in AXES:
        out.setdefault("axis", AXES[name])
    return out


def history_line(argv: list[str] | None = None, when: datetime | None = None) -> str:
    """``<UTC time>: <command line>`` (the running program's arguments by default)."""
    argv = list(sys.argv if argv is None else argv)
    if argv:
        p = Path(argv[0])
        prog = p.parent.name if p.name == "__main__.py" else p.name  # python -m <package>
        argv[0] = "flexmm" if prog in ("cli", "flexmm") else prog
    stamp = (when or datetime.now(timezone.utc)).strftime("%Y-%m-%dT%H:%M:%SZ")
    return f"{stamp}: {shlex.join(argv) if argv else 'flexmm'}"


def global_attrs(previous_history: str | None = None) -> dict[str, str]:
    """``Conventions`` and ``history`` (this program's line appended to an earlier history)."""
    line = history_line()
    history = f"{previous_history.rstrip()}\n{line}" if previous_history else line
    return {"Conventions": CONVENTIONS, "history": history}


def describe(ds, previous_history: str | None = None):
    """``ds`` (an xarray Dataset, changed in place and returned) with the CF attrs of this module."""
    for name, var in ds.variables.items():
        var.attrs = variable_attrs(str(name), var.attrs, var.dtype)
    ds.attrs.update(global_attrs(previous_history or ds.attrs.get("history")))
    return ds


def write_netcdf(ds, path: str | Path, previous_history: str | None = None) -> Path:
    """Write ``ds`` to ``path`` (netCDF4 via h5netcdf) with CF metadata, atomically; its path."""
    from flexmm.io.atomic import atomic_target

    target = Path(path)
    with atomic_target(target) as tmp:
        describe(ds, previous_history).to_netcdf(tmp, engine="h5netcdf")
    return target
