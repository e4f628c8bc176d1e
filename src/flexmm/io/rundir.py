"""One run's directory, written atomically: lock, stage, then commit everything with one rename.

A run writes its dataset, config and log into a private staging directory next to the target
(``.<name>.staging.<pid>``) while holding a lock (``.<name>.lock``), so a second run into the same
directory is refused instead of interleaving its files with the first. ``commit(status)``:

- ``finished``: the staging directory *becomes* ``<name>`` in one step — swapped with an
  existing ``<name>`` by ``renameat2(RENAME_EXCHANGE)`` (Linux), then the old contents (an
  earlier result, its analysis and figures) are removed; a plain rename if there is none. A
  ``<name>`` that holds anything a run directory would not (subdirectories, other files: ``--out
  runs`` instead of ``--out runs/x``) is refused before the run, never replaced;
- ``failed`` / ``interrupted``: the partial result goes to ``<name>.<status>`` (replacing an
  older partial of the same kind); a finished ``<name>`` is never touched, and nothing partial
  sits where a finished result is expected.

Leaving the ``with`` block without a commit (an error, a signal before the run started) removes
the staging directory. Staging directories and temporary files of processes that no longer run
(a ``kill -9``, a power cut) are removed by the next run into the same directory.
"""

from __future__ import annotations

import contextlib
import ctypes
import fcntl
import os
import re
import shutil
from pathlib import Path

from flexmm.errors import OutputError

FINISHED = "finished"
_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # alive, another user's
        return True
    return True


def _exchange(a: Path, b: Path) -> bool:
    """Atomically swap two existing paths (Linux renameat2); False where unsupported."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)  # the C library already loaded in this process
    except OSError:
        return False
    fn = getattr(libc, "renameat2", None)
    if fn is None:
        return False
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    rc = fn(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE)
    if rc == 0:
        return True
    err = ctypes.get_errno()
    if err in (22, 38, 95):  # EINVAL, ENOSYS, EOPNOTSUPP: this filesystem cannot exchange
        return False
    raise OSError(err, os.strerror(err), str(b))


def clean_stale(directory: Path) -> list[Path]:
    """Remove staging directories and ``.*.<pid>.tmp`` files of dead processes in ``directory``."""
    removed = []
    if not directory.is_dir():
        return removed
    pattern = re.compile(r"^\..+\.(?:staging|old)\.(\d+)$|^\..+\.(\d+)\.tmp(?:\.cut)?$")
    for p in directory.iterdir():
        m = pattern.match(p.name)
        if m is None:
            continue
        pid = int(m.group(1) or m.group(2))
        if pid != os.getpid() and not _pid_alive(pid):
            if p.is_dir():
                shutil.rmtree(p, ignore_errors=True)
            else:
                p.unlink(missing_ok=True)
            removed.append(p)
    return removed


@contextlib.contextmanager
def exclusive(lock_path: Path, what: str):
    """Hold an exclusive lock on ``lock_path`` (created if needed) for the block.

    ``OutputError`` naming ``what`` and the holder's pid if another process holds it. The lock is
    the kernel's (``flock``): it is released when its holder exits, even by ``kill -9``.
    """
    try:
        lock_path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as exc:
        raise OutputError(f"cannot lock {what}: {exc.strerror or exc}") from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 32, 0).decode(errors="replace").strip() or "?"
            raise OutputError(f"{what} is in use by another flexmm process (pid {holder}); wait for it to "
                              "finish or choose another output") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, str(os.getpid()).encode(), 0)
        yield
    finally:
        with contextlib.suppress(OSError):
            fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)


#: what a run directory may hold (a run's outputs, its analysis and figures): anything else means
#: the path is not a run directory, and replacing it could destroy unrelated files
RUN_FILE_SUFFIXES = (".nc", ".yaml", ".log", ".json", ".csv", ".png", ".svg", ".pdf", ".gif", ".mp4", ".lock", ".tmp")


def foreign_contents(directory: Path) -> list[str]:
    """Entries of ``directory`` that a flexmm run directory would not hold (subdirectories, other files)."""
    return sorted(p.name for p in directory.iterdir()
                  if p.is_dir() or not p.name.endswith(RUN_FILE_SUFFIXES))


class RunDirectory:
    """Lock ``final``, give a staging directory to write in, commit it (module docstring)."""

    def __init__(self, final: str | Path):
        self.final = Path(final).expanduser()
        self.parent = self.final.parent
        name = self.final.name
        self.lock_path = self.parent / f".{name}.lock"
        self.stage = self.parent / f".{name}.staging.{os.getpid()}"
        self.committed: Path | None = None
        self._lock = exclusive(self.lock_path, f"run directory {self.final}")

    def __enter__(self) -> RunDirectory:
        if self.final.is_dir():
            foreign = foreign_contents(self.final)
            if foreign:
                shown = ", ".join(foreign[:5]) + (", ..." if len(foreign) > 5 else "")
                raise OutputError(f"{self.final} exists and is not a flexmm run directory (it holds {shown}); "
                                  "a finished run replaces its run directory: choose a new or empty one")
        self._lock.__enter__()
        clean_stale(self.parent)
        if self.final.is_dir():
            clean_stale(self.final)
        if self.stage.exists():
            shutil.rmtree(self.stage)
        self.stage.mkdir()
        return self

    def commit(self, status: str) -> Path:
        """Publish the staging directory for a run that ended with ``status``; returns where."""
        if status == FINISHED:
            target = self.final
            if target.exists() and not target.is_dir():
                raise OutputError(f"output path {target} exists and is not a directory")
            if target.exists():
                if _exchange(self.stage, target):
                    shutil.rmtree(self.stage, ignore_errors=True)  # the old result, swapped out
                else:  # two renames, under the lock
                    old = self.parent / f".{self.final.name}.old.{os.getpid()}"
                    os.rename(target, old)
                    os.rename(self.stage, target)
                    shutil.rmtree(old, ignore_errors=True)
            else:
                os.rename(self.stage, target)
        else:
            target = self.parent / f"{self.final.name}.{status}"
            if target.exists():
                shutil.rmtree(target) if target.is_dir() else target.unlink()
            os.rename(self.stage, target)
        self.committed = target
        return target

    def __exit__(self, *exc) -> None:
        if self.committed is None and self.stage.exists():
            shutil.rmtree(self.stage, ignore_errors=True)
        self._lock.__exit__(*exc)
