"""Slices of a sweep (``--shard K/N``) into one store: two shards running at once in two real
processes, each point run once, resumable, the same shard twice refused, another spec's store
refused."""

from __future__ import annotations

import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from test_sweep_store import BASE

from flexmm.errors import OutputError, UsageError
from flexmm.sweep import load_sweep
from flexmm.sweep.execute import prepare
from flexmm.sweep.shard import Shard, parse_shard, sweep_lock
from flexmm.sweep.store import CODE, FINISHED, SweepStore

N_POINTS = 6
VALUES = [round(0.3 + 0.05 * i, 2) for i in range(N_POINTS)]

SPEC = textwrap.dedent(BASE) + textwrap.dedent(f"""\
    vary:
      grid:
        excitation.amplitude_rad: {VALUES}
    """)
CLI = [sys.executable, "-c", "from flexmm.cli import main; main()", "sweep"]


def spec_path(tmp_path: Path, text: str = SPEC) -> Path:
    p = tmp_path / "shard.yaml"
    p.write_text(textwrap.dedent(text))
    return p


def shard_cmd(spec: Path, out: Path, shard: str) -> list[str]:
    return [*CLI, str(spec), "--out", str(out), "--shard", shard, "--workers", "1"]


def points_run(stderr: str) -> list[float]:
    """The amplitudes of the points a `flexmm sweep` run reports it ran (one line per point)."""
    return [float(v) for v in re.findall(r"\] finished excitation\.amplitude_rad=([0-9.]+)", stderr)]


@pytest.mark.parametrize("n_points", [0, 1, 5, 6, 7, 1000, 10**6 + 3])
@pytest.mark.parametrize("n", [1, 2, 3, 4, 7])
def test_shards_partition_the_points(n_points, n):
    ranges = [Shard(k, n).range(n_points) for k in range(n)]
    assert [i for r in ranges for i in r] == list(range(n_points))  # each point in exactly one shard, in order
    assert max(map(len, ranges)) - min(map(len, ranges)) <= 1


@pytest.mark.parametrize("text", ["4/4", "-1/4", "1", "a/b", "1/0", ""])
def test_a_bad_shard_is_a_usage_error(text):
    with pytest.raises(UsageError, match="expected K/N with 0 ≤ K < N"):
        parse_shard(text)


def test_two_shards_at_once_fill_one_store_each_point_once(tmp_path):
    spec, out = spec_path(tmp_path), tmp_path / "sw"
    procs = [subprocess.Popen(shard_cmd(spec, out, f"{k}/2"), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True) for k in range(2)]
    results = [p.communicate(timeout=600) for p in procs]
    for p, (_, err) in zip(procs, results):
        assert p.returncode == 0, err
    ran = [points_run(err) for _, err in results]
    assert sorted(ran[0]) == VALUES[:3] and sorted(ran[1]) == VALUES[3:]  # each shard its own slice, once
    status = SweepStore(out).status()
    assert status.tolist() == [CODE[FINISHED]] * N_POINTS
    ds = xr.load_dataset(out / "sweep.nc", engine="h5netcdf")  # written by the shard that finished last
    assert (ds["status"].values == "finished").all() and np.isfinite(ds["amplitude"].values).all()
    assert ds["amplitude_rad"].values.tolist() == VALUES

    again = subprocess.run(shard_cmd(spec, out, "1/2"), capture_output=True, text=True, timeout=300)
    assert again.returncode == 0 and "0 to run" in again.stderr and points_run(again.stderr) == []


def test_a_shard_resumes_its_own_slice_only(tmp_path):
    spec, out = spec_path(tmp_path), tmp_path / "sw"
    first = subprocess.run(shard_cmd(spec, out, "0/3"), capture_output=True, text=True, timeout=300)
    assert first.returncode == 0, first.stderr
    assert sorted(points_run(first.stderr)) == VALUES[:2]
    assert "4 points of the sweep are pending in other shards" in first.stderr
    assert not (out / "sweep.nc").exists()  # not the whole sweep yet
    plan = prepare(load_sweep(spec), out, shard=Shard(1, 3))
    assert plan.tasks.tolist() == [2, 3] and plan.count("finished") == 0
    assert plan.count("finished", everywhere=True) == 2
    whole = prepare(load_sweep(spec), out)
    assert whole.tasks.tolist() == [2, 3, 4, 5]  # a sweep of every point resumes what the shard left


def test_the_same_shard_twice_at_once_and_a_whole_sweep_during_shards_are_refused(tmp_path):
    root = tmp_path / "sw"
    with sweep_lock(root, Shard(0, 2)):
        with sweep_lock(root, Shard(1, 2)):  # another shard: fine
            pass
        with pytest.raises(OutputError, match="shard 0/2 of .* is already running"):
            with sweep_lock(root, Shard(0, 2)):
                pass
        with pytest.raises(OutputError, match="in use by another flexmm process"):
            with sweep_lock(root):
                pass
    with sweep_lock(root):
        with pytest.raises(OutputError, match="in use by a flexmm sweep of every point"):
            with sweep_lock(root, Shard(1, 2)):
                pass


def test_a_shard_into_a_store_of_another_spec_is_refused(tmp_path):
    spec, out = spec_path(tmp_path), tmp_path / "sw"
    first = subprocess.run(shard_cmd(spec, out, "0/3"), capture_output=True, text=True, timeout=300)
    assert first.returncode == 0, first.stderr
    other = spec_path(tmp_path, SPEC.replace("amplitude_rad: 0.4,", "amplitude_rad: 0.5,"))
    refused = subprocess.run(shard_cmd(other, out, "1/3"), capture_output=True, text=True, timeout=300)
    assert refused.returncode == 2 and "holds the results of another sweep" in refused.stderr
    assert points_run(refused.stderr) == []


def test_cluster_slurm_dry_run_prints_the_job_array_script(tmp_path):
    spec, out = spec_path(tmp_path), tmp_path / "sw"
    done = subprocess.run([*CLI, str(spec), "--out", str(out), "--cluster", "slurm", "--shards", "3", "-j", "2",
                           "--sbatch=--time=0:10:00", "--dry-run"], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    script = done.stdout
    assert script.startswith("#!/bin/bash\n")
    assert "#SBATCH --array=0-2\n" in script and "#SBATCH --cpus-per-task=2\n" in script
    assert "#SBATCH --time=0:10:00\n" in script
    assert f"--out {out}" in script and '--shard "$SLURM_ARRAY_TASK_ID/3"' in script and str(spec) in script
    assert not (out / "store").exists()  # nothing laid out, nothing submitted
