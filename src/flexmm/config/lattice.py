"""The model registry: one ``ModelSpec`` per lattice kind, and the lattice union derived from it.

A spec names everything flexmm knows about a kind: its config class (whose ``kind`` Literal is the
registry key), the models module that builds it, the config field that counts its units along x,
and the hooks of higher layers — the analysis theory, the continuum predictor, the lower-dimensional
reductions. Hooks are ``"module:attribute"`` paths (``flexmm.config.base.resolve``), imported only
by the layer that uses them, so the config layer stays importable without numpy models, analysis or
planning (docs/architecture.md, Registries).

Adding a model kind: its config class, its models module (a builder, ``FIELDS``), one line below;
its predictions, if it has a theory, in ``flexmm.analysis.predict.<its models module>`` (a
``ModelTheory`` named by the ``theory`` hook).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Union, get_args

from flexmm.config.base import Strict, resolve
from flexmm.config.mass_chain import MassChain, MassGrid, MassNetwork
from flexmm.config.rigid import (
    BistableLinkage,
    RotatingSquaresChain,
    RotatingSquaresSheet,
)
from flexmm.config.network import RigidNetwork
from flexmm.config.triangles import RotatingTrianglesChain, RotatingTrianglesSheet

#: which layer each hook of a spec belongs to (tests/test_layers.py checks the paths)
HOOK_LAYERS = {"builder": "flexmm.models", "launcher": "flexmm.models", "theory": "flexmm.analysis",
               "continuum": "flexmm.plan", "reducers": "flexmm.plan"}


@dataclass(frozen=True)
class ModelSpec:
    """One lattice kind.

    - ``config``: the lattice config class; its ``kind`` Literal names the kind;
    - ``builder``: ``build(cfg) -> System``, in a models module whose ``FIELDS`` lists the per-site
      coordinates and their roles (``models.base.FieldSpec``), in state order;
    - ``length``: the config field counting units along x (domain trimming), None if the lattice
      has none (a network of branches);
    - ``launcher``: ``launch_soliton(system, amplitude, center, direction)`` for ``soliton``
      excitations; ``soliton_on_predeformed``: it knows the prestressed theory;
    - ``theory``: an ``analysis.context.ModelTheory`` (predictions compared with measurements);
    - ``continuum``: a ``plan.continuum.ContinuumTheory`` (the wave before the run);
    - ``reducers``: reduction name -> ``reducer(scene dict, lattice config) -> reduced scene dict``.
    """

    config: type[Strict]
    builder: str
    length: str | None
    launcher: str | None = None
    soliton_on_predeformed: bool = False
    theory: str | None = None
    continuum: str | None = None
    reducers: Mapping[str, str] = field(default_factory=dict)

    @property
    def kind(self) -> str:
        return get_args(self.config.model_fields["kind"].annotation)[0]

    def hook(self, name: str) -> Any:
        """The resolved ``launcher``, ``theory`` or ``continuum`` hook, or None if the kind has none."""
        path = getattr(self, name)
        return None if path is None else resolve(path)

    def reducer(self, name: str):
        """The named reduction (e.g. ``"strip"``), or None."""
        path = self.reducers.get(name)
        return None if path is None else resolve(path)

    @property
    def build(self):
        """``build(cfg) -> System``."""
        return resolve(self.builder)

    @property
    def fields(self):
        """The model's per-site coordinates (``FieldSpec``), in state order."""
        return resolve(self.builder.partition(":")[0]).FIELDS

    @property
    def launch_soliton(self):
        """``launch_soliton(system, amplitude, center, direction)``, or None."""
        return self.hook("launcher")


def _registry(*specs: ModelSpec) -> dict[str, ModelSpec]:
    return {s.kind: s for s in specs}


MODELS: dict[str, ModelSpec] = _registry(
    ModelSpec(RotatingSquaresChain, "flexmm.models.rotating_chain:build", "n_units",
              launcher="flexmm.models.rotating_chain:launch_soliton", soliton_on_predeformed=True,
              theory="flexmm.analysis.predict.rotating_squares:CHAIN", continuum="flexmm.plan.continuum:ROTATING_CHAIN"),
    ModelSpec(RotatingSquaresSheet, "flexmm.models.rotating_sheet:build", "n_cols",
              launcher="flexmm.models.rotating_sheet:launch_soliton", theory="flexmm.analysis.predict.rotating_squares:SHEET",
              reducers={"strip": "flexmm.plan.dimension:sheet_to_strip",
                        "chain": "flexmm.plan.dimension:sheet_to_chain"}),
    ModelSpec(BistableLinkage, "flexmm.models.linkage:build", "n_cols",
              theory="flexmm.analysis.predict.linkage:THEORY"),
    ModelSpec(MassChain, "flexmm.models.mass_chain:build", "n_units",
              theory="flexmm.analysis.predict.mass_chain:MASS_CHAIN", continuum="flexmm.plan.continuum:MASS_FRONT"),
    ModelSpec(MassNetwork, "flexmm.models.mass_chain:build", None),
    ModelSpec(MassGrid, "flexmm.models.mass_chain:build", "nx"),
    ModelSpec(RotatingTrianglesChain, "flexmm.models.rotating_triangles:build_chain", "n_units",
              theory="flexmm.analysis.predict.rotating_triangles:THEORY"),
    ModelSpec(RotatingTrianglesSheet, "flexmm.models.rotating_triangles:build_sheet", "n_cols",
              theory="flexmm.analysis.predict.rotating_triangles:THEORY"),
    ModelSpec(RigidNetwork, "flexmm.models.network:build", "n_cols", theory="flexmm.analysis.predict.network:THEORY"),
)

#: the ``lattice`` section of a scene: any registered config class, discriminated on ``kind``
LatticeConfig = Union[tuple(s.config for s in MODELS.values())]

__all__ = ["MODELS", "LatticeConfig", "ModelSpec", "RotatingSquaresChain"]
