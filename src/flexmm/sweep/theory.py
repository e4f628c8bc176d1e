"""Theory for sweep datasets and plots, taken from the analysis' per-model registry.

``speed_at`` evaluates the ``speed_curve`` of the model's theory (``analysis.report.theory_comparison.theory_for``;
NaN where the model has no speed law or no pulse of that amplitude exists); ``reference_lines``
adds the theory's model-specific thresholds worth drawing: for the rotating-squares chain, the
amplitude gap A_min of each polarity (docs/physics.md §1.3, ``analysis.predict.rotating_squares.amplitude_gap_lines``).
"""

from __future__ import annotations

import numpy as np


def _context(config: dict):
    from flexmm.analysis.report.theory_comparison import RunContext

    return RunContext(model=str((config.get("lattice") or {}).get("kind", "unknown")), config=config)


def speed_at(config: dict, units: str, amplitudes) -> np.ndarray:
    """Predicted speed (m/s) of a pulse of each amplitude in a scene (resolved config dict)."""
    from flexmm.analysis.report.theory_comparison import theory_for

    amp = np.asarray(amplitudes, float)
    ctx = _context(config)
    curve = theory_for(ctx).speed_curve
    if curve is None:
        return np.full(amp.shape, np.nan)
    try:
        return np.asarray(curve(ctx, units, amp), float)
    except (ValueError, KeyError, ArithmeticError):
        return np.full(amp.shape, np.nan)


def reference_lines(config: dict) -> dict[str, float]:
    """Scalar theory values of a scene (dataset attributes ``theory_*``); {} if none."""
    from flexmm.analysis.report.theory_comparison import theory_for

    ctx = _context(config)
    fn = theory_for(ctx).reference_lines
    try:
        return fn(ctx) if fn else {}
    except (ValueError, KeyError, ArithmeticError):
        return {}
