"""Turn run datasets into what the papers report (pulse speed, amplitude, width, fronts, ...).

Four subpackages, each importing only those listed after it:

- ``report``: ``analyze.analyze_run(run_dir)``, the entry point (``flexmm analyze``);
  ``theory_comparison`` pairs measurements with predictions; ``summary`` (what ``flexmm run``
  prints), ``export`` (analysis.nc, JSON, CSV), ``figures``;
- ``predict``: each model kind's predictions (a ``ModelTheory``, named by its ``ModelSpec``);
- ``measure``: what is measured — pulses, fronts, driven response, oblique waves, collisions,
  transients, energy — each usable alone (``measure_pulses``, ``measure_fronts``,
  ``measure_driven``, ``energy_budget``; ``leading_pulse`` is a quick single-pulse fit for the
  work-precision and fidelity pilots);
- ``features``: the primitives on sampled fields (peaks, tracks, profile fits, the field view
  ``field_view``, the rest state).

``context`` (the run's context, a measured-vs-predicted row, ``ModelTheory``) is shared by all.
"""

from flexmm.analysis.features.fields import FieldError, field_view
from flexmm.analysis.measure.driven import NotDriven, measure_driven
from flexmm.analysis.measure.energy import energy_budget
from flexmm.analysis.measure.fronts import FrontNotFound, measure_fronts
from flexmm.analysis.measure.pulses import PulseNotFound, leading_pulse, measure_pulses
from flexmm.analysis.report.analyze import RunAnalysis, RunNotFound, analyze_run

__all__ = [
    "FieldError", "FrontNotFound", "NotDriven", "PulseNotFound", "RunAnalysis", "RunNotFound",
    "analyze_run", "energy_budget", "field_view", "leading_pulse", "measure_driven",
    "measure_fronts", "measure_pulses",
]
