"""Turn run datasets into what the papers report (pulse speed, amplitude, width, fronts, ...).

``analyze_run(run_dir)`` is the entry point (``flexmm analyze``); the pieces are usable alone:
``field_view`` picks a field, ``measure_pulses`` / ``measure_fronts`` / ``measure_driven`` /
``energy_budget`` measure, ``theory_comparison.theory_for`` finds the predictions of the run's model kind and
``analysis.export`` writes analysis.nc, JSON and CSV. ``summary.principal`` picks the feature
``flexmm run`` prints (``summary.summary_lines``); ``leading_pulse`` is a quick single-pulse fit
(work-precision and fidelity pilots).
"""

from flexmm.analysis.driven import NotDriven, measure_driven
from flexmm.analysis.energy import energy_budget
from flexmm.analysis.fields import FieldError, field_view
from flexmm.analysis.fronts import FrontNotFound, measure_fronts
from flexmm.analysis.pulses import PulseNotFound, leading_pulse, measure_pulses
from flexmm.analysis.report import RunAnalysis, RunNotFound, analyze_run

__all__ = [
    "FieldError", "FrontNotFound", "NotDriven", "PulseNotFound", "RunAnalysis", "RunNotFound",
    "analyze_run", "energy_budget", "field_view", "leading_pulse", "measure_driven",
    "measure_fronts", "measure_pulses",
]
