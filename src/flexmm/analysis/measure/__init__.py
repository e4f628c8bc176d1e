"""What a run is measured for: travelling pulses (``pulses``, with their arrivals, widths and
steady part), transition fronts (``fronts``), driven response (``driven``, ``harmonics``),
oblique plane waves (``oblique``), collisions and formation transients (``collisions``,
``transients``), the energy budget (``energy``) and the special measurements of the outlook scenes
(``reflection``, ``periodic``, ``breathers``). Built on ``analysis.features``."""
