"""Data files shipped with flexmm (read with importlib.resources)."""
