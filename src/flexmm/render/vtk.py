"""``flexmm export RUN --format vtk``: a run's units as a VTK time series that ParaView opens.

One VTK UnstructuredGrid file (``.vtu``, XML, ASCII) per frame: a point per saved unit at its
position in that frame (the centre of a rigid unit, a mass's body: the geometry the pictures of
``flexmm render`` are drawn from, ``render.structure``, at no exaggeration), one vertex cell
per point, and as point data every site field the run saved (as stored, SI units), the site
index and, for rigid units, their orientation in the plane. A ParaView collection (``.pvd``)
lists the frames with their times; it is written last, so a collection that exists is complete.
Every file is written under a temporary name and renamed.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from flexmm.errors import OutputError
from flexmm.io.atomic import atomic_target, write_text_atomic
from flexmm.render.api import load_lattice
from flexmm.render.source import RunSource
from flexmm.render.structure import ShapeStructure, make_structure

#: VTK's cell type of a single point
VTK_VERTEX = 1


def _numbers(values: np.ndarray) -> str:
    """ASCII of an array: floats as their shortest exact repr (read back bit for bit), ints as ints."""
    flat = np.asarray(values).ravel()
    return " ".join(map(repr, flat.tolist())) if flat.dtype.kind == "f" else " ".join(map(str, flat.tolist()))


def _array(name: str | None, values: np.ndarray, components: int = 1) -> str:
    kind = {"f": "Float64", "i": "Int64", "u": "UInt8"}[np.asarray(values).dtype.kind]
    named = f" Name={quoteattr(name)}" if name else ""
    comps = f' NumberOfComponents="{components}"' if components > 1 else ""
    return f'<DataArray type="{kind}"{named}{comps} format="ascii">{_numbers(values)}</DataArray>'


def vtu_text(points: np.ndarray, point_data: dict[str, np.ndarray]) -> str:
    """A VTK XML UnstructuredGrid of ``points`` (n, 2 or 3; metres) as vertex cells with ``point_data``."""
    n = points.shape[0]
    xyz = np.zeros((n, 3))
    xyz[:, : points.shape[1]] = points
    data = "\n".join(_array(name, np.asarray(v)) for name, v in point_data.items())
    return (
        '<?xml version="1.0"?>\n'
        '<VTKFile type="UnstructuredGrid" version="0.1" byte_order="LittleEndian">\n'
        "<UnstructuredGrid>\n"
        f'<Piece NumberOfPoints="{n}" NumberOfCells="{n}">\n'
        f"<PointData>\n{data}\n</PointData>\n"
        f"<Points>\n{_array(None, xyz, 3)}\n</Points>\n"
        "<Cells>\n"
        f"{_array('connectivity', np.arange(n, dtype=np.int64))}\n"
        f"{_array('offsets', np.arange(1, n + 1, dtype=np.int64))}\n"
        f"{_array('types', np.full(n, VTK_VERTEX, dtype=np.uint8))}\n"
        "</Cells>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n"
    )


def pvd_text(entries: list[tuple[float, str]]) -> str:
    """A ParaView collection of (time s, file name) entries."""
    rows = "\n".join(f'<DataSet timestep="{t!r}" group="" part="0" file={quoteattr(f)}/>' for t, f in entries)
    return ('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">\n'
            f"<Collection>\n{rows}\n</Collection>\n</VTKFile>\n")


def export_vtk(run, out: str | Path | None = None, *, start_s: float | None = None, stop_s: float | None = None,
               every: int = 1, log: Callable[[str], None] | None = None) -> Path:
    """Write a run's frames (``start_s`` to ``stop_s``, every ``every``-th) as ``<name>.pvd`` and
    ``<name>_NNNNN.vtu`` in ``out`` (default ``RUN/vtk``); returns the .pvd path."""
    from flexmm.errors import UsageError

    if every < 1:
        raise UsageError(f"--every must be ≥ 1, got {every}")
    with RunSource(run) as src:
        target = Path(out) if out is not None else src.path.parent / "vtk"
        structure = make_structure(src, load_lattice(src), None, 1.0)
        indices = src.window(start_s, stop_s)[::every]
        names = src.fields
        try:
            target.mkdir(parents=True, exist_ok=True)
            entries = []
            for i, t, frame in src.frames(indices, names):
                data = {name: frame[name] for name in names}
                data["site"] = src.sites.astype(np.int64)
                if isinstance(structure, ShapeStructure):
                    points, phi = structure.state(frame)
                    data["orientation_rad"] = structure.orientation(phi)
                else:
                    points = structure.positions(frame)
                file = f"{src.name}_{i:05d}.vtu"
                with atomic_target(target / file) as tmp:
                    tmp.write_text(vtu_text(points, data))
                entries.append((t, file))
            pvd = target / f"{src.name}.pvd"
            write_text_atomic(pvd, pvd_text(entries))
        except OSError as exc:
            raise OutputError(f"cannot write {target}: {exc.strerror or exc}") from None
    if log:
        log(f"wrote {pvd}: {len(entries)} frames of {src.sites.size} units "
            f"(t = {entries[0][0]:.6g} s to {entries[-1][0]:.6g} s)")
    return pvd


__all__ = ["export_vtk", "pvd_text", "vtu_text"]
