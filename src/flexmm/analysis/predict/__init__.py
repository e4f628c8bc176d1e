"""Each model kind's predictions, compared with what a run measures: one module per model (named
as in ``flexmm.models``), each exposing the ``analysis.context.ModelTheory`` that its
``ModelSpec.theory`` hook names in ``flexmm.config.lattice.MODELS``. A new model kind with a theory
adds its module here and that one hook path."""
