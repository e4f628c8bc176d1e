"""The documentation site: its gallery entries are made from scene files (docs/hooks/gallery.py);
the quick build (``FLEXMM_DOCS_QUICK=1 mkdocs build --strict``: every page, the references and the
links, nothing executed) is in the default suite, and ``make docs``, the whole site with its
gallery runs and executed tutorials, is a slow test."""

from __future__ import annotations

import importlib.util
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
#: the tutorials (docs/tutorials/NAME.md), executed by ``make docs``
TUTORIALS = ("first-scene", "parameter-scan", "fit", "network")

#: a chain of masses with softening bonds pulled outward (the first tutorial's scene, shorter)
SCENE = {
    "name": "gallery_test_chain",
    "description": "A short softening chain pulled outward.",
    "lattice": {"kind": "mass_chain", "n_units": 80, "spacing_m": 0.03, "mass_kg": 0.01,
                "bond": {"law": "polynomial", "k1_n_per_m": 500.0, "k2_n_per_m2": 66666.7}},
    "excitation": {"kind": "impact", "end": "left", "velocity_m_s": -1.0},
    "solver": {"duration_s": 0.25},
    "output": {"n_frames": 101},
}


def _gallery():
    spec = importlib.util.spec_from_file_location("docs_gallery", ROOT / "docs" / "hooks" / "gallery.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture
def scene_file(tmp_path) -> Path:
    path = tmp_path / "gallery_test_chain.yaml"
    path.write_text("# A test scene.\n# Second line of its header.\n" + yaml.safe_dump(SCENE, sort_keys=False))
    return path


def test_gallery_entry_of_a_short_scene_is_a_run_with_its_measurement(scene_file, tmp_path):
    """Under the budget the scene runs in full: the entry holds the pulse measured against the
    softening chain's theory, the picture is drawn at the site's width, and the entry is current
    until the scene file changes."""
    g = _gallery()
    out = tmp_path / "entries"
    entry = g.make_entry(scene_file, out)
    assert entry["mode"] == "run" and entry["status"] == "finished"
    assert entry["header"] == "A test scene.\nSecond line of its header."
    assert re.match(r"pulse 0 .*in strain \(tensile \(rarefaction\).*speed [\d.]+ .*m/s \(theory [\d.]+, [-+][\d.]+ %\)",
                    entry["summary"][0]), entry["summary"]
    speed = [c for c in entry["comparisons"] if c["item"] == "pulse 0" and c["quantity"] == "speed"]
    assert speed and abs(speed[0]["rel_diff"]) < 0.02  # the sech² law of docs/physics.md §2
    assert Image.open(out / entry["picture"]).size[0] == g.PICTURE_WIDTH
    assert json.loads((out / "gallery_test_chain.json").read_text()) == json.loads(json.dumps(entry))
    assert g.load_entry(scene_file, out) is not None
    page = g.scene_page(entry, scene_file.read_text())
    assert "## Measured against theory" in page and entry["summary"][0] in page
    assert "| pulse 0 | speed |" in page
    assert entry["summary"][0] in g.index_page([entry])
    scene_file.write_text(scene_file.read_text().replace("velocity_m_s: -1.0", "velocity_m_s: -1.2"))
    assert g.load_entry(scene_file, out) is None  # a changed scene is made again


def test_gallery_entry_over_the_budget_is_the_structure_at_rest(scene_file, tmp_path):
    g = _gallery()
    entry = g.make_entry(scene_file, tmp_path, budget=0)
    assert entry["mode"] == "structure" and entry["summary"] == [] and entry["comparisons"] == []
    assert (tmp_path / entry["picture"]).is_file()
    assert "not run for the site" in g.headline(entry)
    assert "*The structure at rest*" in g.scene_page(entry, scene_file.read_text())


def _mkdocs(cwd: Path, site: Path, **env) -> subprocess.CompletedProcess:
    pytest.importorskip("mkdocs", reason="the docs extra is not installed (make test installs it)")
    return subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)], cwd=cwd,
                          capture_output=True, text=True, env={**os.environ, "NO_MKDOCS_2_WARNING": "1", **env})


