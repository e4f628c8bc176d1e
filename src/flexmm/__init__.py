"""flexmm: nonlinear waves in flexible mechanical metamaterials.

A scene (YAML config) describes a lattice, an excitation, damping, a solver and what to save;
flexmm builds the system, integrates it with compiled kernels and writes a self-describing
xarray dataset. From Python (docs/api.md)::

    import flexmm
    res = flexmm.run("configs/lego_vector_soliton.yaml", **{"solver.duration_s": 0.4})
    flexmm.analyze(res.dataset).speed_m_s

``run``, ``analyze`` and ``render`` are imported on first use, so ``import flexmm`` stays fast
(``flexmm.render`` is the package of that name, made callable).
"""

from __future__ import annotations

TYPE_CHECKING = False  # typing.TYPE_CHECKING without importing typing (import flexmm stays fast)
from flexmm._version import __version__

#: the public API: name -> the module that defines it (imported on first use)
_LAZY = {"run": "flexmm.api", "analyze": "flexmm.api", "Result": "flexmm.api",
         "Measurements": "flexmm.api", "Scene": "flexmm.config", "FlexmmError": "flexmm.errors",
         "ConfigError": "flexmm.config"}

if TYPE_CHECKING:
    from flexmm.api import Measurements, Result, analyze, render, run
    from flexmm.config import ConfigError, Scene
    from flexmm.errors import FlexmmError


def __getattr__(name: str) -> object:
    import importlib

    if name == "render":  # the package flexmm.render, callable (flexmm/render/__init__.py)
        return importlib.import_module("flexmm.render")
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'flexmm' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(list(globals()) + list(_LAZY) + ["render"])


__all__ = ["ConfigError", "FlexmmError", "Measurements", "Result", "Scene", "__version__", "analyze", "render",
           "run"]
