"""Checkpoints: a run's whole state at a frame, so ``flexmm run --resume`` continues it bit for bit.

A checkpoint holds what the next frame depends on: the stepper's state arrays (q, v, the total
force f, the accumulator with its ledger, counters and integrator state slots) and scalars (t, the
step, time spent, the runaway guard's references), the step follower's state (its reduction, the
stiffness tracker's warm-start vector and counters), the frames done and how many of them the
dataset holds, the run's log so far, and how to rebuild the run without planning it again: the
scene as asked (``source_config``, whose hash a resume compares), the scene that runs
(``planned_config``: integrator and step fixed), the plan's attributes and the whole-run error check
(``error_check``). It is tied to the flexmm version and git commit that wrote it.

File (``checkpoint.ckpt`` in the run's directory): ``MAGIC``, the header length (8 bytes, little
endian), the header (JSON: the fields above and a table of the arrays), the arrays' bytes, and the
SHA-256 of everything before it. ``write`` writes a temporary file, fsyncs it, moves the current
checkpoint to ``checkpoint.prev.ckpt`` and renames the new one into place, so a checkpoint that is
complete always exists; ``best`` reads the newest valid one (a truncated or corrupted file is
refused by its checksum, and the previous one used).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from flexmm._version import __version__
from flexmm.errors import FlexmmError
from flexmm.io.atomic import temporary_name
from flexmm.io.pause import pause_point
from flexmm.io.provenance import git_commit

MAGIC = b"FLEXMM-CHECKPOINT\n"
#: the layout of the header and arrays; a checkpoint of another format is refused
FORMAT = 1
NAME = "checkpoint.ckpt"
PREVIOUS = "checkpoint.prev.ckpt"
#: seconds of wall time between checkpoints unless told (``flexmm run --checkpoint-s``)
DEFAULT_EVERY_S = 60.0
_DIGEST = 32


class CheckpointError(FlexmmError):
    """No checkpoint to continue from, or one that must not be continued (what and why)."""


@dataclass
class Checkpoint:
    """A checkpoint read back: ``meta`` (the header), ``arrays`` by name, the file it came from."""

    meta: dict
    arrays: dict[str, np.ndarray]
    path: Path

    @property
    def directory(self) -> Path:
        return self.path.parent

    def dataset(self) -> Path:
        """The dataset holding the checkpoint's frames: the file the run was writing, or the
        ``dataset.nc`` it became when the run ended (a published partial or finished run)."""
        own = self.directory / self.meta["dataset"]
        return own if own.is_file() else self.directory / "dataset.nc"


def write(directory: Path, meta: dict, arrays: dict[str, np.ndarray], durable: bool = True) -> int:
    """Write a checkpoint atomically into ``directory`` (module docstring); returns its size in bytes.

    ``durable``: fsync the file and the directory, so the checkpoint survives a power cut or an OS
    crash, not only the death of the process (which the rename alone survives)."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    target, tmp = directory / NAME, temporary_name(directory / NAME)
    flat = {k: np.ascontiguousarray(a, dtype=np.dtype(a.dtype).newbyteorder("<")) for k, a in arrays.items()}
    table, offset = [], 0
    for name, a in flat.items():
        table.append({"name": name, "dtype": a.dtype.str, "shape": list(a.shape), "offset": offset})
        offset += a.nbytes
    header = json.dumps({**meta, "format": FORMAT, "flexmm_version": __version__, "git_commit": git_commit(),
                         "written": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "arrays": table}, default=_plain).encode()
    digest = hashlib.sha256()
    try:
        with open(tmp, "wb") as fh:
            for part in (MAGIC, len(header).to_bytes(8, "little"), header, *(memoryview(a).cast("B") for a in flat.values())):
                digest.update(part)
                fh.write(part)
            fh.write(digest.digest())
            fh.flush()
            if durable:
                os.fsync(fh.fileno())
        if target.exists():
            os.replace(target, directory / PREVIOUS)
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    if durable:
        _sync_directory(directory)
    return len(MAGIC) + 8 + len(header) + offset + _DIGEST


