"""flexmm's version, written here only: the package (``flexmm.__version__``), the wheel's metadata
(pyproject.toml reads it: ``[tool.setuptools.dynamic]``) and every output's provenance take it
from this module. This module imports nothing."""

__version__ = "0.1.0"
