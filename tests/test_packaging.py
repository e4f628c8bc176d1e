"""The package as a user installs it: the wheel built from the sources, installed outside the
repository, runs; its metadata carries the licence, the version and the type marker."""

from __future__ import annotations

import email.parser
import importlib.util
import os
import re
import shutil
import subprocess
import sys
import sysconfig
import tomllib
import zipfile
from pathlib import Path

import pytest
import yaml

import flexmm

ROOT = Path(__file__).resolve().parents[1]
#: what building the package reads (an sdist holds the same)
SOURCES = ("pyproject.toml", "README.md", "LICENSE", "CITATION.cff", "src")


def _run(cmd, **kw) -> subprocess.CompletedProcess:
    out = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, **kw)
    assert out.returncode == 0, f"{cmd}: exit {out.returncode}\n{out.stdout[-3000:]}\n{out.stderr[-3000:]}"
    return out


def _source_tree(tree: Path) -> Path:
    """A copy of what building reads, in ``tree`` (nothing is written into the repository)."""
    tree.mkdir(parents=True)
    for name in SOURCES:
        src = ROOT / name
        if src.is_dir():
            shutil.copytree(src, tree / name, ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
        else:
            shutil.copy2(src, tree / name)
    return tree


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """The wheel built from a copy of the sources."""
    tmp = tmp_path_factory.mktemp("wheel")
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet", "-w", tmp / "dist",
          _source_tree(tmp / "src-tree")])
    (whl,) = (tmp / "dist").glob("flexmm-*.whl")
    return whl


def test_the_wheel_carries_licence_type_marker_and_one_version(wheel):
    with zipfile.ZipFile(wheel) as z:
        names = z.namelist()
        meta_name = next(n for n in names if n.endswith(".dist-info/METADATA"))
        meta = email.parser.Parser().parsestr(z.read(meta_name).decode())
        licence = next(n for n in names if n.endswith("LICENSE") and ".dist-info/" in n)
        assert "MIT License" in z.read(licence).decode()
    assert "flexmm/py.typed" in names and "flexmm/data/raney2016_bistable_energy_coeffs.csv" in names
    assert meta["Version"] == flexmm.__version__ and wheel.name.startswith(f"flexmm-{flexmm.__version__}-")
    assert meta["License-Expression"] == "MIT"
    assert "flexmm developers" in (meta["Author"] or "")
    # the version is written in one place: nowhere else in pyproject or the package
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert "version" not in project and "version" in project["dynamic"]
    hits = [p for p in (ROOT / "src" / "flexmm").rglob("*.py")
            if re.search(rf"[\"']{re.escape(flexmm.__version__)}[\"']", p.read_text())]
    assert hits == [ROOT / "src" / "flexmm" / "_version.py"]


def test_citation_file_is_cff_1_2_0():
    """The fields CFF 1.2.0 requires, with the licence pyproject declares."""
    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text())
    assert cff["cff-version"] == "1.2.0"
    assert cff["message"] and cff["title"]
    assert cff["authors"] and all("name" in a or "family-names" in a for a in cff["authors"])
    assert cff["license"] == "MIT" and 'license = "MIT"' in (ROOT / "pyproject.toml").read_text()


@pytest.mark.slow
def test_the_wheel_installs_and_runs_outside_the_repository(wheel, tmp_path):
    """A new venv in tmp_path gets the wheel (the dependencies are those of the test environment,
    reached through a .pth file, so nothing is downloaded); ``flexmm --version`` and ``flexmm
    validate`` on a shipped config copied beside it run from there."""
    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", venv])
    py = venv / "bin" / "python"
    _run([sys.executable, "-m", "pip", "--python", py, "install", "--no-deps", "--quiet", wheel])
    site = Path(_run([py, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"]).stdout.strip())
    (site / "test-deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    shutil.copy2(ROOT / "configs" / "lego_vector_soliton.yaml", tmp_path / "scene.yaml")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "numba")  # compiled from the installed files, not the shared cache
    where = _run([py, "-c", "import flexmm; print(flexmm.__file__)"], cwd=tmp_path, env=env).stdout.strip()
    assert Path(where).is_relative_to(site), where
    exe = venv / "bin" / "flexmm"
    assert _run([exe, "--version"], cwd=tmp_path, env=env).stdout.strip() == f"flexmm {flexmm.__version__}"
    out = _run([exe, "validate", "scene.yaml"], cwd=tmp_path, env=env)
    assert "scene.yaml" in out.stdout + out.stderr
    bad = (tmp_path / "scene.yaml").read_text().replace("n_units: 900", "n_units: -3")
    (tmp_path / "bad.yaml").write_text(bad)
    res = subprocess.run([exe, "validate", "bad.yaml"], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert res.returncode == 2 and "lattice.n_units" in res.stderr and "Traceback" not in res.stderr


@pytest.mark.slow
def test_sdist_and_wheel_build_and_pass_twine_check(tmp_path):
    """What ``make release-check`` does, on a copy of the sources: ``python -m build`` makes an
    sdist and a wheel of the one version, and ``twine check --strict`` passes on both (the README
    renders as the package's long description)."""
    for tool in ("build", "twine"):
        if importlib.util.find_spec(tool) is None:
            pytest.skip(f"{tool} is not installed (pip install '.[release]', or make release-check)")
    _run([sys.executable, "-m", "build", "--outdir", tmp_path / "dist", _source_tree(tmp_path / "src-tree")])
    built = sorted(p.name for p in (tmp_path / "dist").iterdir())
    assert built == [f"flexmm-{flexmm.__version__}-py3-none-any.whl", f"flexmm-{flexmm.__version__}.tar.gz"]
    out = _run([sys.executable, "-m", "twine", "check", "--strict", *sorted((tmp_path / "dist").iterdir())])
    assert out.stdout.count("PASSED") == 2, out.stdout
