"""Measurements on the shipped rigid-unit scenes (configs/), shared by test_rigid_scenes.py.

Each function runs a scene (optionally with ``--set``-style overrides) and returns the numbers
the slow tests assert on; docs/scenes.md quotes them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from flexmm.api import run_scene
from flexmm.config import load_scene, scene_from_dict
from flexmm.io.run_dataset import open_run

REPO = Path(__file__).resolve().parents[2]


def run(name: str, tmp_path: Path, overrides: list[str] | None = None):
    """Run configs/<name>.yaml as declared; return (scene, dataset, result)."""
    scene = load_scene(REPO / "configs" / f"{name}.yaml", overrides or [])
    result = run_scene(scene, run_dir=tmp_path / name)
    assert result.status == "finished", result.reason
    return scene, open_run(result.path), result


def run_edited(name: str, tmp_path: Path, edit):
    """Run configs/<name>.yaml after ``edit(data)`` changes its dict (e.g. inside a list)."""
    data = yaml.safe_load((REPO / "configs" / f"{name}.yaml").read_text())
    edit(data)
    result = run_scene(scene_from_dict(data), run_dir=tmp_path / name)
    assert result.status == "finished", result.reason
    return open_run(result.path)


def peak(row: np.ndarray) -> tuple[float, float]:
    """Sub-site position and signed height of the largest |value| (parabola through the maximum)."""
    y = np.abs(row)
    k = int(np.clip(np.argmax(y), 1, y.size - 2))
    a, b, c = y[k - 1 : k + 2]
    den = a - 2 * b + c
    off = 0.5 * (a - c) / den if den < 0 else 0.0
    return k + off, float(np.sign(row[k]) * (b - 0.25 * (a - c) * off))


def track(theta: np.ndarray, time: np.ndarray, lo: int, hi: int, t0: float, t1: float):
    """Peak positions/heights of theta[:, lo:hi] for t0 ≤ t ≤ t1: (times, positions, heights)."""
    sel = (time >= t0) & (time <= t1)
    pos, amp = zip(*(peak(row[lo:hi]) for row in theta[sel]))
    return time[sel], np.asarray(pos) + lo, np.asarray(amp)


def row_fields(ds, name: str) -> np.ndarray:
    """(time, rows, cols) view of a sheet field."""
    nr, nc = int(ds["row"].max()) + 1, int(ds["col"].max()) + 1
    return ds[name].values.reshape(-1, nr, nc)


def fwhm(profile: np.ndarray) -> int:
    """Number of entries above half the maximum."""
    return int(np.sum(profile > 0.5 * profile.max()))


def sound_bullet(tmp_path: Path, overrides=None) -> dict:
    """Across-row widths (FWHM, units) of the rotation and strain footprints along the beam."""
    scene, ds, result = run("a_sheet_sound_bullet", tmp_path, overrides)
    theta = np.abs(row_fields(ds, "theta")).max(axis=0)
    u = row_fields(ds, "u") / scene.lattice.a_m
    strain = np.abs(np.diff(u, axis=2)).max(axis=0)
    cols = [20, 40, 60, 80, 100]
    return {"cols": cols, "theta_width": [fwhm(theta[:, c]) for c in cols],
            "theta_peak": [float(theta[:, c].max()) for c in cols],
            "strain_width": [fwhm(strain[:, c]) for c in cols],
            "wall_s": result.wall_s}


def front_positions(theta: np.ndarray, threshold: float) -> np.ndarray:
    """Per frame, the last column (row 0) whose θ/threshold > 1 (−1 if none)."""
    out = []
    for row in theta:
        hit = np.flatnonzero(row / threshold > 1.0)
        out.append(hit.max() if hit.size else -1)
    return np.asarray(out)


def wall_position(row: np.ndarray) -> float:
    """Interpolated zero crossing of θ between a + domain (left) and a − domain (right)."""
    k = int(np.flatnonzero((row[:-1] > 0) & (row[1:] <= 0))[-1])
    return k + row[k] / (row[k] - row[k + 1])
