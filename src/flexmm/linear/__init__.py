"""Linear dynamics of a built system, from the Hessian of its compiled energy.

``dispersion``: the Bloch cell and pass bands of 1D models; ``sheet``: the cell and plane-wave
acoustic modes of the 2D rotating-squares sheet; ``triangles``: both for the rotating triangles.
They read a model's couplings into a ``flexmm.linalg.BlochCell``, whose bands
``flexmm.linalg.bloch_frequencies`` computes (the one Bloch solver, also used by
``plan.domain``). Unlike ``flexmm.theory`` (closed forms, no built model), these need a
``System`` and ``stability.hessian_operator``, so they sit above the models and integrators in
the layering (docs/architecture.md).
"""
