"""Per-point leases (``flexmm.sweep.lease``): two workers handed the same points run each once
(two real processes: overlapping shards started together); a lease of a killed process is taken
over, a live one is not; a lease on another host is taken over only once its heartbeat is older
than the TTL; a holder whose lease was taken over does not publish."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time

import pytest
from test_sweep_shard import CLI, N_POINTS, VALUES, points_run, shard_cmd, spec_path

from flexmm.io.rundir import lock_holder
from flexmm.sweep.lease import Lease
from flexmm.sweep.store import CODE, FINISHED, PENDING, SweepStore


def test_overlapping_shards_at_once_run_each_shared_point_once(tmp_path):
    # shard 0/2 is points 0-2 and shard 0/3 points 0-1: both plans see points 0 and 1 pending
    # and both are handed them; without the lease each would run (and store) them
    spec, out = spec_path(tmp_path), tmp_path / "sw"
    procs = [subprocess.Popen(shard_cmd(spec, out, s), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for s in ("0/2", "0/3")]
    results = [p.communicate(timeout=600) for p in procs]
    for p, (_, err) in zip(procs, results):
        assert p.returncode == 0, err
    ran = sorted(points_run(results[0][1]) + points_run(results[1][1]))
    assert ran == VALUES[:3], results  # each point once, in one process or the other
    assert "not run here" in results[0][1] + results[1][1]  # one of them met the other's lease
    status = SweepStore(out).status().tolist()
    assert status == [CODE[FINISHED]] * 3 + [CODE[PENDING]] * (N_POINTS - 3)
    assert not list((out / "store" / "leases").iterdir())  # every lease released


HOLD = """
import sys, time
from flexmm.sweep.lease import Lease
lease = Lease(sys.argv[1], 0)
assert lease.acquire() is None
print("held", flush=True)
time.sleep(600)
"""


def test_a_live_holders_lease_is_refused_and_a_killed_ones_taken_over(tmp_path):
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(tmp_path)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        mine = Lease(tmp_path, 0)
        said = mine.acquire()
        assert said is not None and f"pid {holder.pid} on host {socket.gethostname()}" in said
        os.kill(holder.pid, signal.SIGKILL)
        holder.wait(timeout=30)
        assert mine.acquire() is None and mine.held()  # the dead process's lease is broken
        mine.release()
        assert not mine.path.exists()
    finally:
        holder.kill()
        holder.wait()


def _leased_elsewhere(tmp_path, age_s: float) -> Lease:
    lease = Lease(tmp_path, 3, ttl_s=60)
    lease.path.parent.mkdir(parents=True)
    lease.path.write_text(json.dumps({**lock_holder(), "host": "node-that-cannot-be-seen", "pid": 12345}))
    then = time.time() - age_s
    os.utime(lease.path, (then, then))
    return lease


def test_a_lease_on_another_host_is_taken_over_only_after_its_heartbeat_stops(tmp_path):
    fresh = _leased_elsewhere(tmp_path / "a", age_s=5)
    said = fresh.acquire()
    assert said is not None and "pid 12345 on host node-that-cannot-be-seen" in said
    old = _leased_elsewhere(tmp_path / "b", age_s=61)
    assert old.acquire() is None and old.held()
    old.release()


def test_an_empty_lease_is_taken_over_only_after_the_ttl(tmp_path):
    # its creator died between creating the file (O_EXCL) and writing its name in it
    lease = Lease(tmp_path, 5, ttl_s=60)
    lease.path.parent.mkdir(parents=True)
    lease.path.write_text("")
    assert lease.acquire() is not None  # might be being written this instant
    then = time.time() - 61
    os.utime(lease.path, (then, then))
    assert lease.acquire() is None and lease.held()
    lease.release()


def test_the_heartbeat_keeps_a_lease_fresh_and_a_taken_over_lease_is_not_ours(tmp_path):
    lease = Lease(tmp_path, 0, heartbeat_s=0.1)
    assert lease.acquire() is None
    then = time.time() - 1000
    os.utime(lease.path, (then, then))
    time.sleep(0.5)
    assert time.time() - lease.path.stat().st_mtime < 5  # touched again by the heartbeat
    # another worker found it stale (e.g. this one was cut off) and took it
    lease.path.write_text(json.dumps({**lock_holder(), "host": "other", "pid": 1}))
    assert not lease.held()
    lease.release()
    assert lease.path.exists()  # the new holder's lease is left alone


@pytest.mark.parametrize("state", [FINISHED, "failed"])
def test_a_point_stored_by_another_worker_meanwhile_is_not_run_again(tmp_path, state):
    from flexmm.sweep import load_sweep
    from flexmm.sweep.observe import OBSERVABLES
    from flexmm.sweep.worker import ELSEWHERE, run_point

    spec = load_sweep(spec_path(tmp_path))
    store = SweepStore(tmp_path / "sw")
    store.create_or_check("x", N_POINTS, list(OBSERVABLES), "t")
    store.write_point(2, state, note="stored by the other worker")
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    out = run_point(spec, 2, store, scratch)
    assert out["status"] == ELSEWHERE and state in out["reason"]
    assert store.read()["note"][2].decode() == "stored by the other worker"


def test_a_point_held_elsewhere_is_waited_for_and_taken_over_when_its_holder_dies(tmp_path):
    # another process holds point 0's lease; the sweep runs point 1 (the rest of that batch), then
    # waits for point 0 instead of running it beside its holder; the holder killed, it runs it
    spec, out = spec_path(tmp_path), tmp_path / "sw"
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(out / "store")], stdout=subprocess.PIPE, text=True)
    sweep = None
    try:
        assert holder.stdout.readline().strip() == "held"
        sweep = subprocess.Popen([*CLI, str(spec), "--out", str(out), "--workers", "1", "--batch-size", "2"],
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        store, t0 = SweepStore(out), time.monotonic()
        while not (store.exists() and store.state(1) == FINISHED):
            assert sweep.poll() is None, sweep.communicate()
            assert time.monotonic() - t0 < 600
            time.sleep(0.1)
        time.sleep(2)  # waiting for the lease, not running point 0 (nor the next batch)
        assert store.state(0) == PENDING and store.state(2) == PENDING and sweep.poll() is None
        os.kill(holder.pid, signal.SIGKILL)
        holder.wait(timeout=30)
        _, err = sweep.communicate(timeout=600)
    finally:
        holder.kill()
        holder.wait()
        if sweep is not None and sweep.poll() is None:
            sweep.kill()
            sweep.wait()
    assert sweep.returncode == 0, err
    assert sorted(points_run(err)) == VALUES  # point 0 run here, once, after its holder died
    assert SweepStore(out).status().tolist() == [CODE[FINISHED]] * N_POINTS
