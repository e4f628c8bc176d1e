"""What a bistable linkage's run is about (docs/physics.md): its joints are bistable, so its waves
are transition fronts that switch the bars' angle θ from one well to the other. No front speed
law is derived for it in docs/physics.md, so nothing is predicted: the analysis measures the
front in θ and compares it with nothing.
"""

from __future__ import annotations

from flexmm.analysis.context import ModelTheory


def analysis(ctx) -> str:
    """'front': every joint of the linkage is bistable."""
    return "front"


#: the theory registered for ``bistable_linkage`` (``config.lattice.MODELS``)
THEORY = ModelTheory(analysis=analysis, front_field="theta")
