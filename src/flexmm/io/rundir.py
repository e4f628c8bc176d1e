"""One run's directory, written atomically: lock, stage, then commit everything with one rename.

A run writes its dataset, config and log into a private staging directory next to the target
(``.<name>.staging.<pid>``) while holding a lock (``.<name>.lock``), so a second run into the same
directory is refused instead of interleaving its files with the first. ``commit(status)``:

- ``finished``: the staging directory *becomes* ``<name>`` in one step — swapped with an
  existing ``<name>`` by ``renameat2(RENAME_EXCHANGE)`` (Linux), then the old contents (an
  earlier result, its analysis and figures) are removed; a plain rename if there is none. A
  ``<name>`` (or ``<name>.failed``/``.interrupted``) that holds anything a run directory would not
  (subdirectories, other files: ``--out runs`` instead of ``--out runs/x``), or files but no
  ``dataset.nc``/``run.log`` (a directory flexmm did not write, e.g. one holding the user's
  scene), is refused before the run, never replaced (``refuse_inputs_inside``: nor is a run whose
  input file lies inside the directory it would replace);
- ``failed`` / ``interrupted``: the partial result goes to ``<name>.<status>`` (replacing an
  older partial of the same kind); a finished ``<name>`` is never touched, and nothing partial
  sits where a finished result is expected.

A run that writes checkpoints stages in a work directory ``.<name>.work.<pid>`` instead, which
outlives a killed process for ``flexmm run --resume`` (``RunDirectory``).

A commit killed midway leaves ``<name>`` either as it was or as the new run, never a mix: the
exchange is one system call (a kill after it leaves the old contents under the work directory's
name, which ``--resume`` recognises as older than the published run and removes); where the
filesystem cannot exchange, a kill between the two renames leaves the old directory aside as
``.<name>.old.<pid>``, which the next run into ``<name>`` renames back (``clean_stale``).

Leaving the ``with`` block without a commit (an error, a signal before the run started) removes
the staging directory. Staging directories and temporary files of processes that no longer run
(a ``kill -9``, a power cut) are removed by the next run into the same directory.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import fcntl
import json
import os
import re
import shutil
import socket
import time
from pathlib import Path

from flexmm.errors import OutputError
from flexmm.io.pause import pause_point

FINISHED = "finished"
#: where a run that did not finish is published: ``<name>.<status>``
PARTIAL = ("failed", "interrupted")
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
            home = directory / p.name[1 : -len(f".old.{pid}")] if p.name.endswith(f".old.{pid}") else None
            if home is not None and not home.exists():  # a commit killed between its two renames:
                os.rename(p, home)  # the previous result back in place (the new one is in its work directory)
                removed.append(p)
                continue
            if p.is_dir():
                shutil.rmtree(p, ignore_errors=True)
            else:
                p.unlink(missing_ok=True)
            removed.append(p)
    return removed


#: errors of a filesystem that has no ``flock`` (Lustre without ``-o flock``, some NFS, FUSE)
NO_FLOCK = frozenset({errno.ENOSYS, errno.ENOTSUP, errno.EOPNOTSUPP, errno.ENOLCK})


def _start_time(pid: int) -> str | None:
    """When process ``pid`` started (clock ticks since boot, ``/proc/<pid>/stat``), None if unknown."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = stat[stat.rfind(")") + 2 :].split()
    return fields[19] if len(fields) > 19 else None


def lock_holder() -> dict:
    """What an O_EXCL lock file says about its holder: this host, pid and process start time."""
    return {"host": socket.gethostname(), "pid": os.getpid(), "start": _start_time(os.getpid()),
            "since": time.strftime("%Y-%m-%dT%H:%M:%S%z")}


def lock_is_stale(holder: dict, host: str | None = None) -> bool:
    """True only when the lock's holder is known dead: it is on this host and its pid does not run
    (or runs a process started at another time: the pid was reused). A lock held on another host
    is never stale from here: its process cannot be seen, so it is reported, never taken."""
    if holder.get("host") != (host or socket.gethostname()) or not isinstance(holder.get("pid"), int):
        return False
    pid = holder["pid"]
    if not _pid_alive(pid):
        return True
    start = _start_time(pid)
    return holder.get("start") is not None and start is not None and start != holder["start"]


def read_holder(path: Path) -> dict | None:
    try:
        holder = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return holder if isinstance(holder, dict) else None


def _describe(holder: dict | None) -> str:
    if holder is None:
        return "an unknown process"
    return f"pid {holder.get('pid')} on host {holder.get('host')} since {holder.get('since', '?')}"