def test_quick_build_renders_every_page_and_reference(tmp_path):
    """The quick build (docs/hooks/quick.py) passes --strict (no warning, broken link or anchor): a
    page per scene (made from the scene file, no run), the CLI reference with every command, the
    API reference, and the tutorials with their code shown, not run."""
    import typer

    from flexmm.cli import app

    site = tmp_path / "site"
    done = _mkdocs(ROOT, site, FLEXMM_DOCS_QUICK="1")
    assert done.returncode == 0, f"{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    for config in sorted((ROOT / "configs").glob("*.yaml")):
        page = (site / "gallery" / f"{config.stem}.html").read_text()
        assert any(s in page for s in ("Not run in this quick build", "Measured against theory",
                                       "The structure at rest")), config.name
    cli = (site / "reference" / "cli.html").read_text()
    for name in typer.main.get_command(app).commands:
        assert f"flexmm {name}" in cli, name
    assert "flexmm.api.run" in (site / "reference" / "api.html").read_text()
    for page in TUTORIALS:
        html = (site / "tutorials" / f"{page}.html").read_text()
        source = (ROOT / "docs" / "tutorials" / f"{page}.md").read_text()
        # every fence (executed ones included) is a highlighted code block, none left as text
        fences = sum(1 for line in source.splitlines() if line.startswith("```")) // 2
        assert html.count('<div class="highlight">') == fences > 0, page
        assert 'exec="' not in html, page
    assert not re.search(r"speed \d+\.\d+ m/s", (site / "tutorials" / "first-scene.html").read_text())  # not run


def test_strict_build_fails_on_a_broken_link_or_anchor(tmp_path):
    """The site's settings (mkdocs.yml, inherited) turn a link to a missing page and a link to a
    missing heading into errors."""
    (tmp_path / "docs").mkdir()
    (tmp_path / "mkdocs.yml").write_text(f"INHERIT: {ROOT / 'mkdocs.yml'}\ndocs_dir: docs\nhooks: []\n"
                                         "plugins: [search]\nnav: [index.md]\n")
    index = tmp_path / "docs" / "index.md"
    for body, message in (("[a page](missing.md)", "missing.md"), ("[a heading](#no-such-heading)", "no-such-heading")):
        index.write_text(f"# Home\n\n{body}\n")
        done = _mkdocs(tmp_path, tmp_path / "site")
        assert done.returncode != 0 and message in done.stderr, done.stderr[-2000:]
    index.write_text("# Home\n\n[a heading](#home)\n")
    assert _mkdocs(tmp_path, tmp_path / "site").returncode == 0


@pytest.mark.slow
def test_make_docs_builds_the_site(tmp_path):
    """``make docs`` (strict: any warning, broken link or failing snippet fails it) writes a page
    per scene with its measurement, the CLI reference with every command, the API reference and
    the executed tutorials."""
    import typer

    from flexmm.cli import app

    site = tmp_path / "site"
    t0 = time.perf_counter()
    done = subprocess.run(["make", "-C", str(ROOT), "docs", f"VENV={sys.prefix}", f"SITE_DIR={site}"],
                          capture_output=True, text=True, env={**os.environ, "MAKEFLAGS": ""})
    assert done.returncode == 0, f"{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    print(f"make docs: {time.perf_counter() - t0:.1f} s")
    assert (site / "index.html").is_file()
    for config in sorted((ROOT / "configs").glob("*.yaml")):
        page = (site / "gallery" / f"{config.stem}.html").read_text()
        assert "Measured against theory" in page or "The structure at rest" in page, config.name
        assert (site / "gallery" / f"{config.stem}.png").is_file()
    cli = (site / "reference" / "cli.html").read_text()
    group = typer.main.get_command(app)
    for name in group.commands:
        assert f"flexmm {name}" in cli, name
    assert "flexmm.api.run" in (site / "reference" / "api.html").read_text()
    tutorial = (site / "tutorials" / "first-scene.html").read_text()
    assert re.search(r"speed \d+\.\d+ m/s", tutorial)  # the snippets ran and printed their output
    fit = (site / "tutorials" / "fit.html").read_text()
    assert re.search(r"reduced χ² = 1\.0\d", fit) and fit.count("relative error") >= 3
    network = (site / "tutorials" / "network.html").read_text()
    m = re.search(r"measured ([\d.]+) m/s against the long-wave speed ([\d.]+) m/s", network)
    assert m and abs(float(m.group(1)) / float(m.group(2)) - 1) < 0.03, m
