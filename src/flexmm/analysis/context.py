"""What a prediction sees and returns: the run's context and one measured-vs-predicted row."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import yaml

#: libyaml's safe loader where PyYAML was built with it (same data, ~10x faster than pure Python)
_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


@dataclass
class Comparison:
    """One measured quantity, with the theory's value where one applies."""

    item: str
    quantity: str
    measured: float
    predicted: float | None
    units: str
    note: str = ""

    @property
    def rel_diff(self) -> float | None:
        """(measured − predicted)/|predicted|, or None without a usable prediction."""
        if self.predicted is None or not math.isfinite(self.predicted) or self.predicted == 0:
            return None
        return (self.measured - self.predicted) / abs(self.predicted)

    def as_dict(self) -> dict:
        return {"item": self.item, "quantity": self.quantity, "measured": self.measured,
                "predicted": self.predicted, "units": self.units, "rel_diff": self.rel_diff,
                "note": self.note}


@dataclass
class RunContext:
    """What a theory may read about a run: model kind, resolved config (dict) and the dataset."""

    model: str
    config: dict
    ds: Any = None
    cache: dict = field(default_factory=dict)

    @classmethod
    def from_dataset(cls, ds) -> "RunContext":
        text = ds.attrs.get("config", "")
        config = yaml.load(text, Loader=_LOADER) if text else {}
        model = ds.attrs.get("model") or (config.get("lattice") or {}).get("kind", "unknown")
        return cls(model=str(model), config=config or {}, ds=ds)

    def scene(self):
        """The validated Scene of the run (cached); ConfigError if the config does not validate."""
        if "scene" not in self.cache:
            from flexmm.config import scene_from_dict

            self.cache["scene"] = scene_from_dict(self.config)
        return self.cache["scene"]


Predictor = Callable[..., list[Comparison]]


@dataclass(frozen=True)
class ModelTheory:
    """Prediction functions of one model kind (any may be None); a ``ModelSpec``'s ``theory`` hook.

    pulse(ctx, PulseMeasurement) -> [Comparison]; front(ctx, FrontMeasurement) -> [Comparison];
    driven(ctx, DrivenMeasurement) -> [Comparison]; speed_curve(ctx, field, amplitudes) -> speeds
    (m/s, NaN where no pulse exists); profile(ctx, PulseMeasurement, x_m) -> field values;
    bands_hz(ctx) -> [(f_lo, f_hi)] linear pass bands; analysis(ctx) -> 'pulse' or 'front', the
    default analysis of a run that is not driven (e.g. 'front' for multistable chains);
    collision(ctx, Collision) -> [Comparison] (e.g. the Toda head-on shifts);
    reference_lines(ctx) -> {name: value}, scalar thresholds sweeps store and draw (``theory_*``);
    pulse_field: the field whose pulses the theory predicts, measured when none is asked (None:
    θ for models with rotations, else the strain); front_field: the field a front switches,
    measured when none is asked (None: the displacement).
    """

    pulse: Predictor | None = None
    front: Predictor | None = None
    driven: Predictor | None = None
    speed_curve: Callable[..., Any] | None = None
    profile: Callable[..., Any] | None = None
    bands_hz: Callable[..., list] | None = None
    analysis: Callable[..., str] | None = None
    collision: Predictor | None = None
    reference_lines: Callable[..., dict] | None = None
    pulse_field: str | None = None
    front_field: str | None = None
