"""The package's structure stays as declared: layered, acyclic, one kernel table.

The import-linter contracts in pyproject.toml ([tool.importlinter]) list the layers top to
bottom and forbid cycles between sibling modules; this test runs them, so a new upward or
circular import fails CI with the offending import chain.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from flexmm.config.base import resolve
from flexmm.config.excitation import EXCITATIONS
from flexmm.config.lattice import HOOK_LAYERS, MODELS
from flexmm.models import model_fields

ROOT = Path(__file__).resolve().parents[1]


def test_import_contracts_hold() -> None:
    exe = shutil.which("lint-imports", path=str(Path(sys.executable).parent))
    assert exe is not None, "import-linter is a test dependency (pyproject [test] extra)"
    out = subprocess.run([exe, "--no-cache"], cwd=ROOT, capture_output=True, text=True)
    assert out.returncode == 0, out.stdout[-4000:] + out.stderr[-2000:]
    assert "3 kept, 0 broken" in out.stdout


@pytest.mark.parametrize("kind", sorted(MODELS))
def test_config_declares_the_fields_its_model_builds(kind: str) -> None:
    """The config layer names each kind's fields (to validate output.fields without importing
    the models); the model's FieldSpecs must agree."""
    assert MODELS[kind].config.FIELD_NAMES == model_fields(kind)


@pytest.mark.parametrize("kind", sorted(MODELS))
def test_model_hooks_live_in_their_layer_and_resolve(kind: str) -> None:
    """Each hook of a ModelSpec names an object of the layer that uses it, of the expected type:
    the registry sits in the config layer and must not make it depend on a layer above the user."""
    from flexmm.analysis.context import ModelTheory
    from flexmm.plan.continuum import ContinuumTheory

    spec = MODELS[kind]
    paths = {"builder": [spec.builder], "launcher": [spec.launcher], "theory": [spec.theory],
             "continuum": [spec.continuum], "reducers": list(spec.reducers.values())}
    paths |= {hook: [getattr(spec, hook)] for hook in ("topology", "hinges", "elements", "bands")}
    assert set(paths) == set(HOOK_LAYERS)
    for hook, items in paths.items():
        for path in filter(None, items):
            assert path.split(":")[0].startswith(HOOK_LAYERS[hook] + "."), (hook, path)
            assert resolve(path) is not None
    assert callable(spec.build) and spec.fields
    assert spec.launcher is None or callable(spec.launch_soliton)
    assert spec.theory is None or isinstance(spec.hook("theory"), ModelTheory)
    assert spec.continuum is None or isinstance(spec.hook("continuum"), ContinuumTheory)
    assert all(callable(spec.reducer(name)) for name in spec.reducers)
    assert spec.length is None or spec.config.model_fields[spec.length].annotation is int


def test_importing_the_config_imports_no_higher_layer() -> None:
    """Registry hooks are resolved lazily: loading the scene schema (and every registry) pulls in
    no models, analysis, planning or assembly code."""
    code = ("import sys, flexmm.config, flexmm.config.lattice, flexmm.config.excitation; "
            "print(sorted({m for m in sys.modules if m.startswith('flexmm.') and "
            "m.split('.')[1] not in ('config', 'errors', '_jit', '_version', 'units', 'io')}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout


@pytest.mark.parametrize("kind", sorted(EXCITATIONS))
def test_excitation_hooks_live_in_the_assembler_and_resolve(kind: str) -> None:
    """Each excitation kind's ``apply`` hook is a function of ``flexmm.assemble``."""
    import inspect

    spec = EXCITATIONS[kind]
    assert spec.apply.split(":")[0] == "flexmm.assemble", spec.apply
    fn = resolve(spec.apply)
    assert list(inspect.signature(fn).parameters) == ["system", "scene", "exc", "terms"]
