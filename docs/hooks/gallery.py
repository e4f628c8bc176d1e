"""The documentation site's scene gallery, generated from configs/ (an MkDocs hook and a script).

For each scene file, an *entry* (``runs/docs/gallery/NAME.json`` and ``NAME.png``) holds a
picture and what ``flexmm analyze`` measures against theory. A scene whose run is short (an
estimated work of at most ``BUDGET_UNIT_STEPS`` unit-steps at the default step) is run in full
through the Python API (``flexmm.run``, ``flexmm.analyze``, ``flexmm.render``: the space-time
diagram with the structure at mid-run); a longer one gets a picture of its structure at rest
from a run of a few steps, and no measurement.

As a script (``make docs`` runs it once per scene, so ``make -j2 docs`` makes two at a time and a
scene is remade only when its file changes)::

    python docs/hooks/gallery.py configs/NAME.yaml runs/docs/gallery

As a hook (mkdocs.yml), it makes any entry that is missing or stale (the scene file's hash or the
flexmm version differs), then adds the gallery pages: an index with one row per scene and one page
per scene, listed in the navigation under "Gallery". In a quick build (docs/hooks/quick.py) it runs
nothing: a scene without a current entry gets a page that says so (``skipped_entry``).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import sys
import time
from pathlib import Path

#: above this estimated work (units × steps at the default step) a scene is not run for the gallery
BUDGET_UNIT_STEPS = 2e8
ENTRIES = Path("runs/docs/gallery")  # relative to the directory of mkdocs.yml
CONFIGS = Path("configs")
PICTURE_WIDTH = 800


def _sha(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()


def _header(text: str) -> str:
    """The scene file's leading comment block, as prose."""
    lines = []
    for line in text.splitlines():
        if not line.startswith("#"):
            break
        lines.append(line[1:].strip())
    return "\n".join(lines)


def _shown(config: Path) -> str:
    """The scene file's path as a reader would type it: relative to the working directory."""
    try:
        return config.resolve().relative_to(Path.cwd().resolve()).as_posix()
    except ValueError:
        return config.as_posix()


