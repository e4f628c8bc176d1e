"""After a success the console script ends without the interpreter's teardown, keeping the exit
handlers and the output (issue 37); failures, interruptions and runs with other threads alive
exit the ordinary way."""

from __future__ import annotations

import atexit
import os
import subprocess
import sys
import threading
from pathlib import Path

import pytest

import flexmm.cli as cli

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "lego_vector_soliton.yaml"
FLEXMM = str(Path(sys.executable).with_name("flexmm"))


class _Ended(Exception):
    pass


@pytest.fixture
def ending(monkeypatch):
    """Record the calls of os._exit and of the exit handlers instead of making them (with no
    dataset abandoned by an earlier test in this process: that exit is tested in test_nothing_lost)."""
    from flexmm.io import run_dataset

    monkeypatch.setattr(run_dataset, "ABANDONED", [])
    calls = []

    def fake_exit(code):
        calls.append(("exit", code))
        raise _Ended

    monkeypatch.setattr(os, "_exit", fake_exit)
    monkeypatch.setattr(atexit, "_run_exitfuncs", lambda: calls.append(("handlers", None)))
    return calls


@pytest.mark.parametrize("raised", [None, 0])
def test_a_success_ends_after_the_handlers_and_the_output(monkeypatch, ending, capsys, raised):
    def fake_app():
        print("out")
        raise SystemExit(raised)

    monkeypatch.setattr(cli, "app", fake_app)
    monkeypatch.setattr(threading, "active_count", lambda: 1)  # an earlier test's daemon thread is not this command's
    with pytest.raises(_Ended):
        cli.main()
    assert ending == [("handlers", None), ("exit", 0)]
    assert capsys.readouterr().out == "out\n"


@pytest.mark.parametrize(("raised", "status"), [(2, 2), (130, 130), (143, 143), ("bad", 1)])
def test_a_failure_exits_the_ordinary_way_with_its_status(monkeypatch, ending, capsys, raised, status):
    import gc

    frozen = []
    monkeypatch.setattr(gc, "freeze", lambda: frozen.append(True))  # not this test process's objects
    monkeypatch.setattr(cli, "app", lambda: (_ for _ in ()).throw(SystemExit(raised)))
    with pytest.raises(SystemExit) as exc:
        cli.main()
    assert exc.value.code == status and ending == []
    assert frozen == ([True] if status in (130, 143) else [])  # after a signal: the teardown skips the collection
    assert capsys.readouterr().err == ("bad\n" if raised == "bad" else "")


def test_ordinary_exit_while_another_thread_runs(monkeypatch, ending):
    monkeypatch.setattr(cli, "app", lambda: (_ for _ in ()).throw(SystemExit(0)))
    stop = threading.Event()
    t = threading.Thread(target=stop.wait)
    t.start()
    try:
        with pytest.raises(SystemExit) as exc:
            cli.main()
    finally:
        stop.set()
        t.join()
    assert exc.value.code == 0 and ending == []


def test_console_script_output_and_status():
    ok = subprocess.run([FLEXMM, "validate", str(CONFIG), "--no-build"], capture_output=True, text=True)
    assert ok.returncode == 0 and ok.stdout.strip()
    bad = subprocess.run([FLEXMM, "validate", str(CONFIG) + ".missing"], capture_output=True, text=True)
    assert bad.returncode == 2 and bad.stderr.startswith("error:")
