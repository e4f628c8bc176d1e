"""Turn run datasets into what the papers report (pulse speed, amplitude, width, ...)."""

from flexmm.analysis.pulses import PulseNotFound, leading_pulse

__all__ = ["PulseNotFound", "leading_pulse"]
