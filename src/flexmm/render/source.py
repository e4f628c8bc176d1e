"""Read a run's dataset for rendering: attributes, coordinates, and frames streamed in blocks.

The file is opened once (h5netcdf) and site fields are read a block of frames at a time, so a
long run is never loaded whole; ``RunSource.frames`` yields one frame at a time.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Self

import numpy as np

from flexmm.errors import UsageError
from flexmm.io.identify import run_dataset
from flexmm.io.run_dataset import REST_SUFFIX, SHAPE_VARIABLES

#: bytes of field data read per block of frames
BLOCK_BYTES = 16 * 2**20


def _text(value) -> str:
    return value.decode() if isinstance(value, bytes) else str(value)


class _Variable:
    """An xarray variable read through the part of h5netcdf's interface ``RunSource`` uses."""

    def __init__(self, var):
        self.var = var
        self.dimensions = tuple(var.dims)
        self.attrs = dict(var.attrs)

    def __getitem__(self, key) -> np.ndarray:
        return np.asarray(self.var.values[key])


class _InMemory:
    """A run's ``xarray.Dataset`` in memory, read like the open file (``attrs``, ``variables``)."""

    def __init__(self, ds):
        self.attrs = dict(ds.attrs)
        self.variables = {str(name): _Variable(var) for name, var in ds.variables.items()}

    def close(self) -> None:
        pass


