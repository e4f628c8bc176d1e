"""Pictures and movies of the deformed structure of a run (``flexmm render``).

Layers (each module a few hundred lines at most): ``source`` streams a dataset's frames;
``params`` and ``masses`` read the lattice parameters from the stored config (no model rebuild);
``rigid`` and ``structure`` turn one frame's fields into polygons, lines and bodies; ``colour``
chooses what colours them; ``figure`` draws with matplotlib collections updated in place;
``movie`` writes GIF (Pillow) and MP4 (ffmpeg); ``api.render_run`` ties them together.

This package is also the notebook API's ``flexmm.render(run, t=...)``: importing a submodule
of a package binds the package itself as ``flexmm.render``, so the package is made callable
(``api.figure``) rather than shadowing a function of the same name.
"""

import sys
import types

from flexmm.render.api import RenderOptions, figure, render_run


class _CallableModule(types.ModuleType):
    """``flexmm.render(run, t=None, **options)``: ``flexmm.render.api.figure``."""

    def __call__(self, run, t=None, **options):
        return figure(run, t, **options)


sys.modules[__name__].__class__ = _CallableModule

__all__ = ["RenderOptions", "figure", "render_run"]
