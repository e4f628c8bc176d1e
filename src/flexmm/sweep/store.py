"""On-disk state of a sweep: one observables store with a status array, and the kept datasets.

Layout of a sweep directory::

    SWEEP_DIR/spec.json                 what was asked (axes, fixed overrides, base file)
    SWEEP_DIR/sweep.nc                  the combined dataset (written last, atomically)
    SWEEP_DIR/store/meta.json           the spec's fingerprint, number of points, observable names
    SWEEP_DIR/store/status.npy          uint8 per point: 0 pending, 1 finished, 2 failed
    SWEEP_DIR/store/observables.npy     float64 (point, observable), NaN where not measured
    SWEEP_DIR/store/note.npy            fixed-width UTF-8 per point: why a value is missing / why it failed
    SWEEP_DIR/store/label.npy           fixed-width UTF-8 (point, 3): kind, field and amplitude units measured
    SWEEP_DIR/store/leases/<i>.lease    who runs point i now (``flexmm.sweep.lease``), removed after it
    SWEEP_DIR/points/<h[:2]>/<h>/       a kept point's run (``keep:``), <h> = its config sha256
    SWEEP_DIR/work/<i>/                 checkpoints of point i while it runs (not kept), removed once it is stored

Points are numbered in C order over the sweep's shape (``SweepSpec.point_at``). The arrays are
laid out once, up front (sparse files), by the process that plans the sweep; afterwards every
worker writes only the byte ranges of its own points (``os.pwrite``), so no lock is needed and
two workers (or two processes running slices of one sweep) never touch the same bytes; two
workers handed the *same* point run it once, by its lease (``flexmm.sweep.lease``). A point's
values are written first and its status byte last, so a point killed at any instant stays
*pending* and is run again. Resuming reads status.npy alone: one byte per point.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from flexmm.errors import UsageError
from flexmm.io.atomic import write_text_atomic

DATASET = "dataset.nc"
RESULT = "sweep.nc"
STORE = "store"
#: the running points' checkpoints: SWEEP_DIR/work/<point>/
WORK = "work"
FINISHED, FAILED, PENDING = "finished", "failed", "pending"
#: status byte of each state (the order of STATES)
STATES = (PENDING, FINISHED, FAILED)
CODE = {s: np.uint8(i) for i, s in enumerate(STATES)}
NOTE_BYTES = 400  # a failure's reason or a missing value's note, UTF-8, cut to this length
LABEL_BYTES = 24  # kind, field, amplitude units
LABELS = ("kind", "field", "amplitude_units")


def write_json_atomic(path: Path, data: Any) -> None:
    """Write JSON to a hidden temporary file, fsync, then rename it into place."""
    write_text_atomic(path, json.dumps(data, indent=1, sort_keys=True, default=_plain))


def _plain(obj: Any):
    if hasattr(obj, "item"):
        return obj.item()
    return str(obj)


def dataset_status(path: Path) -> str | None:
    """The ``status`` attribute of a run dataset, or None if unreadable."""
    import h5py

    try:
        with h5py.File(path, "r") as f:
            s = f.attrs.get("status")
    except (OSError, KeyError):
        return None
    return s.decode() if isinstance(s, bytes) else (str(s) if s is not None else None)


def _fixed(text: str, n: int) -> bytes:
    """UTF-8, cut to at most n bytes on a character boundary."""
    return text.encode()[:n].decode(errors="ignore").encode()


@dataclass(frozen=True)
class _Array:
    """One .npy file of the store: where its data starts and how long a point's row is."""

    path: Path
    offset: int
    row_bytes: int