class RunSource:
    """A run's dataset opened for reading frames (use as a context manager): a run directory, its
    dataset.nc, or the run's ``xarray.Dataset`` in memory."""

    def __init__(self, path):
        if hasattr(path, "data_vars"):  # an xarray.Dataset
            self.path = Path(path.encoding.get("source") or "<in memory>/dataset.nc")
            self.file = _InMemory(path)
        else:
            import h5netcdf

            self.path, _ = run_dataset(path)  # RunNotFound saying what the file is if it is not a run's dataset
            try:
                self.file = h5netcdf.File(self.path, "r")
            except (OSError, ValueError) as exc:
                raise UsageError(f"cannot read {self.path}: not a readable flexmm dataset ({exc})") from None
        f = self.file
        self.attrs = {k: _text(v) if isinstance(v, (str, bytes)) else v for k, v in f.attrs.items()}
        if "time" not in f.variables or "site" not in f.variables:
            raise UsageError(f"{self.path} is not a flexmm run dataset (no time or site)")
        self.time = np.asarray(f.variables["time"][...], float)
        self.sites = np.asarray(f.variables["site"][...], np.int64)
        self.fields = [name for name, var in f.variables.items() if var.dimensions == ("time", "site")]
        self.coords = {name: np.asarray(var[...]) for name, var in f.variables.items()
                       if var.dimensions == ("site",) and name != "site"}
        #: the units' shapes and joints, where the model stores them (io.run_dataset.shape_variables)
        self.shapes = {name: np.asarray(f.variables[name][...]) for name in SHAPE_VARIABLES if name in f.variables}
        # the rest state of the fields measured from the reference configuration, where it is not
        # zero (a predeformed run); fields measured from the rest state (mass models) need none
        self.rest = {name[: -len(REST_SUFFIX)]: np.asarray(v, float) for name, v in self.coords.items()
                     if name.endswith(REST_SUFFIX) and np.any(v)
                     and self._reference(name[: -len(REST_SUFFIX)]) == "absolute"}
        if self.time.size == 0:
            raise UsageError(f"{self.path}: the run wrote no frames ({self.status_line()})")

    # ------------------------------------------------------------ attributes
    @property
    def config_text(self) -> str:
        """The resolved scene (YAML) stored with the run."""
        return str(self.attrs.get("config", ""))

    @property
    def model(self) -> str:
        """The model kind (attribute ``model``)."""
        return str(self.attrs.get("model", "unknown"))

    @property
    def name(self) -> str:
        """The scene's name (attribute ``title``, else the run directory)."""
        return str(self.attrs.get("title") or self.path.parent.name)

    @property
    def status(self) -> str:
        """'finished', 'failed' or 'interrupted'."""
        return str(self.attrs.get("status", "finished"))

    @property
    def reason(self) -> str:
        """Why a run failed or was interrupted ('' if it finished)."""
        return str(self.attrs.get("status_reason", ""))

    def status_line(self) -> str:
        """'' for a finished run, else e.g. 'INTERRUPTED: interrupted by SIGINT at t = ...'."""
        if self.status == "finished":
            return ""
        return f"{self.status.upper()}" + (f": {self.reason}" if self.reason else "")

    def _reference(self, name: str) -> str:
        """What field ``name`` is measured from ('absolute' in datasets that do not say)."""
        var = self.file.variables.get(name)
        return "absolute" if var is None else _text(var.attrs.get("reference", "absolute"))

    def units(self, name: str) -> str:
        """Units of a variable ('' if none)."""
        return _text(self.file.variables[name].attrs.get("units", "")) if name in self.file.variables else ""

    # ------------------------------------------------------------ time selection
    def _slack(self) -> float:
        return 0.5 * float(np.median(np.diff(self.time))) if self.time.size > 1 else 0.0

    def check_time(self, t: float, option: str) -> None:
        """UsageError if ``t`` lies outside the run's frames (half a frame interval of slack)."""
        lo, hi, eps = self.time[0], self.time[-1], self._slack()
        if not (math.isfinite(t) and lo - eps <= t <= hi + eps):
            tail = f" ({self.status} run)" if self.status != "finished" else ""
            raise UsageError(f"{option} {t:.6g} s is outside the run: its frames span "
                             f"{lo:.6g} s to {hi:.6g} s{tail}")

    def index_at(self, t: float) -> int:
        """Index of the frame nearest ``t`` (checked against the run's span)."""
        self.check_time(t, "--time")
        return int(np.argmin(np.abs(self.time - t)))

    def window(self, start: float | None, stop: float | None) -> np.ndarray:
        """Frame indices with start ≤ t ≤ stop (defaults: the whole run)."""
        lo = self.time[0] if start is None else start
        hi = self.time[-1] if stop is None else stop
        if start is not None:
            self.check_time(start, "--start")
        if stop is not None:
            self.check_time(stop, "--stop")
        if hi < lo:
            raise UsageError(f"--stop {hi:.6g} s is before --start {lo:.6g} s")
        eps = 1e-9 * max(abs(self.time[-1]), 1e-300)
        idx = np.flatnonzero((self.time >= lo - eps) & (self.time <= hi + eps))
        if idx.size == 0:
            idx = np.array([int(np.argmin(np.abs(self.time - lo)))])
        return idx

    # ------------------------------------------------------------ fields
    def require(self, names) -> None:
        """UsageError naming the fields the run did not save."""
        missing = [n for n in names if n not in self.fields]
        if missing:
            raise UsageError(f"{self.path}: the run did not save {', '.join(missing)} (saved: "
                             f"{', '.join(self.fields) or 'no site fields'}); rerun with output.fields "
                             "including them")

    def read(self, names, i0: int, i1: int) -> dict[str, np.ndarray]:
        """Fields ``names`` of frames i0..i1−1, each (i1 − i0, n_site)."""
        return {n: np.asarray(self.file.variables[n][i0:i1, :], float) for n in names}

    def frames(self, indices, names):
        """Yield (index, time s, {name: (n_site,)}) for the given increasing frame indices,
        reading contiguous blocks of at most BLOCK_BYTES."""
        indices = np.asarray(indices, np.int64)
        per_frame = 8 * max(1, self.sites.size * max(1, len(names)))
        span = max(1, BLOCK_BYTES // per_frame)
        k = 0
        while k < indices.size:
            i0 = int(indices[k])
            j = int(np.searchsorted(indices, i0 + span, side="left"))
            j = max(j, k + 1)
            i1 = int(indices[j - 1]) + 1
            block = self.read(names, i0, i1)
            for i in indices[k:j]:
                yield int(i), float(self.time[i]), {n: block[n][i - i0] for n in names}
            k = j

    def close(self) -> None:
        """Close the file."""
        self.file.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


__all__ = ["RunSource"]
