"""Slices of a sweep (``--shard K/N``) and the locks that let them share one store.

Shard K of N is the K-th of N contiguous, nearly equal ranges of the point numbers (C order over
the sweep's shape), K = 0 … N−1, so a job array's task id is the shard number
(``--shard $SLURM_ARRAY_TASK_ID/N``). Shards of one sweep run into the same directory at once:

- ``sweep_lock``: a sweep of every point holds ``SWEEP_DIR/.sweep.lock`` exclusively; a shard
  holds it shared (any number of shards, never together with a whole sweep) plus
  ``SWEEP_DIR/.shard-K-of-N.lock`` exclusively (the same shard twice at once is refused; run
  again later, it resumes);
- ``store_lock``: a short, blocking, exclusive lock around laying the store out and writing the
  combined dataset, so the first shard lays the store out and the others open it, and the last
  shard to finish (the one that finds no point pending) writes ``sweep.nc``.

Each shard writes only its own points' bytes of the store (``flexmm.sweep.store``). Locks are
the kernel's ``flock``: released when their holder dies, even by ``kill -9``.
"""

from __future__ import annotations

import fcntl
import os
import re
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

from flexmm.errors import OutputError, UsageError
from flexmm.io.rundir import NO_FLOCK, exclusive


@dataclass(frozen=True)
class Shard:
    """Slice ``k`` of ``n`` (0 ≤ k < n) of a sweep's points."""

    k: int
    n: int

    def range(self, n_points: int) -> range:
        """The point numbers of this shard: [k·P/n, (k+1)·P/n) of P points."""
        return range(self.k * n_points // self.n, (self.k + 1) * n_points // self.n)

    def __str__(self) -> str:
        return f"{self.k}/{self.n}"


def parse_shard(text: str) -> Shard:
    """``K/N`` with 0 ≤ K < N as a Shard; UsageError naming the option otherwise."""
    m = re.fullmatch(r"\s*(\d+)\s*/\s*(\d+)\s*", text or "")
    if not m or not 0 <= int(m[1]) < int(m[2]):
        raise UsageError(f"--shard {text!r}: expected K/N with 0 ≤ K < N, e.g. --shard 0/4 "
                         "(K is a job array's task id: --array=0-3 with --shard $SLURM_ARRAY_TASK_ID/4)")
    return Shard(int(m[1]), int(m[2]))


@contextmanager
def _flock(path: Path, how: int, busy: str | None) -> Iterator[bool]:
    """Hold flock ``how`` on ``path``; non-blocking with OutputError ``busy`` if given, else wait.
    Yields False (and holds nothing) where the filesystem has no flock."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, how | (fcntl.LOCK_NB if busy else 0))
        except BlockingIOError:
            raise OutputError(busy) from None
        except OSError as exc:
            if exc.errno not in NO_FLOCK:
                raise
            yield False
            return
        yield True
    finally:
        os.close(fd)  # releases the lock


@contextmanager
def sweep_lock(root: Path, shard: Shard | None = None) -> Iterator[None]:
    """One sweep of every point per directory, or any number of distinct shards (module docstring)."""
    with ExitStack() as stack:
        if shard is None:  # the run directories' lock (with its fallback where there is no flock)
            stack.enter_context(exclusive(root / ".sweep.lock", f"sweep directory {root}"))
        else:
            held = [stack.enter_context(_flock(root / ".sweep.lock", fcntl.LOCK_SH,
                                               f"sweep directory {root} is in use by a flexmm sweep of every "
                                               "point; wait for it to finish")),
                    stack.enter_context(_flock(root / f".shard-{shard.k}-of-{shard.n}.lock", fcntl.LOCK_EX,
                                               f"shard {shard} of {root} is already running"))]
            if not all(held):
                raise OutputError(f"{root} is on a filesystem without file locks (flock), which shards "
                                  "need: run the sweep there without --shard")
        yield


@contextmanager
def store_lock(root: Path) -> Iterator[None]:
    """Wait for, then hold, the store's lock (laying it out, writing the combined dataset)."""
    with _flock(root / ".store.lock", fcntl.LOCK_EX, None):
        yield