class SweepStore:
    """The sweep directory's files; the only code that knows their names and layout."""

    def __init__(self, root: str | Path):
        self.root = Path(root)
        self.points = self.root / "points"
        self.dir = self.root / STORE
        self._arrays: dict[str, _Array] | None = None

    # ------------------------------------------------------------ layout

    def point_dir(self, config_hash: str) -> Path:
        """A kept point's run directory, sharded by the hash's first two hex digits."""
        return self.points / config_hash[:2] / config_hash

    def work_dir(self, index: int) -> Path:
        """Where point ``index`` writes its checkpoints while it runs (``flexmm.sweep.worker``)."""
        return self.root / WORK / str(index)

    @property
    def result_path(self) -> Path:
        return self.root / RESULT

    def meta(self) -> dict | None:
        try:
            return json.loads((self.dir / "meta.json").read_text())
        except (OSError, ValueError):
            return None

    def exists(self) -> bool:
        return self.meta() is not None

    def create_or_check(self, fingerprint: str, n_points: int, observables: list[str], spec_name: str) -> bool:
        """Lay the store out for a spec (True), or check that the one there is the same spec's
        (False); a store of another spec is refused (``UsageError``)."""
        meta = self.meta()
        if meta is not None:
            self.check(fingerprint, n_points)
            if meta.get("observables") != list(observables):
                raise UsageError(f"{self.dir} measured other observables ({meta.get('observables')}); "
                                 "delete it to start over")
            return False
        self.dir.mkdir(parents=True, exist_ok=True)
        # the arrays first, the meta file last: a store without meta.json is laid out again
        for name, dtype, shape in self._shapes(n_points, len(observables)):
            arr = np.lib.format.open_memmap(self.dir / f".{name}.npy.tmp", mode="w+", dtype=dtype, shape=shape)
            if name == "observables":
                arr[...] = np.nan
            arr.flush()
            del arr
            os.replace(self.dir / f".{name}.npy.tmp", self.dir / f"{name}.npy")
        write_json_atomic(self.dir / "meta.json", {"fingerprint": fingerprint, "n_points": n_points,
                                                   "observables": list(observables), "spec_name": spec_name,
                                                   "states": list(STATES)})
        return True

    def check(self, fingerprint: str, n_points: int) -> None:
        """UsageError unless the store there (if any) holds the points of this spec."""
        meta = self.meta()
        if meta is not None and (meta.get("fingerprint") != fingerprint or meta.get("n_points") != n_points):
            raise UsageError(
                f"{self.root} holds the results of another sweep ({meta.get('spec_name')!r}, "
                f"{meta.get('n_points')} points): give another --out, or delete it to start over")

    @staticmethod
    def _shapes(n: int, n_obs: int):
        return [("status", np.uint8, (n,)), ("observables", np.float64, (n, n_obs)),
                ("note", f"S{NOTE_BYTES}", (n,)), ("label", f"S{LABEL_BYTES}", (n, len(LABELS)))]

    def _array_info(self) -> dict[str, _Array]:
        if self._arrays is None:
            out = {}
            for name in ("status", "observables", "note", "label"):
                a = np.load(self.dir / f"{name}.npy", mmap_mode="r")
                out[name] = _Array(self.dir / f"{name}.npy", a.offset, a.dtype.itemsize * int(np.prod(a.shape[1:])))
                del a
            self._arrays = out
        return self._arrays

    # ------------------------------------------------------------ reading

    def status(self) -> np.ndarray:
        """The status byte of every point (a copy); all pending if there is no store yet."""
        if not self.exists():
            return np.zeros(0, np.uint8)
        return np.load(self.dir / "status.npy")

    def state(self, index: int) -> str:
        """The state of one point, read from its status byte."""
        info = self._array_info()["status"]
        fd = os.open(info.path, os.O_RDONLY)
        try:
            return STATES[os.pread(fd, 1, info.offset + index)[0]]
        finally:
            os.close(fd)

    def read(self) -> dict[str, np.ndarray]:
        """Every array of the store (memory-mapped, read-only)."""
        return {name: np.load(self.dir / f"{name}.npy", mmap_mode="r")
                for name in ("status", "observables", "note", "label")}

    # ------------------------------------------------------------ writing (workers)

    def write_point(self, index: int, state: str, values: np.ndarray | None = None, note: str = "",
                    labels: tuple[str, str, str] = ("", "", "")) -> None:
        """Publish one point: its values, note and labels, then its status byte (last)."""
        info = self._array_info()
        obs = info["observables"]
        row = np.full(obs.row_bytes // 8, np.nan) if values is None else np.asarray(values, np.float64)
        self._pwrite(obs, index, row.tobytes())
        self._pwrite(info["note"], index, np.array([_fixed(note, NOTE_BYTES)], f"S{NOTE_BYTES}").tobytes())
        self._pwrite(info["label"], index,
                     np.array([_fixed(s, LABEL_BYTES) for s in labels], f"S{LABEL_BYTES}").tobytes())
        self._pwrite(info["status"], index, CODE[state].tobytes())

    def reset(self, indices) -> None:
        """Mark points pending again (before they are rerun)."""
        info = self._array_info()["status"]
        for i in indices:
            self._pwrite(info, int(i), CODE[PENDING].tobytes())

    @staticmethod
    def _pwrite(arr: _Array, index: int, data: bytes) -> None:
        assert len(data) == arr.row_bytes, (arr.path, len(data), arr.row_bytes)
        fd = os.open(arr.path, os.O_WRONLY)
        try:
            os.pwrite(fd, data, arr.offset + index * arr.row_bytes)
        finally:
            os.close(fd)


def spec_fingerprint(summary: dict, base_data: dict) -> str:
    """sha256 of what decides the points' configs (not how they are measured or kept)."""
    payload = {k: summary[k] for k in ("mode", "set", "vary")}
    payload["base"] = base_data
    return hashlib.sha256(json.dumps(payload, sort_keys=True, default=_plain).encode()).hexdigest()
