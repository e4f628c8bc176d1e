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
HOOK_LAYERS = {"builder": "flexmm.models", "launcher": "flexmm.models", "topology": "flexmm.models",
               "hinges": "flexmm.models", "elements": "flexmm.models", "theory": "flexmm.analysis",
               "continuum": "flexmm.plan", "reducers": "flexmm.plan", "bands": "flexmm.linear"}


@dataclass(frozen=True)
class ModelSpec:
    """One lattice kind.

    - ``config``: the lattice config class; its ``kind`` Literal names the kind;
    - ``builder``: ``build(cfg) -> System``, in a models module whose ``FIELDS`` lists the per-site
      coordinates and their roles (``models.base.FieldSpec``), in state order;
    - ``length``: the config field counting units along x (domain trimming), None if the lattice
      has none (a network of branches);
    - ``launcher``: ``launch_soliton(system, lattice, amplitude, center, direction)`` for ``soliton``
      excitations; ``soliton_on_predeformed``: it knows the prestressed theory;
    - ``chain_waves``: ``initial.launch`` may start the exact waves of a uniform chain of masses
      (``models.launch_chains``);
    - ``topology``: ``topology(cfg) -> models.mass_topology.Topology`` of a lattice of point masses
      (sites, bonds, ends; the renderer draws such a kind as masses); None for rigid units;
    - ``hinges``: ``hinges(cfg) -> (a, b, axis)``, the hinges of a lattice of rotating units
      in its builder's order (design variables and drawing read them without building);
    - ``elements``: ``elements(cfg) -> {target: count}``, the per-element targets of its
      ``variation`` (a design's ``profile: each``);
    - ``theory``: an ``analysis.context.ModelTheory`` (predictions compared with measurements);
    - ``continuum``: a ``plan.continuum.ContinuumTheory`` (the wave before the run);
    - ``reducers``: reduction name -> ``reducer(scene dict, lattice config) -> reduced scene dict``;
    - ``bands``: ``band_path(cfg, points)``, the Bloch bands ``flexmm bands`` computes;
    - ``label``: what pictures call the kind (default: its ``kind``).
    """

    config: type[Strict]
    builder: str
    length: str | None
    launcher: str | None = None
    soliton_on_predeformed: bool = False
    theory: str | None = None
    continuum: str | None = None
    reducers: Mapping[str, str] = field(default_factory=dict)
    chain_waves: bool = False
    topology: str | None = None
    hinges: str | None = None
    elements: str | None = None
    bands: str | None = None
    label: str = ""

    @property
    def kind(self) -> str:
        return get_args(self.config.model_fields["kind"].annotation)[0]

    @property
    def branched(self) -> bool:
        """Its sites lie on branches, not along x (it has no ``length``)."""
        return self.length is None

    def hook(self, name: str) -> Any:
        """The resolved hook of that name (``launcher``, ``theory``, ``topology``, ...), or None if
        the kind has none."""
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
        """``launch_soliton(system, lattice, amplitude, center, direction)``, or None."""
        return self.hook("launcher")


def _registry(*specs: ModelSpec) -> dict[str, ModelSpec]:
    return {s.kind: s for s in specs}


_M = "flexmm.models."
MODELS: dict[str, ModelSpec] = _registry(
    ModelSpec(RotatingSquaresChain, _M + "rotating_chain:build", "n_units",
              launcher=_M + "rotating_chain:launch_soliton", soliton_on_predeformed=True,
              theory="flexmm.analysis.predict.rotating_squares:CHAIN", continuum="flexmm.plan.continuum:ROTATING_CHAIN",
              hinges=_M + "rotating_chain:lattice_hinges", elements=_M + "rotating_sheet:element_counts",
              label="rotating-squares chain"),
    ModelSpec(RotatingSquaresSheet, _M + "rotating_sheet:build", "n_cols",
              launcher=_M + "rotating_sheet:launch_soliton", theory="flexmm.analysis.predict.rotating_squares:SHEET",
              reducers={"strip": "flexmm.plan.dimension:sheet_to_strip",
                        "chain": "flexmm.plan.dimension:sheet_to_chain"},
              hinges=_M + "rotating_sheet:lattice_hinges", elements=_M + "rotating_sheet:element_counts",
              label="rotating-squares sheet"),
    ModelSpec(BistableLinkage, _M + "linkage:build", "n_cols", theory="flexmm.analysis.predict.linkage:THEORY",
              hinges=_M + "linkage:lattice_hinges", label="bistable linkage"),
    ModelSpec(MassChain, _M + "mass_chain:build", "n_units",
              theory="flexmm.analysis.predict.mass_chain:MASS_CHAIN", continuum="flexmm.plan.continuum:MASS_FRONT",
              chain_waves=True, topology=_M + "mass_topology:chain", elements=_M + "mass_chain:element_counts",
              label="chain of masses"),
    ModelSpec(MassNetwork, _M + "mass_chain:build", None, topology=_M + "mass_topology:network",
              elements=_M + "mass_chain:element_counts", label="network of chains of masses"),
    ModelSpec(MassGrid, _M + "mass_chain:build", "nx", topology=_M + "mass_topology:grid",
              elements=_M + "mass_chain:element_counts", label="grid of masses"),
    ModelSpec(RotatingTrianglesChain, _M + "rotating_triangles:build_chain", "n_units",
              theory="flexmm.analysis.predict.rotating_triangles:CHAIN"),
    ModelSpec(RotatingTrianglesSheet, _M + "rotating_triangles:build_sheet", "n_cols",
              theory="flexmm.analysis.predict.rotating_triangles:SHEET"),
    ModelSpec(RigidNetwork, _M + "network:build", "n_cols", theory="flexmm.analysis.predict.network:THEORY",
              bands="flexmm.linear.network:band_path"),
)

#: the ``lattice`` section of a scene: any registered config class, discriminated on ``kind``
LatticeConfig = Union[tuple(s.config for s in MODELS.values())]

__all__ = ["MODELS", "LatticeConfig", "ModelSpec", "RotatingSquaresChain"]
