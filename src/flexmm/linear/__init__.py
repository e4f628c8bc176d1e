"""Linear dynamics of a built system, from the Hessian of its compiled energy.

``dispersion``: Bloch dispersion and pass bands of 1D models; ``sheet``: plane-wave acoustic
modes of the 2D rotating-squares sheet. Unlike ``flexmm.theory`` (closed forms, no built
model), these need a ``System`` and ``stability.hessian_operator``, so they sit above the models
and integrators in the layering (docs/architecture.md).
"""
