"""Save only what the requested analysis needs: its field, at the cadence it needs.

An analysis request is a spec string: ``pulse[:FIELD]`` (a travelling pulse of FIELD, default
θ or the strain of u), ``front[:FIELD]`` (a transition front of a displacement), ``energy``
(energies only: one field, every few sites), or ``none``. The pulse analysis locates the peak of
each site's trace with a parabola through its top samples, so the pulse's passage at a site —
FWHM / speed — should span ``FRAMES_PER_PASSAGE`` frames; its width needs ``SITES_PER_WIDTH``
saved sites per FWHM. Choices the user made in ``output`` (keys they set) are never changed.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import get_args

from flexmm.config.analysis import AnalysisRequest, RunPurpose

FRAMES_PER_PASSAGE = 10
SITES_PER_WIDTH = 8
MIN_FRAMES, MAX_FRAMES = 21, 20_001
#: what ``--analysis`` may ask for (``none``: output as declared)
KINDS = (*get_args(RunPurpose), "none")


@dataclass(frozen=True)
class Purpose:
    """What a run for one analysis saves: ``field(model fields)`` its default field; ``energies``:
    only the energies matter (one field, no rates, every ``ENERGY_STRIDE``-th site); ``passage``:
    frames dense enough to follow a wave past a site; ``width``: sites dense enough to fit its width."""

    field: Callable[[tuple[str, ...]], str]
    energies: bool = False
    passage: bool = False
    width: bool = False


ENERGY_STRIDE = 10
#: every ``RunPurpose``
PURPOSES = {
    "pulse": Purpose(lambda fields: "theta" if "theta" in fields else "strain", passage=True, width=True),
    "front": Purpose(lambda fields: fields[0], passage=True),
    "energy": Purpose(lambda fields: fields[0], energies=True),
}


def parse_analysis(spec: str | None) -> AnalysisRequest | None:
    """``pulse``, ``pulse:theta``, ``front:u``, ``energy``, ``none`` (or None) -> request; a
    ConfigError naming ``--analysis``, the field and what was expected otherwise."""
    return AnalysisRequest.parse(spec)


def default_field(request: AnalysisRequest, model_fields: tuple[str, ...]) -> str:
    """The dataset field an analysis reads: its own, else θ for pulses, else strain of u."""
    return request.field or PURPOSES[request.kind].field(model_fields)


def _stored(field: str, model_fields: tuple[str, ...]) -> tuple[list[str], bool]:
    """(coordinates to save, velocities needed) for a field spec of the analysis module."""
    base, _, arg = field.partition(":")
    if base == "strain":
        return [arg or model_fields[0]], False
    if base == "velocity":
        return [arg or model_fields[0]], True
    if base.endswith("_dot"):
        return [base[:-4]], True
    return [base], False


def output_plan(scene, request: AnalysisRequest | None, model_fields: tuple[str, ...],
                passage_s: float | None = None, width_sites: float | None = None,
                user: set[str] | None = None) -> tuple[dict, list[str]]:
    """Updates to ``scene.output`` for ``request`` and the notes explaining them.

    ``passage_s`` (pulse FWHM / speed) and ``width_sites`` come from a prediction; without them
    the cadence and site stride stay as declared. ``user``: the output keys the user set
    (default: those set in ``scene.output``); they are never changed.
    """
    if request is None:
        return {}, ["no analysis requested: output as declared (--analysis pulse saves only what it needs)"]
    out = scene.output
    user = scene.output.model_fields_set if user is None else user
    upd, notes = {}, []
    purpose = PURPOSES[request.kind]
    fld = default_field(request, model_fields)
    fields, rates = ([model_fields[0]], False) if purpose.energies else _stored(fld, model_fields)
    if "fields" not in user and set(fields) != set(out.fields or model_fields):
        upd["fields"] = fields
    if "velocities" not in user and out.velocities != rates:
        upd["velocities"] = rates
    if purpose.energies and "site_stride" not in user:
        upd["site_stride"] = max(1, out.site_stride, ENERGY_STRIDE)
    if passage_s and not ({"n_frames", "every_s"} & user) and purpose.passage:
        n = math.ceil(scene.solver.duration_s / (passage_s / FRAMES_PER_PASSAGE)) + 1
        n = min(max(n, MIN_FRAMES), MAX_FRAMES)
        if n != out.n_frames:
            upd["n_frames"] = n
    if width_sites and "site_stride" not in user and purpose.width:
        stride = max(1, int(width_sites // SITES_PER_WIDTH))
        if stride != out.site_stride:
            upd["site_stride"] = stride
    if upd:
        notes.append(f"analysis {request} (field {fld}) needs only: "
                     + ", ".join(f"output.{k} = {v}" for k, v in upd.items()))
    else:
        notes.append(f"analysis {request}: output as declared already fits")
    if not passage_s and purpose.passage:
        notes.append("pulse duration unknown before the run: output cadence kept")
    return upd, notes


def saved_fraction(scene, upd: dict, model_fields: tuple[str, ...]) -> float:
    """Bytes saved after/before the updates (site variables only)."""
    def size(o: dict) -> float:
        n_f = len(o.get("fields") or model_fields) * (2 if o.get("velocities", True) else 1)
        return n_f * o.get("n_frames", 201) / o.get("site_stride", 1)

    before = scene.output.model_dump()
    return size({**before, **upd}) / size(before)
