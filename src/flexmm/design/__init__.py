"""Inverse design and fitting with exact gradients (discrete adjoint of velocity Verlet).

``kernels``/``terms``: second derivatives of model forces and external terms (compiled);
``sweeps``: forward, reverse and tangent sweeps; ``gradient``: the Python API (raw arrays,
objectives, checkpointing); ``variables``: scene-level design variables and their map to the
raw arrays; ``fit``/``design``: the ``flexmm fit`` and ``flexmm design`` verbs.
"""