def claim(path: Path, mine: dict, stale=None) -> dict | None:
    """Create ``path`` with O_EXCL holding ``mine`` (JSON): None once it is ours, else what the
    file says about its live holder (``{}`` if unreadable). A file whose holder ``stale(holder,
    file)`` calls dead (default: ``lock_is_stale(holder)``) is broken first: renamed aside (atomic: of two breakers, the second finds nothing)
    and put back if a live holder's file was made meanwhile. OSError if the file cannot be made."""
    stale = stale or (lambda holder, _file: lock_is_stale(holder))
    for _attempt in range(3):
        try:
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:
            holder = read_holder(path)
            if holder is None:  # being written by its creator this instant, or left unreadable
                time.sleep(0.2)
                holder = read_holder(path)
            if holder is not None and stale(holder, path):
                broken = path.with_name(f"{path.name}.stale.{os.getpid()}")
                with contextlib.suppress(FileNotFoundError):
                    os.rename(path, broken)
                    taken = read_holder(broken)
                    if taken is not None and not stale(taken, broken):  # a live holder's file made meanwhile
                        with contextlib.suppress(OSError):
                            os.link(broken, path)  # put it back (never over a newer one)
                    broken.unlink(missing_ok=True)
                continue
            return holder or {}
        with os.fdopen(fd, "w") as fh:
            json.dump(mine, fh)
            fh.flush()
            os.fsync(fh.fileno())
        return None
    return read_holder(path) or {}


@contextlib.contextmanager
def _exclusive_file(path: Path, what: str):
    """The fallback where ``flock`` is unsupported: ``path`` created with O_EXCL, holding
    ``lock_holder()``; removed when the block ends. A lock left by a dead process on this host is
    broken (``lock_is_stale``); any other is reported with how to remove it by hand."""
    mine = lock_holder()
    try:
        holder = claim(path, mine)
    except OSError as exc:
        raise OutputError(f"cannot lock {what} with an O_EXCL lock file {path} (this filesystem does not "
                          f"support flock): {exc.strerror or exc}") from None
    if holder is not None:
        raise OutputError(
            f"{what} is in use by {_describe(holder or None)} (lock file {path}, created with O_EXCL because this "
            "filesystem does not support flock); wait for it to finish or choose another output. If no "
            f"flexmm process runs there any more, remove {path} by hand")
    try:
        yield
    finally:
        if read_holder(path) == mine:
            path.unlink(missing_ok=True)


@contextlib.contextmanager
def exclusive(lock_path: Path, what: str):
    """Hold an exclusive lock on ``lock_path`` (created if needed) for the block.

    ``OutputError`` naming ``what`` and the holder if another process holds it. The lock is the
    kernel's (``flock``): it is released when its holder exits, even by ``kill -9``. Where the
    filesystem does not support ``flock`` (``NO_FLOCK``), an O_EXCL lock file ``<lock>.excl``
    holding host, pid and start time is used instead (``_exclusive_file``).
    """
    try:
        lock_path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as exc:
        raise OutputError(f"cannot lock {what}: {exc.strerror or exc}") from None
    fallback = False
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 32, 0).decode(errors="replace").strip() or "?"
            raise OutputError(f"{what} is in use by another flexmm process (pid {holder}; flock on {lock_path}); "
                              "wait for it to finish or choose another output") from None
        except OSError as exc:
            if exc.errno not in NO_FLOCK:
                raise
            fallback = True
        if fallback:
            with _exclusive_file(lock_path.with_name(lock_path.name + ".excl"), what):
                yield
            return
        os.ftruncate(fd, 0)
        os.pwrite(fd, str(os.getpid()).encode(), 0)
        yield
    finally:
        if not fallback:
            with contextlib.suppress(OSError):
                fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)


#: what a run directory may hold (a run's outputs, its analysis and figures): anything else means
#: the path is not a run directory, and replacing it could destroy unrelated files
#: files only a flexmm run directory holds (one of them at least)
RUN_MARKERS = ("dataset.nc", "run.log")
RUN_FILE_SUFFIXES = (".nc", ".yaml", ".log", ".json", ".csv", ".png", ".svg", ".pdf", ".gif", ".mp4", ".lock", ".tmp",
                     ".ckpt")


