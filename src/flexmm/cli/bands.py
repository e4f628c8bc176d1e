"""``flexmm bands CONFIG``: the Bloch bands of a periodic rigid network, from the Hessian of its energy.

Writes ``bands.txt`` (one row per wave vector: path distance, k_x, k_y, then every branch's
frequency), ``bands.json`` and ``bands.png`` to the output directory (``flexmm.linear.network``).
"""

from __future__ import annotations

import json
from pathlib import Path

import typer

from flexmm.cli.common import OverrideOption, check_output_dir, error, load_or_exit, output_dir, writing

FILES = ("bands.txt", "bands.json", "bands.png")


def bands(
    config: str = typer.Argument(..., help="Scene YAML file (lattice kind rigid_network, periodic)."),
    overrides: list[str] = OverrideOption,
    points: int = typer.Option(64, "--points", min=4, max=4096, help="Wave vectors per segment of the path."),
    out: str = typer.Option(None, "--out", "-o", help="Output directory (default runs/<name>/bands)."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Only print the paths of the files written."),
) -> None:
    """Bloch bands ω(k) of a periodic network's cell along Γ–X–M–Γ (Γ–X with one periodic direction).

    The network must be periodic: a generated sheet with left/right and/or bottom/top periodic, or a
    geometry file with lattice_vectors_m. Frequencies in Hz, wave vectors in rad/m."""
    import numpy as np

    from flexmm.config.lattice import MODELS
    from flexmm.io.atomic import atomic_target, write_text_atomic

    scene = load_or_exit(config, list(overrides or []))
    band_path = MODELS[scene.lattice.kind].hook("bands")
    if band_path is None:
        raise error(f"flexmm bands computes the bands of a periodic rigid_network; {config} is a "
                    f"{scene.lattice.kind} (its bands: flexmm.linear)")
    folder = check_output_dir(Path(out) if out else Path(scene.output.directory) / scene.name / "bands")
    path = band_path(scene.lattice, points)
    f, k, dist = path["frequency_hz"], path["k_rad_m"], path["distance_rad_m"]
    head = "# distance_rad_m k_x_rad_m k_y_rad_m " + " ".join(f"f{b}_hz" for b in range(f.shape[1]))
    rows = [" ".join(f"{x:.10g}" for x in (dist[i], k[i, 0], k[i, 1], *f[i])) for i in range(len(dist))]
    labels = ", ".join(f"{name} at {d:.6g} rad/m" for d, name in path["labels"])
    output_dir(folder)
    with writing(folder):
        write_text_atomic(folder / "bands.txt", "\n".join([f"# {scene.name}: {labels}", head, *rows]) + "\n")
        write_text_atomic(folder / "bands.json", json.dumps(
            {"labels": path["labels"], "distance_rad_m": dist.tolist(), "k_rad_m": k.tolist(),
             "frequency_hz": [[None if x != x else x for x in row] for row in f.tolist()]}, indent=0))
        _figure(path, folder / "bands.png", scene.name, atomic_target)
    if quiet:
        for name in FILES:
            typer.echo(folder / name)
        return
    typer.echo(f"{scene.name}: {f.shape[1]} branches; {'the lowest ' if f.shape[1] > 12 else ''}at Γ (Hz): "
               + ", ".join(f"{x:.4g}" for x in f[0, :12]) + f"; highest {float(np.nanmax(f, initial=0.0)):.4g} Hz")
    typer.echo(f"written: {folder}/bands.{{txt,json,png}}")


def _figure(path: dict, target: Path, title: str, atomic_target) -> None:
    """ω(k) along the path, the corners marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 4.0))
    ax.plot(path["distance_rad_m"], path["frequency_hz"], color="C0", lw=1.2)
    for d, name in path["labels"]:
        ax.axvline(d, color="0.7", lw=0.6)
    ax.set_xticks([d for d, _ in path["labels"]], [name for _, name in path["labels"]])
    ax.set_xlim(0, path["distance_rad_m"][-1])
    ax.set_ylim(bottom=0)
    ax.set_ylabel("frequency (Hz)")
    ax.set_title(f"{title}: Bloch bands")
    fig.tight_layout()
    with atomic_target(target) as tmp:
        fig.savefig(tmp, dpi=120, format="png")
    plt.close(fig)
