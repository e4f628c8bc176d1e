"""Analysis options: what to measure on a run, as a config model.

One model for every place that says how a run is measured: ``flexmm analyze`` builds it from
its options (``--analysis``, ``--field``, ``--row``, ``--threshold``, ``--jump``) and a sweep
spec's ``analysis:`` block is this model, so both accept the same values and report mistakes
the same way (file:line, or the option, with the field and what was expected). The analysis
kinds are ``AnalysisKind``; ``flexmm.analysis.report.analyze`` dispatches on them.
"""

from __future__ import annotations

import re
from typing import Annotated, Literal

from pydantic import AfterValidator, Field

from flexmm.config.base import Finite, Strict

#: what is measured: ``auto`` (a shaker: driven; oblique plane waves: modes; else what the
#: model's theory prefers, pulses by default), travelling pulses, transition fronts, the driven
#: response, or the groups of oblique plane waves on a skew-periodic sheet
AnalysisKind = Literal["auto", "pulse", "front", "driven", "modes"]

_FIELD = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(:[A-Za-z_][A-Za-z0-9_]*)?")
FIELD_FORMS = "theta, u, u_dot, strain[:NAME] or velocity[:NAME]"


def _field_spec(text: str) -> str:
    if not _FIELD.fullmatch(text):
        raise ValueError(f"a field name: {FIELD_FORMS}")
    return text


#: a field of a run's dataset (whether the run has it is checked when it is measured)
FieldSpec = Annotated[str, AfterValidator(_field_spec), Field(description=FIELD_FORMS)]


class AnalysisOptions(Strict):
    """How a run is measured (``flexmm analyze`` options; a sweep spec's ``analysis:``)."""

    kind: AnalysisKind = "auto"
    field: FieldSpec | None = Field(None, description="field measured (default: θ, or the strain of u; "
                                                      "the displacement for fronts and drives)")
    row: int | None = Field(None, ge=0, description="row of a 2D lattice (default: the middle one)")
    threshold_fraction: float = Field(0.25, ge=0.01, le=1.0,
                                      description="pulse detection level, fraction of the peak")
    jump: Finite | None = Field(None, description="well-to-well jump of a front (default: measured)")


#: what a run is for (``flexmm run/plan/compare --analysis``), which decides what it saves
RunPurpose = Literal["pulse", "front", "energy"]


class AnalysisRequest(Strict):
    """The analysis a run is planned for: ``pulse[:FIELD]``, ``front[:FIELD]`` or ``energy``
    (``flexmm.plan.output`` saves only what it needs)."""

    kind: RunPurpose
    field: FieldSpec | None = None

    def __init__(self, kind: str, field: str | None = None, **data):
        super().__init__(kind=kind, field=field, **data)

    def __str__(self) -> str:
        return self.kind + (f":{self.field}" if self.field else "")

    @classmethod
    def parse(cls, spec: str | None, *, option: str = "--analysis") -> AnalysisRequest | None:
        """``pulse``, ``pulse:theta``, ``front:u``, ``energy``; None for ``none`` (or None). A
        ConfigError naming ``option``, the field and what was expected if it is none of them."""
        from flexmm.config.loader import validate

        if spec is None or spec.strip() == "none":
            return None
        kind, _, fld = spec.strip().partition(":")
        data = {"kind": kind, **({"field": fld} if fld else {})}
        where = f"{option} {spec}"
        return validate(cls, data, lines={(k,): where for k in data}, source=option)
