"""On-disk state of a sweep: one run directory per point, named by its config hash.

Layout of a sweep directory::

    SWEEP_DIR/spec.yaml                 what was asked (axes, fixed overrides, base file)
    SWEEP_DIR/sweep.nc                  the combined dataset (written last, atomically)
    SWEEP_DIR/points/<sha256>/          one scene; <sha256> = flexmm.io.provenance.config_hash
        point.json                      its varied values (written before the run starts)
        dataset.nc config.yaml run.log  what `flexmm run` writes
        done.json                       finished marker, written last (atomic), with observables
        error.json                      failed marker: the error or blow-up reason

A point is *finished* only if done.json exists and dataset.nc carries ``status = finished``;
*failed* if error.json exists; anything else (including a run killed at any instant) is
*pending* and is cleaned and rerun. Every file is published by an atomic rename, so an
interrupted sweep never leaves a point that looks finished but is not.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from flexmm.io.atomic import write_text_atomic

DONE = "done.json"
ERROR = "error.json"
POINT = "point.json"
DATASET = "dataset.nc"
RESULT = "sweep.nc"
FINISHED, FAILED, PENDING = "finished", "failed", "pending"


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


class SweepStore:
    """Point directories under ``root/points``; the only code that knows the file names."""

    def __init__(self, root: str | Path):
        self.root = Path(root)
        self.points = self.root / "points"

    def point_dir(self, config_hash: str) -> Path:
        return self.points / config_hash

    def state(self, config_hash: str) -> str:
        d = self.point_dir(config_hash)
        if (d / DONE).is_file() and dataset_status(d / DATASET) == FINISHED:
            return FINISHED
        if (d / ERROR).is_file():
            return FAILED
        return PENDING

    def read(self, config_hash: str, marker: str) -> dict:
        try:
            return json.loads((self.point_dir(config_hash) / marker).read_text())
        except (OSError, ValueError):
            return {}

    @property
    def result_path(self) -> Path:
        return self.root / RESULT


def clean_point(d: Path, *, keep_dataset: bool = False) -> None:
    """Remove markers, temporary files and (unless keep_dataset) an unfinished dataset."""
    if not d.is_dir():
        return
    for p in d.iterdir():
        if p.name in (DONE, ERROR) or (p.name.startswith(".") and p.name.endswith(".tmp")):
            p.unlink(missing_ok=True)
        elif p.name == DATASET and not keep_dataset:
            p.unlink(missing_ok=True)
