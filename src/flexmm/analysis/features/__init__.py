"""Feature primitives on sampled fields: peaks and their widths (``peaks``), peaks tracked from
frame to frame (``detect``), pulse shapes and their fits (``profiles``), the field a measurement
reads (``fields``), the rest state it is measured from (``rest``) and the Hilbert envelope
(``envelope``). Arrays in, arrays out; nothing here knows about pulses, fronts or theory."""
