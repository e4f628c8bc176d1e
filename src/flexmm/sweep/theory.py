"""Theory for sweep datasets and plots, taken from the analysis' per-model registry.

``speed_at`` evaluates ``flexmm.analysis.compare.THEORY[kind].speed_curve`` (NaN where the model
has no speed law or no pulse of that amplitude exists); ``reference_lines`` adds model-specific
thresholds worth drawing: for the rotating-squares chain, the amplitude gap A_min of each
polarity (docs/physics.md §1.3, ``flexmm.theory.rotating.amplitude_gap``).
"""

from __future__ import annotations

import math

import numpy as np


def _context(config: dict):
    from flexmm.analysis.compare import RunContext

    return RunContext(model=str((config.get("lattice") or {}).get("kind", "unknown")), config=config)


def speed_at(config: dict, units: str, amplitudes) -> np.ndarray:
    """Predicted speed (m/s) of a pulse of each amplitude in a scene (resolved config dict)."""
    from flexmm.analysis.compare import theory_for

    amp = np.asarray(amplitudes, float)
    ctx = _context(config)
    curve = theory_for(ctx).speed_curve
    if curve is None:
        return np.full(amp.shape, np.nan)
    try:
        return np.asarray(curve(ctx, units, amp), float)
    except (ValueError, KeyError, ArithmeticError):
        return np.full(amp.shape, np.nan)


def _rotating_gap(ctx) -> dict[str, float]:
    from flexmm.analysis.predict_rotating import params
    from flexmm.theory.rotating import amplitude_gap

    p, _, _ = params(ctx)
    out = {}
    for sign, name in ((+1, "positive"), (-1, "negative")):
        try:
            out[f"theory_amplitude_gap_{name}_rad"] = amplitude_gap(p, sign)
        except ValueError:
            out[f"theory_amplitude_gap_{name}_rad"] = math.nan
    return out


REFERENCE_LINES = {"rotating_squares_chain": _rotating_gap}


def reference_lines(config: dict) -> dict[str, float]:
    """Scalar theory values of a scene (dataset attributes ``theory_*``); {} if none."""
    ctx = _context(config)
    fn = REFERENCE_LINES.get(ctx.model)
    try:
        return fn(ctx) if fn else {}
    except (ValueError, KeyError, ArithmeticError):
        return {}
