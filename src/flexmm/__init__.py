"""flexmm: nonlinear waves in flexible mechanical metamaterials.

A scene (YAML config) describes a lattice, an excitation, damping, a solver and what to save;
``flexmm.run_scene`` builds the system, integrates it with compiled kernels and writes a
self-describing xarray dataset.
"""

__version__ = "0.1.0"

__all__ = ["__version__"]
