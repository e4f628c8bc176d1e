"""Streaming, atomic netCDF4 writer for run outputs (readable with xarray, engine h5netcdf).

Frames are buffered and flushed in chunks along an unlimited ``time`` dimension, so a run
far larger than memory streams to disk. Everything goes to a hidden temporary file that is
renamed into place only when closed: a reader never sees a half-written dataset.

A full disk never leaves a file that cannot be closed: before a batch of frames is written the
writer checks that the filesystem has room for the chunks it will allocate (``_room``), and
every batch is flushed to disk (``H5Fflush``) before its frames count as written, so
``n_written`` are frames really on disk. A small reserve file (``RESERVE_BYTES``) is held
beside the dataset from the start and released when writing fails, so the file's metadata
can still be written and the file closed. If HDF5 fails anyway (another process filled the
disk during a batch), the file is abandoned and ``close`` returns None: nothing is kept,
and ``closed_why`` says why.
"""

from __future__ import annotations

import contextlib
import errno
import gc
import io
import os
import sys
from pathlib import Path

import h5netcdf
import numpy as np

from flexmm.io.atomic import temporary_name
from flexmm.io.cf import global_attrs, variable_attrs

#: suffix of the site coordinates holding a run's rest state (``u_rest``, ``theta_rest``)
REST_SUFFIX = "_rest"
#: suffix of the site coordinates holding a run's initial state (``u_initial``, ``u_dot_initial``)
INITIAL_SUFFIX = "_initial"
#: values of a field variable's ``reference`` attribute: what its values are measured from
REFERENCES = ("absolute", "rest_state")

BUFFER_BYTES = 32 * 2**20
CHUNK_BYTES = 4 * 2**20
#: space held beside a dataset being written, released so a writer that hit a full disk can close it
RESERVE_BYTES = 2**20
#: room kept free beyond a batch's chunks (HDF5 metadata: chunk index, attributes)
METADATA_BYTES = 256 * 2**10


#: HDF5 files given up after a write failure (``DatasetWriter._abandon``); never closed
ABANDONED: list = []


def leave(code) -> None:
    """End the process at once with exit status ``code`` if a dataset was abandoned: the normal
    exit would have HDF5 flush it again, print errors and crash (exit 139). Otherwise return."""
    if not ABANDONED:
        return
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    os._exit(code if isinstance(code, int) else 0 if code is None else 1)


class WriteFailed(OSError):
    """HDF5 failed to write (a full disk, an I/O error): the file cannot be trusted or closed."""


@contextlib.contextmanager
def _quiet_unraisable():
    """h5py reports failures to close objects it deallocates as 'Exception ignored' tracebacks:
    the writer already reports the failure, once, as a message."""
    hook, err = sys.unraisablehook, sys.stderr
    sys.unraisablehook = lambda _info: None
    sys.stderr = io.StringIO()  # Cython prints such a traceback itself before calling the hook
    try:
        yield
    finally:
        sys.unraisablehook, sys.stderr = hook, err


def _reserve(path: Path, nbytes: int) -> Path | None:
    """Hold ``nbytes`` of disk in ``path`` (None where the disk has not even that)."""
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    except OSError:
        return None
    try:
        try:
            os.posix_fallocate(fd, 0, nbytes)
        except (AttributeError, OSError) as exc:
            if getattr(exc, "errno", None) != errno.EOPNOTSUPP and not isinstance(exc, AttributeError):
                raise
            os.write(fd, bytes(nbytes))
        return path
    except OSError:
        os.close(fd)
        fd = -1
        path.unlink(missing_ok=True)
        return None
    finally:
        if fd >= 0:
            os.close(fd)


def _attrs(name: str, units: str, long_name: str, extra: list[dict]) -> dict:
    """CF attrs of a variable given as (units, long_name[, attrs])."""
    return variable_attrs(name, {"units": units, "long_name": long_name, **(extra[0] if extra else {})})


def _check_frames(f, src: Path, n: int, t_last: float) -> None:
    """``OSError`` unless the open dataset ``f`` holds at least ``n`` frames, frame ``n − 1`` at ``t_last`` s."""
    times = f.variables["time"]
    if times.shape[0] < n or (n and float(times[n - 1]) != t_last):
        found = times.shape[0] if times.shape[0] < n else f"time {float(times[n - 1])!r} s at frame {n - 1}"
        raise OSError(errno.EINVAL, f"it does not hold the checkpoint's {n} frames to t = {t_last!r} s "
                                    f"(it holds {found})", str(src))