def foreign_contents(directory: Path) -> list[str]:
    """Entries of ``directory`` that a flexmm run directory would not hold (subdirectories, other files).

    A directory with files but neither ``dataset.nc`` nor ``run.log`` is not one flexmm wrote
    (every committed run directory, finished or partial, holds its log): all its files are then
    foreign, so a user's own ``config.yaml`` copied into a fresh ``--out`` directory is never replaced.
    """
    entries = list(directory.iterdir())
    if entries and not any((directory / name).is_file() for name in RUN_MARKERS):
        return sorted(p.name for p in entries)
    return sorted(p.name for p in entries if p.is_dir() or not p.name.endswith(RUN_FILE_SUFFIXES))


def _shown(names: list[str]) -> str:
    return ", ".join(names[:5]) + (", ..." if len(names) > 5 else "")


def refuse_inputs_inside(run_dir: Path, inputs) -> None:
    """``OutputError`` if an input file (a scene the user wrote) lies inside ``run_dir`` or one of its
    partial siblings (``.failed``/``.interrupted``): committing the run would replace it."""
    final = Path(run_dir).expanduser().absolute().resolve()
    homes = [final] + [final.with_name(f"{final.name}.{status}") for status in PARTIAL]
    for item in inputs:
        path = Path(item).expanduser().absolute().resolve()
        for home in homes:
            if home in path.parents:
                raise OutputError(f"the input {item} is inside the run directory {home}, whose contents a run "
                                  "replaces: move the input elsewhere or choose another --out (flexmm never "
                                  "writes over its inputs)")


#: a file that makes a staging directory worth keeping when its run dies (``flexmm.checkpoint.NAME``)
CHECKPOINT_FILE = "checkpoint.ckpt"


class RunDirectory:
    """Lock ``final``, give a staging directory to write in, commit it (module docstring).

    ``checkpoints``: the run writes checkpoints into its staging directory, so it is a *work*
    directory ``.<name>.work.<pid>`` that outlives the process when the run dies (a ``kill -9``
    leaves it for ``flexmm run --resume``; leaving the block uncommitted keeps it if it holds a
    checkpoint). A new run discards the work directories of earlier ones (``discarded``) unless
    ``keep_work`` (a resume, which reads them: ``work_dirs``).
    """

    def __init__(self, final: str | Path, *, checkpoints: bool = False, keep_work: bool = False):
        self.final = Path(final).expanduser()
        self.parent = self.final.parent
        name = self.final.name
        self.lock_path = self.parent / f".{name}.lock"
        kind = "work" if checkpoints else "staging"
        self.stage = self.parent / f".{name}.{kind}.{os.getpid()}"
        self.keep_work = keep_work
        self.discarded: list[Path] = []
        self.committed: Path | None = None
        self._lock = exclusive(self.lock_path, f"run directory {self.final}")

    def work_dirs(self) -> list[Path]:
        """Work directories of earlier runs into ``final`` (their processes ended: the lock is ours)."""
        pattern = re.compile(rf"^\.{re.escape(self.final.name)}\.work\.(\d+)$")
        if not self.parent.is_dir():
            return []
        return sorted(p for p in self.parent.iterdir() if p != self.stage and pattern.match(p.name) and p.is_dir())

    def __enter__(self) -> RunDirectory:
        for status in ("", *PARTIAL):  # every directory a commit may replace
            where = self.final.with_name(f"{self.final.name}.{status}") if status else self.final
            foreign = foreign_contents(where) if where.is_dir() else []
            if foreign:
                raise OutputError(f"{where} exists and is not a flexmm run directory (it holds {_shown(foreign)}, "
                                  "files flexmm did not write); a run replaces its run directory, so flexmm "
                                  "refuses rather than delete them: choose a new or empty directory")
        self._lock.__enter__()
        clean_stale(self.parent)
        if self.final.is_dir():
            clean_stale(self.final)
        if not self.keep_work:
            for old in self.work_dirs():
                shutil.rmtree(old, ignore_errors=True)
                self.discarded.append(old)
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
                    pause_point("commit:exchanged")
                    shutil.rmtree(self.stage, ignore_errors=True)  # the old result, swapped out
                else:  # two renames, under the lock; a kill between them is undone by the next run (clean_stale)
                    old = self.parent / f".{self.final.name}.old.{os.getpid()}"
                    os.rename(target, old)
                    pause_point("commit:moved-old")
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
        if self.committed is None and self.stage.exists() and not (self.stage / CHECKPOINT_FILE).is_file():
            shutil.rmtree(self.stage, ignore_errors=True)
        self._lock.__exit__(*exc)
