"""``flexmm --help``, ``validate`` and ``schema`` start fast: no plotting, xarray or signal processing.

Each case runs in a fresh interpreter (the test process has imported everything already) and
lists the heavy modules that are loaded after the command ran through Typer's CliRunner.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "lego_vector_soliton.yaml"

PROBE = """
import json, sys
from typer.testing import CliRunner
from flexmm.cli import app
result = CliRunner().invoke(app, json.loads(sys.argv[1]))
assert result.exit_code == 0, result.output
heavy = sorted(m for m in sys.modules
               if m.split('.')[0] in ('matplotlib', 'xarray', 'pandas') or m.startswith('scipy.signal'))
print(json.dumps({"heavy": heavy, "scipy": 'scipy' in sys.modules, "numba": 'numba' in sys.modules}))
"""


def loaded_after(*args: str) -> dict:
    proc = subprocess.run([sys.executable, "-c", PROBE, json.dumps(list(args))],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("args", [["--help"], ["--version"], ["schema"], ["run", "--help"], ["analyze", "--help"],
                                  ["validate", str(CONFIG)], ["validate", str(CONFIG), "--no-build"]],
                         ids=["help", "version", "schema", "run-help", "analyze-help", "validate", "validate-no-build"])
def test_no_plotting_xarray_or_signal_imports(args):
    assert loaded_after(*args)["heavy"] == []


def test_help_imports_neither_scipy_nor_numba():
    loaded = loaded_after("--help")
    assert not loaded["scipy"] and not loaded["numba"]


def test_run_and_its_summary_import_no_dask(tmp_path):
    """xarray would import dask and dask.array (~0.3 s) at the first array it wraps, to ask whether
    it is a dask array (issue 37): ``flexmm run`` with its printed summary, and ``analyze``, read and
    measure the run without importing dask (``io.lazy_xarray``)."""
    probe = PROBE.replace("'pandas')", "'pandas', 'dask')")
    out = str(tmp_path / "r")
    for args in (["run", str(CONFIG), "--out", out, "-s", "solver.duration_s=0.2", "-s", "output.n_frames=201"],
                 ["analyze", out]):
        proc = subprocess.run([sys.executable, "-c", probe, json.dumps(args)], capture_output=True, text=True,
                              timeout=600)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        heavy = json.loads(proc.stdout.strip().splitlines()[-1])["heavy"]
        assert "xarray" in heavy and not [m for m in heavy if m.split(".")[0] == "dask"], heavy


def test_deferred_dask_checks_still_see_dask_arrays():
    """Once dask is imported, the xarray that ``io.lazy_xarray`` returns knows its arrays as before."""
    probe = """
import sys
from flexmm.io.lazy_xarray import xarray
xr = xarray()
v = xr.Variable(("x",), [1.0, 2.0])
assert "dask" not in sys.modules and v.chunks is None
import dask.array as da
from xarray.namedarray.pycompat import array_type, is_chunked_array, mod_version
d = xr.DataArray(da.zeros(4, chunks=2), dims="x")
assert d.chunks == ((2, 2),) and is_chunked_array(d.variable._data) and array_type("dask") == (da.Array,)
assert str(mod_version("dask")) == __import__("dask").__version__
assert float(d.sum().compute()) == 0.0
print("ok")
"""
    proc = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0 and proc.stdout.strip() == "ok", proc.stdout + proc.stderr