class DatasetWriter:
    """Write (time, site) fields and per-time scalars; call ``close`` to publish the file.

    ``site_vars``: name -> (units, long_name[, attrs]); ``time_vars`` likewise; ``site_coords``:
    name -> (values (n_site,), units, long_name[, attrs]); ``constants``: name -> (dimensions, values,
    units, long_name) of constant variables on dimensions of their own (the units' shapes:
    ``shape_variables``). ``n_frames``: the frames the run will write,
    if known: the time dimension is then fixed-size (readers open such files ~2× faster than
    ones with an unlimited dimension, whose size h5netcdf recomputes from every variable); a run
    that stops early is cut to the frames it wrote when it closes.
    """

    def __init__(self, path: Path, n_site: int, site_vars: dict, time_vars: dict, site_coords: dict,
                 n_frames: int | None = None, constants: dict | None = None):
        self.path = Path(path)
        self.tmp = temporary_name(self.path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.n_site = n_site
        self.site_names = list(site_vars)
        self.time_names = list(time_vars)
        self.broken: str | None = None  # why HDF5 failed: the file is then abandoned
        self.closed_why = ""  # why close kept nothing
        self.reserve = _reserve(temporary_name(self.path.with_name(self.path.name + ".reserve")), RESERVE_BYTES)
        self.file = h5netcdf.File(self.tmp, "w")
        self.n_frames = n_frames
        self.file.dimensions = {"time": n_frames, "site": n_site}
        cap = 1024 if n_frames is None else max(1, n_frames)  # chunks no longer than a fixed dimension
        chunk_t = int(max(1, min(256, cap, CHUNK_BYTES // (8 * max(n_site, 1)))))
        chunk_1d = (min(1024, cap),)
        self._chunk_t, self._chunk_1d = chunk_t, chunk_1d[0]
        t = self.file.create_variable("time", ("time",), "f8", chunks=chunk_1d)
        t.attrs.update(variable_attrs("time", {"units": "s", "long_name": "time"}))
        s = self.file.create_variable("site", ("site",), "i8", data=np.arange(n_site))
        s.attrs.update(variable_attrs("site", {"units": "1", "long_name": "site index"}))
        coord_names = " ".join(site_coords)
        for name, (values, units, long_name, *extra) in site_coords.items():
            c = self.file.create_variable(name, ("site",), np.asarray(values).dtype, data=values)
            c.attrs.update(_attrs(name, units, long_name, extra))
        for name, (dims, values, units, long_name, *extra) in (constants or {}).items():
            values = np.asarray(values)
            for dim, size in zip(dims, values.shape):
                if dim not in self.file.dimensions:
                    self.file.dimensions[dim] = size
            c = self.file.create_variable(name, dims, values.dtype, data=values)
            c.attrs.update(_attrs(name, units, long_name, extra))
        for name, (units, long_name, *extra) in site_vars.items():
            v = self.file.create_variable(name, ("time", "site"), "f8", chunks=(chunk_t, n_site))
            v.attrs.update(_attrs(name, units, long_name, extra))
            if coord_names:
                v.attrs["coordinates"] = coord_names
        for name, (units, long_name, *extra) in time_vars.items():
            v = self.file.create_variable(name, ("time",), "f8", chunks=chunk_1d)
            v.attrs.update(_attrs(name, units, long_name, extra))
        self.n_written = 0
        self.t_written: float | None = None  # time of the last frame on disk (s)
        self._buf: list[tuple[float, dict, dict]] = []
        self._buf_frames = max(1, BUFFER_BYTES // (8 * max(1, n_site * len(self.site_names))))

    def append(self, t: float, site_values: dict, time_values: dict) -> None:
        """Queue one frame (SI values); flushed to disk in batches."""
        self._buf.append((t, {k: np.array(v, float) for k, v in site_values.items()}, dict(time_values)))
        if len(self._buf) >= self._buf_frames:
            self.flush()

    def _new_chunk_bytes(self, i0: int, k: int) -> int:
        """Bytes of the chunks that writing frames i0 .. i0 + k − 1 allocates (chunks are whole)."""
        def new(chunk: int) -> int:
            return (i0 + k - 1) // chunk - ((i0 - 1) // chunk if i0 > 0 else -1)

        return 8 * (new(self._chunk_t) * self._chunk_t * self.n_site * len(self.site_names)
                    + new(self._chunk_1d) * self._chunk_1d * (1 + len(self.time_names)))

    def _room(self, i0: int, k: int) -> tuple[int, str]:
        """How many of the k frames from i0 the filesystem has room for (all of them where it does
        not report sizes), and, when not all, why."""
        try:
            st = os.statvfs(self.tmp.parent)
        except OSError:
            return k, ""
        if st.f_blocks == 0:  # a filesystem that reports no sizes: nothing to check against
            return k, ""
        free = st.f_bavail * st.f_frsize - METADATA_BYTES
        if self._new_chunk_bytes(i0, k) <= free:
            return k, ""
        lo, hi = 0, k  # the most frames that fit: bytes grow with the frames
        while lo < hi:
            mid = (lo + hi + 1) // 2
            lo, hi = (mid, hi) if self._new_chunk_bytes(i0, mid) <= free else (lo, mid - 1)
        return lo, (f"No space left on device ({max(free, 0) / 2**20:.2f} MiB free, "
                    f"{self._new_chunk_bytes(i0, k) / 2**20:.2f} MiB needed for the next {k} frames)")

    def flush(self) -> None:
        """Write the buffered frames; ``OSError`` (ENOSPC) after writing those that fit when the disk
        has no room for all of them (the rest are dropped: ``n_written`` counts what is on disk)."""
        if not self._buf:
            return
        if self.broken:
            raise WriteFailed(errno.EIO, self.broken)
        if self.n_frames is not None and self.n_written + len(self._buf) > self.n_frames:
            raise ValueError(f"more frames than the {self.n_frames} declared")
        fits, why = self._room(self.n_written, len(self._buf))
        if fits < len(self._buf):
            del self._buf[fits:]
            self._write()
            raise OSError(errno.ENOSPC, why, str(self.path.parent))
        self._write()

    def _write(self) -> None:
        if not self._buf:
            return
        i0, k = self.n_written, len(self._buf)
        f = self.file
        failed = None
        with _quiet_unraisable():  # h5py objects that fail to close as they go: reported once, below
            try:
                if self.n_frames is None:
                    f.resize_dimension("time", i0 + k)
                f.variables["time"][i0 : i0 + k] = [b[0] for b in self._buf]
                for name in self.site_names:
                    f.variables[name][i0 : i0 + k, :] = np.stack([b[1][name] for b in self._buf])
                for name in self.time_names:
                    f.variables[name][i0 : i0 + k] = [b[2][name] for b in self._buf]
                f._h5file.flush()  # on disk now (a full disk shows here, not when the file is closed)
            except (OSError, RuntimeError) as exc:  # HDF5's own failure: the file is no longer consistent
                failed = (getattr(exc, "errno", None) or errno.EIO, _first_line(exc))
            # the youngest generation holds what this write made; a full collection, ~0.1–0.5 s on
            # the heap of a run (issue 37: frames ≤ 5 % of a large run), only after a failure
            gc.collect(0 if failed is None else 2)
        if failed is not None:
            self._abandon(f"HDF5 could not write frames {i0}-{i0 + k - 1}: {failed[1]}")
            raise WriteFailed(failed[0], self.broken)
        self.n_written += k
        self.t_written = self._buf[-1][0]
        self._buf.clear()

    def sync(self) -> None:
        """Write the buffered frames and make them durable (HDF5 flush, then fsync): ``n_written``
        frames survive a crash of the process from here on (a checkpoint counts on it)."""
        self.flush()
        if self.file is None:
            return
        self.file._h5file.flush()
        fd = os.open(self.tmp, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)

    def copy_frames(self, src: Path, n: int, t_last: float) -> None:
        """Start with the first ``n`` frames of the dataset ``src`` (a run continued from a checkpoint,
        whose frame ``n − 1`` is at ``t_last`` s). ``OSError`` when ``src`` does not hold them."""
        step = max(1, BUFFER_BYTES // (8 * max(1, self.n_site * max(1, len(self.site_names)))))
        try:
            with h5netcdf.File(src, "r") as f:
                _check_frames(f, src, n, t_last)
                if self.n_frames is None:
                    self.file.resize_dimension("time", n)
                for i in range(0, n, step):
                    j = min(i + step, n)
                    for name in ("time", *self.site_names, *self.time_names):
                        self.file.variables[name][i:j] = f.variables[name][i:j]
        except (RuntimeError, KeyError) as exc:  # HDF5 cannot read it (a file cut short by a kill)
            raise OSError(errno.EIO, f"it cannot be read ({_first_line(exc)})", str(src)) from None
        self.n_written, self.t_written = n, (t_last if n else None)

    def _release_reserve(self) -> None:
        if self.reserve is not None:
            self.reserve.unlink(missing_ok=True)
            self.reserve = None

    def _abandon(self, why: str) -> None:
        """Give up the file after an HDF5 write failure. HDF5 cannot close a file whose data it
        cannot write (each try reports errors; one at interpreter exit crashes the process), so the
        file is never closed: it is kept open in ``ABANDONED`` and its name removed (its space is
        freed when the process ends, which ``leave`` makes quick)."""
        self.broken = why
        self._buf.clear()
        self._release_reserve()
        ABANDONED.append(self.file)
        self.file = None
        self.tmp.unlink(missing_ok=True)

    def close(self, attrs: dict) -> Path | None:
        """Flush, stamp global attributes, and atomically move the file into place.

        Returns None, with ``closed_why`` set and the temporary file removed, when the file
        could not be completed (an HDF5 write failed): then nothing is kept."""
        try:
            self.flush()
        except OSError:  # the disk is full (or failing): the frames still buffered are lost
            self._buf.clear()
        if self.n_frames is not None and self.n_written < self.n_frames:
            self._release_reserve()  # room for the metadata, and for the copy that cuts the file
        if self.broken is None:
            try:
                self.file.attrs.update({**global_attrs(), **{k: v for k, v in attrs.items() if v is not None}})
                self.file.attrs["n_frames_written"] = self.n_written
                self.file.close()
            except (OSError, RuntimeError) as exc:
                self._abandon(f"HDF5 could not complete the file: {_first_line(exc)}")
        self._release_reserve()
        if self.broken is not None:
            self.tmp.unlink(missing_ok=True)
            self.closed_why = self.broken
            return None
        if self.n_frames is not None and self.n_written < self.n_frames:
            cut = self.tmp.with_name(self.tmp.name + ".cut")
            try:
                self._cut(cut)
            except OSError:  # no room to rewrite: keep the full-size file; n_frames_written says
                cut.unlink(missing_ok=True)
            else:
                self.tmp.unlink()
                self.tmp = cut
        os.replace(self.tmp, self.path)
        return self.path

    def _cut(self, dst_path: Path) -> None:
        """Copy the temporary file to ``dst_path`` with only the frames written (an early stop)."""
        n, step = self.n_written, max(1, BUFFER_BYTES // (8 * max(1, self.n_site)))
        with h5netcdf.File(self.tmp, "r") as src, h5netcdf.File(dst_path, "w") as dst:
            dst.dimensions = {**{name: len(dim) for name, dim in src.dimensions.items()}, "time": n}
            dst.attrs.update(dict(src.attrs))
            for name, var in src.variables.items():
                timed = var.dimensions[:1] == ("time",)
                chunks = None if not timed or n == 0 else tuple(min(c, m) for c, m in zip(var.chunks, (n, *var.shape[1:])))
                out = dst.create_variable(name, var.dimensions, var.dtype, chunks=chunks)
                out.attrs.update({k: v for k, v in var.attrs.items() if k not in ("DIMENSION_LIST", "_Netcdf4Dimid")})
                if not timed:
                    out[...] = var[...]
                    continue
                for i in range(0, n, step):
                    out[i : min(i + step, n)] = var[i : min(i + step, n)]

    def abort(self) -> None:
        """Drop the temporary file (nothing is published)."""
        if self.file is not None:
            with _quiet_unraisable():
                try:
                    self.file.close()
                except Exception:  # noqa: BLE001 - best effort on an already failing path
                    pass
        self._release_reserve()
        self.tmp.unlink(missing_ok=True)


#: the variables ``shape_variables`` writes
#: how a unit is drawn (``UnitShapes.outline``, stored as its index ``unit_outline``): its polygon,
#: arms from its centre to its vertices (a cross, for squares), or thin arms (bars)
OUTLINES = ("polygon", "cross", "bars")
SHAPE_VARIABLES = ("unit_centre_x", "unit_centre_y", "unit_vertex_x", "unit_vertex_y", "rotation_sign", "link_site",
                   "link_point_x", "link_point_y", "unit_outline", "unit_angle", "unit_marker_x", "unit_marker_y",
                   "link_joint", "unit_image_offset", "image_vertex")


def shape_variables(shapes, sites: np.ndarray, length_m: float) -> dict:
    """The ``constants`` (``DatasetWriter``) of a model's ``UnitShapes`` on the saved sites:
    polygons (site, vertex) and rotation signs per saved unit, the joints between saved units, and
    how to draw them (outline, reference angles, markers, joints, mirror images) where the model
    gives them."""
    if shapes is None:
        return {}
    index = np.full(shapes.rotation_sign.size, -1, np.int64)  # unit -> its position along ``site``
    index[sites] = np.arange(sites.size)
    keep = (index[shapes.links[:, 0]] >= 0) & (index[shapes.links[:, 1]] >= 0)
    pts = shapes.link_points[keep] * length_m
    body = "relative to the unit's centre in the reference configuration"
    out = {
        "unit_centre_x": (("site",), shapes.centres[sites, 0] * length_m, "m", "x of the unit's centre in the reference configuration"),
        "unit_centre_y": (("site",), shapes.centres[sites, 1] * length_m, "m", "y of the unit's centre in the reference configuration"),
        "unit_vertex_x": (("site", "vertex"), shapes.vertices[sites, :, 0] * length_m, "m", f"x of the unit's vertices {body}"),
        "unit_vertex_y": (("site", "vertex"), shapes.vertices[sites, :, 1] * length_m, "m", f"y of the unit's vertices {body}"),
        "rotation_sign": (("site",), shapes.rotation_sign[sites], "1", "the unit turns by rotation_sign times theta"),
        "link_site": (("link", "end"), index[shapes.links[keep]], "1", "the two sites a hinge or ligament joins"),
        "link_point_x": (("link", "end"), pts[..., 0], "m", f"x of a joint's attachment points {body}"),
        "link_point_y": (("link", "end"), pts[..., 1], "m", f"y of a joint's attachment points {body}"),
        "unit_outline": ((), np.int64(OUTLINES.index(shapes.outline)), "1", "how a unit is drawn",
                         {"flag_values": np.arange(len(OUTLINES)), "flag_meanings": " ".join(OUTLINES)}),
    }
    if shapes.angle is not None:
        out["unit_angle"] = (("site",), shapes.angle[sites], "rad", "the unit's orientation in the reference configuration")
    if shapes.markers is not None:
        out["unit_marker_x"] = (("site", "marker"), shapes.markers[sites, :, 0] * length_m, "m", f"x of a point on the unit (a magnet) {body}")
        out["unit_marker_y"] = (("site", "marker"), shapes.markers[sites, :, 1] * length_m, "m", f"y of a point on the unit (a magnet) {body}")
    if shapes.link_joints:
        out["link_joint"] = ((), np.int64(1), "1", "each link carries a joint (drawn at its midpoint)")
    if shapes.images is not None and shapes.images.shape[1]:
        out["unit_image_offset"] = (("site", "image"), shapes.images[sites] * length_m, "m",
                                    "vertical offset of the unit's mirror image across the row (a lateral hinge)")
        out["image_vertex"] = (("image",), shapes.image_vertex, "1",
                               "the vertex of a unit joined to its reflection in the unit's mirror image")
    return out


def _first_line(exc: BaseException) -> str:
    """HDF5's messages run over several lines (time, file name, buffer address): the first says it."""
    text = str(exc).strip()
    if not text:
        return type(exc).__name__
    line = text.splitlines()[0]
    cut = line.find(" (file write failed")
    return (line[:cut] + ": No space left on device" if "No space left" in text else line[:cut]) if cut > 0 else line


def add_state(system, sites: np.ndarray, site_vars: dict, site_coords: dict,
              initial: dict[str, np.ndarray] | None = None) -> None:
    """Declare a run's rest and initial state in the layout ``DatasetWriter`` takes (changes its arguments).

    Adds the site coordinates ``<field>_rest`` (the rest state, measured from the reference
    configuration), ``<field>_initial`` and ``<field>_dot_initial`` (the state at t = 0, in the
    field variable's own reference) for every lattice field of ``system`` (a models.System) on the
    saved ``sites``, and gives every field variable in ``site_vars`` (and its rate) the attrs
    ``reference`` (one of REFERENCES), ``rest_state`` and ``initial_state`` (the names of those
    coordinates). ``initial``: SI values per variable name on the saved sites, overriding the
    system's q0, v0 (a continuum run samples its prediction instead).
    """
    n, sc = system.n_sites, system.scales
    rest = system.rest_fields_si()
    reference = system.field_reference
    for k, f in enumerate(system.fields):
        units, rate_units = ("rad", "rad/s") if f.kind == "angle" else ("m", "m/s")  # as flexmm.units.UNITS
        span = slice(k * n, (k + 1) * n)
        q0 = (initial or {}).get(f.name, np.asarray(system.q0[span])[sites] * sc.coordinate(f.kind))
        v0 = (initial or {}).get(f.name + "_dot", np.asarray(system.v0[span])[sites] * sc.rate(f.kind))
        rest_name, q0_name, v0_name = (f.name + REST_SUFFIX, f.name + INITIAL_SUFFIX,
                                       f.name + "_dot" + INITIAL_SUFFIX)
        site_coords[rest_name] = (rest[f.name][sites], units, f"{f.long_name} in the rest state",
                                  {"reference": "absolute"})
        site_coords[q0_name] = (np.asarray(q0, float), units, f"{f.long_name} at t = 0", {"reference": reference})
        site_coords[v0_name] = (np.asarray(v0, float), rate_units, f"rate of {f.long_name} at t = 0")
        for name, initial_name in ((f.name, q0_name), (f.name + "_dot", v0_name)):
            if name in site_vars:
                units_, long_name, *extra = site_vars[name]
                declared = {"reference": reference, "rest_state": rest_name, "initial_state": initial_name}
                site_vars[name] = (units_, long_name, {**(extra[0] if extra else {}), **declared})


def estimate_bytes(n_frames: int, n_site: int, n_site_vars: int, n_time_vars: int) -> int:
    """Size of the data a run will write (excluding HDF5 overhead)."""
    return 8 * n_frames * (n_site * n_site_vars + n_time_vars + 1)


def open_run(path: str | Path):
    """Open a run's dataset (a run directory or the .nc file) as an xarray Dataset."""
    import xarray as xr

    p = Path(path)
    if p.is_dir():
        p = p / "dataset.nc"
    return xr.load_dataset(p, engine="h5netcdf")


#: HDF5 / netCDF-4 bookkeeping attributes that xarray does not show
_HIDDEN_ATTRS = frozenset({"CLASS", "NAME", "REFERENCE_LIST", "DIMENSION_LIST", "_Netcdf4Dimid",
                           "_Netcdf4Coordinates", "_nc3_strict", "_NCProperties"})


def _attr_value(v):
    """As h5netcdf and xarray give it: bytes decoded, a one-element array as its element."""
    if not np.isscalar(v) and len(v) == 1:
        v = v[0]
    return v.decode() if isinstance(v, bytes) else v


def load_run_quickly(path: str | Path):
    """``open_run`` for a dataset this module's ``DatasetWriter`` wrote, read with h5py alone.

    The file is flat (numeric variables, dimensions named by their ``_Netcdf4Dimid``), so the
    variables, their dimensions and attributes are read directly and then CF-decoded by xarray
    (``xr.decode_cf``): the same Dataset as ``open_run``, about ten times faster for a small run
    (what a sweep's points are). Anything else (groups, strings) is read by ``open_run``.
    """
    import h5py
    import xarray as xr

    p = Path(path)
    if p.is_dir():
        p = p / "dataset.nc"
    with h5py.File(p, "r") as f:
        items = dict(f.items())
        if any(not isinstance(d, h5py.Dataset) or d.dtype.kind not in "fiub" for d in items.values()):
            return open_run(p)
        names = {int(d.attrs["_Netcdf4Dimid"]): n for n, d in items.items() if d.attrs.get("CLASS") == b"DIMENSION_SCALE"}
        variables = {}
        for name, d in items.items():
            if str(_attr_value(d.attrs.get("NAME", ""))).startswith("This is a netCDF dimension but not a netCDF variable"):
                continue  # a dimension without a coordinate variable (the units' vertices, links)
            ids = d.attrs.get("_Netcdf4Coordinates")
            dims = tuple(names[int(i)] for i in ids) if ids is not None else (name,) if d.ndim else ()
            attrs = {k: _attr_value(v) for k, v in d.attrs.items() if k not in _HIDDEN_ATTRS}
            variables[name] = xr.Variable(dims, d[()], attrs)
        attrs = {k: _attr_value(v) for k, v in f.attrs.items() if k not in _HIDDEN_ATTRS}
    return xr.decode_cf(xr.Dataset(variables, attrs=attrs))


class MemoryWriter:
    """``DatasetWriter``'s interface, keeping the run in memory: ``close`` makes ``dataset``, the
    Dataset ``load_run_quickly`` would read back from the file ``DatasetWriter`` writes (same
    variables, dimensions, attributes and their types), and writes nothing.

    For runs that are measured and dropped (the points of a sweep that are not kept): no file to
    lay out, write and read back. ``path`` is where the file would have gone (it does not exist).

    ``spill``: a directory for checkpoints (a sweep point's work directory). A checkpoint needs
    its frames on disk, so ``sync`` writes the frames kept so far to ``spill/dataset.nc`` (a
    ``DatasetWriter``, the rest appended at each later ``sync``) and ``close`` completes that file
    too; a run that ends before its first checkpoint writes nothing. ``copy_frames`` reads the
    frames of a checkpoint back into memory (a resumed point).
    """

    def __init__(self, path: Path, n_site: int, site_vars: dict, time_vars: dict, site_coords: dict,
                 n_frames: int | None = None, constants: dict | None = None, spill: Path | None = None):
        self.path, self.n_site, self.n_frames = Path(path), n_site, n_frames
        self.site_vars, self.time_vars, self.site_coords = site_vars, time_vars, site_coords
        self.constants = constants or {}
        self.frames: list[tuple[float, dict, dict]] = []
        self.n_written = 0
        self.t_written: float | None = None
        self.dataset = None
        self.spill_dir = None if spill is None else Path(spill)
        self._spill: DatasetWriter | None = None

    def append(self, t: float, site_values: dict, time_values: dict) -> None:
        if self.n_frames is not None and len(self.frames) >= self.n_frames:
            raise ValueError(f"more frames than the {self.n_frames} declared")
        self.frames.append((t, {k: np.array(v, float) for k, v in site_values.items()}, dict(time_values)))
        self.n_written, self.t_written = len(self.frames), t

    def flush(self) -> None:
        pass

    @property
    def tmp(self) -> Path:
        """The file the frames a checkpoint counts are in (after ``sync``)."""
        return self._spill.tmp

    def sync(self) -> None:
        """Every frame so far on disk, durably, in ``spill/dataset.nc`` (nothing without ``spill``)."""
        if self.spill_dir is None:
            return
        if self._spill is None:
            self._spill = DatasetWriter(self.spill_dir / "dataset.nc", self.n_site, self.site_vars, self.time_vars,
                                        self.site_coords, self.n_frames, self.constants)
        for t, site_values, time_values in self.frames[self._spill.n_written + len(self._spill._buf):]:
            self._spill.append(t, site_values, time_values)
        self._spill.sync()

    def discard_spill(self) -> None:
        """Remove the frames ``sync`` wrote (no checkpoint will count them: a point that finished)."""
        if self._spill is not None:
            self._spill.abort()
            self._spill = None

    def copy_frames(self, src: Path, n: int, t_last: float) -> None:
        """Start with the first ``n`` frames of the dataset ``src`` (``DatasetWriter.copy_frames``)."""
        try:
            with h5netcdf.File(src, "r") as f:
                _check_frames(f, src, n, t_last)
                times = np.asarray(f.variables["time"][:n], float)
                site = {k: np.asarray(f.variables[k][:n], float) for k in self.site_vars}
                per_time = {k: np.asarray(f.variables[k][:n], float) for k in self.time_vars}
        except (RuntimeError, KeyError) as exc:  # HDF5 cannot read it (a file cut short by a kill)
            raise OSError(errno.EIO, f"it cannot be read ({_first_line(exc)})", str(src)) from None
        self.frames = [(float(times[i]), {k: v[i].copy() for k, v in site.items()},
                        {k: float(v[i]) for k, v in per_time.items()}) for i in range(n)]
        self.n_written, self.t_written = n, (t_last if n else None)

    def close(self, attrs: dict) -> Path:
        import xarray as xr

        n, frames = self.n_written, self.frames
        variables = {"time": (("time",), np.array([f[0] for f in frames], float).reshape(n),
                              variable_attrs("time", {"units": "s", "long_name": "time"})),
                     "site": (("site",), np.arange(self.n_site, dtype=np.int64),
                              variable_attrs("site", {"units": "1", "long_name": "site index"}))}
        for name, (values, units, long_name, *extra) in self.site_coords.items():
            variables[name] = (("site",), np.asarray(values), _attrs(name, units, long_name, extra))
        for name, (dims, values, units, long_name, *extra) in self.constants.items():
            variables[name] = (dims, np.asarray(values), _attrs(name, units, long_name, extra))
        coord_names = " ".join(self.site_coords)
        for name, (units, long_name, *extra) in self.site_vars.items():
            data = np.array([f[1][name] for f in frames], float).reshape(n, self.n_site)
            a = _attrs(name, units, long_name, extra)
            variables[name] = (("time", "site"), data, {**a, "coordinates": coord_names} if coord_names else a)
        for name, (units, long_name, *extra) in self.time_vars.items():
            variables[name] = (("time",), np.array([f[2][name] for f in frames], float).reshape(n),
                               _attrs(name, units, long_name, extra))
        glob = {**global_attrs(), **{k: v for k, v in attrs.items() if v is not None}, "n_frames_written": n}
        stored = _as_stored({"": glob, **{k: v[2] for k, v in variables.items()}})
        ds = xr.Dataset({k: xr.Variable(dims, data, stored[k]) for k, (dims, data, _) in variables.items()},
                        attrs=stored[""])
        self.dataset = xr.decode_cf(ds)
        if self._spill is not None:  # the frames a last checkpoint counts: the spill file completed
            try:
                self.sync()
            except OSError:
                pass  # what it holds is cut to the frames written when it closes
            self._spill.close(attrs)
        self.frames = []
        return self.path

    def abort(self) -> None:
        self.frames = []
        if self._spill is not None:
            self._spill.abort()


def _as_stored(groups: dict[str, dict]) -> dict[str, dict]:
    """Attributes as a netCDF file gives them back: written into an HDF5 file held in memory
    (never on disk) and read as ``load_run_quickly`` reads them (types included). What a
    scalar or string becomes depends on its type and value only: those seen before (units,
    long names: most of a run's attributes) are taken from ``_STORED``."""
    import io

    import h5py

    def key(v):
        return (type(v), v) if isinstance(v, (str, bool, int, float, np.generic)) else None

    if len(_STORED) > _STORED_MAX:  # before choosing what to convert: what is not converted is looked up
        _STORED.clear()
    todo = {(name, k): v for name, attrs in groups.items() for k, v in attrs.items()
            if key(v) is None or key(v) not in _STORED}
    if todo:
        with h5py.File(io.BytesIO(), "w") as f:
            for i, ((name, k), v) in enumerate(todo.items()):
                f.attrs[str(i)] = v
                todo[name, k] = _attr_value(f.attrs[str(i)])
                if key(v) is not None:
                    _STORED[key(v)] = todo[name, k]
    return {name: {k: todo[name, k] if (name, k) in todo else _STORED[key(v)] for k, v in attrs.items()}
            for name, attrs in groups.items()}


#: (type, value) -> the attribute value read back from HDF5 (see ``_as_stored``)
_STORED: dict = {}
_STORED_MAX = 10_000
