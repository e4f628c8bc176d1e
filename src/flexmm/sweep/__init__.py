"""Families of scenes: sweep specs, resumable parallel execution, combined sweep datasets.

``load_sweep(path)`` / ``spec_from_scene(config, vary)`` describe a sweep; ``run_sweep(spec,
sweep_dir)`` runs what is pending and writes SWEEP_DIR/sweep.nc; ``plot_sweep(sweep_dir,
out_png)`` plots the observables against the varied parameters with theory curves.

Names are imported on first use so that worker processes can pin their thread counts before
numpy and numba load (see ``flexmm.sweep.worker``).
"""

from __future__ import annotations

from importlib import import_module

_EXPORTS = {
    "Axis": "spec",
    "SweepSpec": "spec",
    "load_sweep": "spec",
    "parse_vary": "spec",
    "spec_from_scene": "spec",
    "SweepPlan": "execute",
    "SweepReport": "execute",
    "prepare": "execute",
    "run_sweep": "execute",
    "SweepStore": "store",
    "write_combined": "combine",
    "plot_sweep": "plot",
    "is_sweep": "plot",
    "open_sweep": "plot",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(import_module(f"flexmm.sweep.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module 'flexmm.sweep' has no attribute {name!r}")
