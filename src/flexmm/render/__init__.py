"""Pictures and movies of the deformed structure of a run (``flexmm render``).

Layers (each module a few hundred lines at most): ``source`` streams a dataset's frames;
``params`` and ``masses`` read the lattice parameters from the stored config (no model rebuild);
``rigid`` and ``structure`` turn one frame's fields into polygons, lines and bodies; ``colour``
chooses what colours them; ``figure`` draws with matplotlib collections updated in place;
``movie`` writes GIF (Pillow) and MP4 (ffmpeg); ``api.render_run`` ties them together.
"""

from flexmm.render.api import RenderOptions, render_run

__all__ = ["RenderOptions", "render_run"]
