"""Diagnostics of the integrators themselves, behind ``flexmm bench`` and ``flexmm stability``:
measured stability limits (``stability_scan``), work–precision diagrams (``workprecision``) and
the scipy ``solve_ivp`` baseline they are compared with (``baseline``)."""
