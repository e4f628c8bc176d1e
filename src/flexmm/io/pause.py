"""A test hook: stop the process at a named point of writing its outputs, for fault tests.

``FLEXMM_PAUSE_AT=NAME[:N]`` makes the N-th arrival (default the first) of this process at
``pause_point(NAME)`` stop the process with SIGSTOP, as a debugger's breakpoint would. The test
that set it then acts at exactly that moment — fills the disk, sends SIGKILL — and sends SIGCONT
(or SIGKILL). Nothing is injected into the writes themselves: what fails afterwards fails on
the real filesystem. Unset (always, outside the fault tests), ``pause_point`` does nothing.

Points: ``plan`` (a scene's planning starts), ``build`` (a lattice is built), ``pilot`` (an
accuracy pilot starts), ``frame`` (a frame of the run is written), ``checkpoint`` (before a checkpoint file is written), ``commit`` (a run's outputs are
complete in its work or staging directory; before config.yaml, run.log and the rename that
publishes them), ``commit:exchanged`` (the new directory swapped into place, the old one not yet
removed), ``commit:moved-old`` (no atomic exchange on this filesystem: the old directory moved
aside, the new one not yet renamed into place).
"""

from __future__ import annotations

import os
import signal

VARIABLE = "FLEXMM_PAUSE_AT"
_seen: dict[str, int] = {}


def pause_point(name: str) -> None:
    """Stop this process (SIGSTOP) if ``FLEXMM_PAUSE_AT`` names this point and arrival (module docstring)."""
    want = os.environ.get(VARIABLE)
    if not want:
        return
    where, _, nth = want.rpartition(":")
    if not nth.isdigit():  # a point name with a colon, no count
        where, nth = want, "1"
    if where != name:
        return
    _seen[name] = _seen.get(name, 0) + 1
    if _seen[name] == int(nth):
        os.kill(os.getpid(), signal.SIGSTOP)
