"""Per-point leases: one worker at a time runs a point of a sweep, on any number of hosts.

Two workers may be handed the same point: a Dask cluster whose scheduler lost sight of a worker
that still runs (a network partition) gives its batch to another; shards of different N overlap;
a sweep run again on another host while the first still runs. Before a worker touches a point
(its checkpoints in ``SWEEP_DIR/work/<i>/``, its run directory, its bytes of the store) it takes
the point's lease ``SWEEP_DIR/store/leases/<i>.lease``: a file created with O_EXCL (atomic on
local filesystems and NFS v3+) holding its host, pid and process start time
(``flexmm.io.rundir.lock_holder``). While it holds the lease a thread touches the file every
``HEARTBEAT_S`` seconds; the lease goes once the point is stored (or stopped).

A lease is *stale*, and the next worker breaks it (``flexmm.io.rundir.claim``), when its holder
is known dead: on this host, its pid does not run (or runs another process: the pid was reused);
on another host, its heartbeat is older than ``ttl_s`` (default ``LEASE_TTL_S``; a live holder
touches it far more often). A worker that finds a point leased by a live holder leaves it for
later in its batch and, once its other points are done, waits for the lease to go: the point is
then finished (nothing to do) or pending again (the holder was stopped or died: it runs it,
continuing from its checkpoint). A holder checks that the lease is still its own just before it
publishes the point, so a worker cut off for longer than the TTL, whose point was taken over,
does not write it a second time.
"""

from __future__ import annotations

import contextlib
import os
import socket
import threading
import time
from pathlib import Path

from flexmm.io.rundir import read_holder, claim, lock_holder, lock_is_stale

#: seconds between a holder's touches of its lease file
HEARTBEAT_S = 10.0
#: a lease held on another host whose heartbeat is older than this is taken over
LEASE_TTL_S = 120.0
#: seconds between looks at a lease held by another worker
POLL_S = 0.5
LEASES = "leases"


def describe(holder: dict) -> str:
    """'pid P on host H since T' of a lease's holder."""
    return f"pid {holder.get('pid', '?')} on host {holder.get('host', '?')} since {holder.get('since', '?')}"


class Lease:
    """The lease of one point (``SWEEP_DIR/store/leases/<index>.lease``).

    ``acquire()`` → None when taken (its heartbeat runs until ``release()``), else the live
    holder's description; ``held()`` → whether the file still names this process.
    """

    def __init__(self, store_dir: str | Path, index: int, ttl_s: float = LEASE_TTL_S,
                 heartbeat_s: float = HEARTBEAT_S):
        self.path = Path(store_dir) / LEASES / f"{index}.lease"
        self.ttl_s, self.heartbeat_s = ttl_s, heartbeat_s
        self.mine: dict | None = None
        self._stop = threading.Event()
        self._beat: threading.Thread | None = None

    def stale(self, holder: dict, file: Path | None = None) -> bool:
        """Its holder is dead: on this host by its pid, elsewhere by a heartbeat (the mtime of
        ``file``, the lease's by default) older than the TTL."""
        if holder.get("host") == socket.gethostname():
            return lock_is_stale(holder)
        try:
            age = time.time() - (file or self.path).stat().st_mtime
        except FileNotFoundError:
            return False  # gone meanwhile: the next attempt creates it
        return age > self.ttl_s

    def acquire(self) -> str | None:
        """Take the lease (None), or say who holds it."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        mine = {**lock_holder(), "thread": threading.get_ident()}
        holder = claim(self.path, mine, self.stale)
        if holder == {} and self._abandoned():  # its creator died before writing who it was
            aside = self.path.with_name(f"{self.path.name}.abandoned.{os.getpid()}")
            with contextlib.suppress(FileNotFoundError):
                os.rename(self.path, aside)  # atomic: of two workers, one moves it
                aside.unlink()
            holder = claim(self.path, mine, self.stale)
        if holder is not None:
            return describe(holder)
        self.mine = mine
        self._stop.clear()
        self._beat = threading.Thread(target=self._heartbeat, name=f"flexmm-lease-{self.path.stem}", daemon=True)
        self._beat.start()
        return None

    def _abandoned(self) -> bool:
        """The lease file says nothing (its creator died between creating and writing it) and has
        not been touched for the TTL."""
        try:
            return read_holder(self.path) is None and time.time() - self.path.stat().st_mtime > self.ttl_s
        except FileNotFoundError:
            return False

    def _heartbeat(self) -> None:
        while not self._stop.wait(self.heartbeat_s):
            with contextlib.suppress(OSError):
                if self.held():
                    os.utime(self.path)

    def held(self) -> bool:
        """True while the lease file is this holder's (not broken by a worker that found it stale)."""
        return self.mine is not None and read_holder(self.path) == self.mine

    def release(self) -> None:
        """Stop the heartbeat and remove the lease file if it is still ours."""
        self._stop.set()
        if self._beat is not None:
            self._beat.join()
            self._beat = None
        if self.held():
            self.path.unlink(missing_ok=True)
        self.mine = None

    def wait(self) -> None:
        """Until the lease file is gone or stale (KeyboardInterrupt stops the wait)."""
        while True:
            holder = read_holder(self.path)
            if holder is None and (not self.path.exists() or self._abandoned()):
                return
            if holder is not None and self.stale(holder):
                return
            time.sleep(POLL_S)