def read(path: Path) -> Checkpoint:
    """The checkpoint in ``path``; ``CheckpointError`` saying why when it is not a complete one."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise CheckpointError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    head = len(MAGIC) + 8
    if not data.startswith(MAGIC):
        raise CheckpointError(f"{path}: not a flexmm checkpoint")
    if len(data) < head + _DIGEST or hashlib.sha256(data[:-_DIGEST]).digest() != data[-_DIGEST:]:
        raise CheckpointError(f"{path}: its checksum does not match (truncated or corrupted)")
    n = int.from_bytes(data[len(MAGIC) : head], "little")
    meta = json.loads(data[head : head + n])
    if meta.get("format") != FORMAT:
        raise CheckpointError(f"{path}: checkpoint format {meta.get('format')}, this flexmm reads {FORMAT}")
    base, arrays = head + n, {}
    for a in meta.pop("arrays"):
        dtype = np.dtype(a["dtype"])
        count = int(np.prod(a["shape"], dtype=np.int64))
        arrays[a["name"]] = np.frombuffer(data, dtype, count, base + a["offset"]).reshape(a["shape"])
    return Checkpoint(meta, arrays, path)


def best(directories: list[Path]) -> tuple[Checkpoint, list[str]]:
    """The most advanced valid checkpoint in ``directories`` (each: ``NAME``, else ``PREVIOUS``), and
    notes on the files refused. ``CheckpointError`` when there is none."""
    found, refused = [], []
    for d in directories:
        for name in (NAME, PREVIOUS):
            p = Path(d) / name
            if not p.is_file():
                continue
            try:
                found.append(read(p))
            except CheckpointError as exc:
                refused.append(f"refused {exc}")
    if not found:
        where = ", ".join(str(d) for d in directories) or "nowhere"
        why = "; ".join(refused) if refused else (
            f"none was written (a run writes one every {DEFAULT_EVERY_S:g} s of wall time unless told otherwise, "
            "when it ends and on Ctrl-C or SIGTERM; a run stopped before its first frames has none)")
        raise CheckpointError(f"no checkpoint to continue from in {where}: {why}")
    pick = max(found, key=lambda c: (c.meta["frames_done"], c.meta["steps"], c.path.stat().st_mtime))
    return pick, refused


def version_changes(meta: dict) -> list[str]:
    """How the code that wrote a checkpoint differs from this one (flexmm version, git commit)."""
    changes = []
    if meta.get("flexmm_version") != __version__:
        changes.append(f"flexmm version {meta.get('flexmm_version')} -> {__version__}")
    theirs, mine = meta.get("git_commit", "unknown"), git_commit()
    if theirs != mine and "unknown" not in (theirs, mine):
        changes.append(f"git commit {theirs} -> {mine}")
    return changes


def config_changes(old: dict, new: dict, prefix: str = "") -> list[str]:
    """Dotted fields that differ between two resolved configs (``io.provenance.resolved_config``)."""
    out = []
    for key in sorted(set(old) | set(new), key=str):
        a, b, name = old.get(key), new.get(key), f"{prefix}{key}"
        if isinstance(a, dict) and isinstance(b, dict):
            out += config_changes(a, b, name + ".")
        elif a != b:
            out.append(f"{name}: {a!r} -> {b!r}")
    return out


def continuation(found: Checkpoint, scene=None, *, extend: bool = False, allow_version: bool = False,
                 from_work: bool = False) -> tuple:
    """(scene to run, scene as asked) to continue ``found`` (``api.continue_run``), or
    ``CheckpointError`` saying why not: a resume continues a run that did not end (or ended but
    was killed before publishing: ``from_work``), an extension one that did; the code must be the
    same unless ``allow_version``; ``scene``, if given, must be the one the run was started with
    (resume) or its planned scene with only a longer ``solver.duration_s`` (extend)."""
    from flexmm.config.loader import resolve_scene
    from flexmm.io.provenance import resolved_config

    meta = found.meta
    ended = meta["status"] in ("finished", "inaccurate")
    if extend != ended and not (ended and from_work and not extend):
        raise CheckpointError(f"{found.path}: the run {'ended' if ended else 'did not end'} ({meta['status']}): "
                              + ("--extend continues a finished run" if extend else "use --extend to continue it"))
    changes = version_changes(meta)
    if changes and not allow_version:
        raise CheckpointError(f"{found.path} was written by other code ({'; '.join(changes)}): refused, since a "
                              "resumed run is bit-identical only with the code that started it (--force continues "
                              "anyway)")
    planned, source = resolve_scene(meta["planned_config"]), resolve_scene(meta["source_config"])
    if extend:
        if scene is None:
            raise CheckpointError("--extend needs the longer duration: --set solver.duration_s=...")
        diff = [c for c in config_changes(resolved_config(planned), resolved_config(scene))
                if not c.startswith("solver.duration_s:")]
        if diff:
            raise CheckpointError("--extend continues the same scene, changing only solver.duration_s; also "
                                  f"changed: {'; '.join(diff)}")
        if not scene.solver.duration_s > meta["t_s"]:
            raise CheckpointError(f"--extend: solver.duration_s {scene.solver.duration_s:g} s does not go beyond "
                                  f"the run's end at {meta['t_s']:.6g} s")
        return scene, scene
    if scene is not None:
        diff = config_changes(resolved_config(source), resolved_config(scene))
        if diff:
            raise CheckpointError(f"the scene is not the one the run was started with: {'; '.join(diff)}")
    return planned, source


@dataclass
class Checkpointing:
    """Where and how often a run writes checkpoints (``controller.run_problem``), and what it wrote.

    ``meta``: what the caller adds to every checkpoint (configs, plan attributes: module docstring).
    A checkpoint that cannot be written (a full disk) raises ``OSError`` from ``save``, the
    previous one intact (``write``): the run then stops, failed, saying when and why."""

    directory: Path
    every_s: float = DEFAULT_EVERY_S
    meta: dict = field(default_factory=dict)
    count: int = 0
    bytes: int = 0
    seconds: float = 0.0

    def save(self, meta: dict, arrays: dict[str, np.ndarray], durable: bool = True) -> None:
        """Write one checkpoint (``write``); ``OSError`` when it could not be written."""
        pause_point("checkpoint")
        t0 = time.perf_counter()
        try:
            self.bytes = write(self.directory, {**self.meta, **meta}, arrays, durable)
        finally:
            self.seconds += time.perf_counter() - t0
        self.count += 1

    def drop_previous(self) -> None:
        (Path(self.directory) / PREVIOUS).unlink(missing_ok=True)


def _plain(value):
    """numpy scalars (plan attributes) as the Python numbers JSON takes."""
    if hasattr(value, "item"):
        return value.item()
    raise TypeError(f"{type(value).__name__} is not JSON data")


def _sync_directory(directory: Path) -> None:
    """fsync a directory, so the renames in it survive a power cut (where the platform allows)."""
    with contextlib.suppress(OSError):
        fd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
