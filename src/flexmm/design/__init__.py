"""Inverse design and fitting with exact gradients (discrete adjoint of velocity Verlet and of the
symplectic splittings PEFRL and BM6).

``kernels``/``terms``: second derivatives of model forces and external terms (compiled);
``sweeps``: forward, reverse and tangent sweeps of velocity Verlet; ``splitting``: those of a
kick/drift splitting; ``gradient``: the Python API (raw arrays,
objectives, checkpointing); ``variables``: scene-level design variables and their map to the
raw arrays; ``fit``/``design``: the ``flexmm fit`` and ``flexmm design`` verbs.
"""