def _write(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_bytes(data)
    os.replace(tmp, path)


def make_entry(config: Path, out_dir: Path, budget: float = BUDGET_UNIT_STEPS) -> dict:
    """Run (or, over ``budget``, only draw) one scene and write its entry; returns the entry."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    import flexmm
    from flexmm.config import load_scene
    from flexmm.errors import FlexmmError
    from flexmm.plan.cost import estimate

    text = config.read_text()
    scene = load_scene(config)
    cost = estimate(scene)
    work = cost.n_sites * cost.steps if cost.steps else math.inf
    t0 = time.perf_counter()
    entry = {"name": scene.name, "config": _shown(config), "config_sha256": _sha(text),
             "flexmm_version": flexmm.__version__, "description": scene.description or "",
             "header": _header(text), "work_unit_steps": work, "picture": f"{scene.name}.png"}
    if work <= budget:
        res = flexmm.run(config)
        ds = res.dataset
        t_pic = float(ds.time[ds.sizes["time"] // 2])
        entry.update(mode="run", status=res.status, message=res.message, error_estimate=res.error_estimate,
                     accuracy_target=res.accuracy.get("accuracy_requested"))
        try:
            m = flexmm.analyze(ds)
            entry.update(summary=str(m).splitlines(), comparisons=m.comparisons)
        except FlexmmError as exc:
            entry.update(summary=[f"nothing measured: {exc}"], comparisons=[])
        try:
            fig = flexmm.render(ds, t=t_pic, spacetime=True, width=PICTURE_WIDTH)
            entry["render"] = f"flexmm render RUN -t {t_pic:.4g} --spacetime --width {PICTURE_WIDTH}"
        except FlexmmError:  # nothing to draw a space-time diagram of: the frame alone
            fig = flexmm.render(ds, t=t_pic, width=PICTURE_WIDTH)
            entry["render"] = f"flexmm render RUN -t {t_pic:.4g} --width {PICTURE_WIDTH}"
    else:
        res = flexmm.run(config, **{"solver.duration_s": 20 * cost.dt_s, "output.n_frames": 2})
        fig = flexmm.render(res.dataset, t=0.0, width=PICTURE_WIDTH)
        entry.update(mode="structure", status=res.status, message=res.message, error_estimate=None,
                     summary=[], comparisons=[], render=f"flexmm render RUN -t 0 --width {PICTURE_WIDTH}")
    entry["wall_s"] = time.perf_counter() - t0
    out_dir.mkdir(parents=True, exist_ok=True)
    tmp = out_dir / f".{scene.name}.png.tmp"
    fig.savefig(tmp, format="png")
    plt.close(fig)
    os.replace(tmp, out_dir / entry["picture"])
    _write(out_dir / f"{config.stem}.json", json.dumps(entry, indent=1).encode())
    return entry


def skipped_entry(config: Path) -> dict:
    """The entry of a scene the quick build does not run: its name and description, no picture."""
    from flexmm.config import load_scene

    text = config.read_text()
    scene = load_scene(config)
    return {"name": scene.name, "config": _shown(config), "description": scene.description or "",
            "header": _header(text), "mode": "skipped", "picture": None, "summary": [], "comparisons": []}


def load_entry(config: Path, out_dir: Path) -> dict | None:
    """The entry of ``config`` if it is there and current (same scene text, same flexmm version)."""
    import flexmm

    path = out_dir / f"{config.stem}.json"
    if not path.exists():
        return None
    entry = json.loads(path.read_text())
    current = (entry.get("config_sha256") == _sha(config.read_text())
               and entry.get("flexmm_version") == flexmm.__version__
               and (out_dir / entry.get("picture", "")).is_file())
    return entry if current else None


# ---- pages ------------------------------------------------------------------------------------


def _num(x) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return ""
    return f"{x:.4g}" if isinstance(x, float) else str(x)


def _cell(text) -> str:
    return " ".join(str(text).split()).replace("|", "\\|")


def headline(entry: dict) -> str:
    """One line for the index: the principal measurement, or why there is none."""
    if entry["mode"] == "skipped":
        return "not run in this quick build of the site (`make docs` runs it)"
    if entry["mode"] == "structure":
        return f"not run for the site (≈ {entry['work_unit_steps']:.2g} unit-steps): structure at rest"
    if entry["status"] != "finished":
        return f"run {entry['status']}: {entry['message']}"
    return entry["summary"][0] if entry["summary"] else "nothing measured"


def scene_page(entry: dict, config_text: str) -> str:
    """The Markdown of one scene's page."""
    name = entry["name"]
    lines = [f"# {name}", "", entry["description"], ""]
    if entry["picture"]:
        lines += [f"![{name}]({entry['picture']})", ""]
    if entry["mode"] == "skipped":
        lines += [f"*Not run in this quick build of the site*: `make docs` runs it, or run it yourself "
                  f"with `flexmm run {entry['config']}`.", ""]
    elif entry["mode"] == "run":
        est = entry["error_estimate"]
        lines += [f"*Made by this site's build from `{entry['config']}`*: `flexmm run {entry['config']}` "
                  f"(status {entry['status']}, {entry['wall_s']:.1f} s, any compilation included"
                  + (f"; estimated error {est:.2g} of the wave amplitudes and speeds" if est is not None else "")
                  + f"), then `{entry['render']}` (flexmm {entry['flexmm_version']}).", ""]
        lines += ["## Measured against theory", "", "What `flexmm run` prints after the run "
                  "(`flexmm analyze RUN` gives the full table):", "", "```text", *entry["summary"], "```", ""]
        rows = [c for c in entry["comparisons"] if c.get("predicted") is not None]
        if rows:
            lines += ["| item | quantity | measured | theory | units | difference | note |",
                      "| --- | --- | --- | --- | --- | --- | --- |"]
            for c in rows:
                diff = c.get("rel_diff")
                diff = "" if diff is None or not math.isfinite(diff) else f"{100 * diff:+.2f} %"
                lines.append(f"| {_cell(c['item'])} | {_cell(c['quantity'])} | {_num(c['measured'])} | "
                             f"{_num(c['predicted'])} | {_cell(c.get('units') or '')} | {diff} | "
                             f"{_cell(c.get('note') or '')} |")
            lines.append("")
    else:
        lines += [f"*The structure at rest*, from a run of a few steps: the full run (≈ "
                  f"{entry['work_unit_steps']:.2g} unit-steps) is too long for the site's build. Run it "
                  f"with `flexmm run {entry['config']}`.", ""]
    lines += ["## The scene", "", "```text", entry["header"], "```", "",
              f'??? note "{entry["config"]}"', "", "    ```yaml",
              *[f"    {line}" for line in config_text.splitlines()], "    ```", ""]
    return "\n".join(lines)


def index_page(entries: list[dict]) -> str:
    """The gallery's front page: one row per scene."""
    lines = ["# Scene gallery", "",
             "Every scene shipped in `configs/`, run by this site's build: its picture (the space-time "
             "diagram of the scene's main field with the structure at mid-run) and what `flexmm analyze` "
             "measures against theory. Nothing here is pasted: the pages are made from the scene files "
             f"each time the site is built (scenes over {BUDGET_UNIT_STEPS:.0e} unit-steps are drawn at "
             "rest instead of run). The [scenes guide](../scenes.md) explains what each shows and its caveats.",
             "", "| scene | picture | measured against theory |", "| --- | --- | --- |"]
    for e in entries:
        picture = f"![{e['name']}]({e['picture']}){{ width=240 }}" if e["picture"] else ""
        lines.append(f"| [{e['name']}]({e['name']}.md)<br>{_cell(e['description'])} | {picture} | "
                     f"{_cell(headline(e))} |")
    return "\n".join(lines) + "\n"


# ---- the MkDocs hook --------------------------------------------------------------------------


def _root(config) -> Path:
    return Path(config.config_file_path).resolve().parent


def _scenes(config) -> list[Path]:
    return sorted((_root(config) / CONFIGS).glob("*.yaml"))


def on_config(config):
    """List one page per scene under "Gallery" in the navigation."""
    pages = ["gallery/index.md", *[f"gallery/{p.stem}.md" for p in _scenes(config)]]
    for i, item in enumerate(config.nav or []):
        if isinstance(item, dict) and "Gallery" in item:
            config.nav[i] = {"Gallery": pages}
    return config


def on_files(files, config):
    """Make missing or stale entries, then add the gallery's pages and pictures."""
    from mkdocs.structure.files import File

    root = _root(config)
    out_dir = root / ENTRIES
    quick = config.extra.get("quick_build", False)  # docs/hooks/quick.py
    entries = []
    for path in _scenes(config):
        entry = load_entry(path, out_dir)
        if entry is None and quick:
            entry = skipped_entry(path)
        elif entry is None:
            print(f"gallery: making the entry of {path.name}", file=sys.stderr, flush=True)
            entry = make_entry(path, out_dir)
        entries.append(entry)
        files.append(File.generated(config, f"gallery/{path.stem}.md", content=scene_page(entry, path.read_text())))
        if entry["picture"]:
            files.append(File.generated(config, f"gallery/{entry['picture']}",
                                        abs_src_path=str(out_dir / entry["picture"])))
    files.append(File.generated(config, "gallery/index.md", content=index_page(entries)))
    return files


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: python docs/hooks/gallery.py configs/NAME.yaml OUT_DIR")
    e = make_entry(Path(sys.argv[1]), Path(sys.argv[2]))
    print(f"{sys.argv[1]}: {e['mode']}, {e['wall_s']:.1f} s: {headline(e)}")
