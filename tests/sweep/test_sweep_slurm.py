"""A sharded sweep as a job array on a real single-node SLURM (slurmctld + slurmd + munge from
Debian's slurm-wlm, started by the fixture): every point run once, into one store."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest
import slurm_cluster
import xarray as xr
from test_sweep_shard import SPEC, points_run

from flexmm.sweep.store import CODE, FINISHED, SweepStore

N_TASKS = 4
VALUES = [round(0.3 + 0.03 * i, 2) for i in range(8)]


@pytest.fixture(scope="module")
def slurm(tmp_path_factory):
    """A SLURM cluster of this host (2 CPUs), for the module's tests."""
    why = slurm_cluster.missing()
    if why:
        pytest.skip(why)
    cluster = slurm_cluster.start(tmp_path_factory.mktemp("slurm"), cpus=2)
    yield cluster
    cluster.stop()


@pytest.mark.slow
def test_job_array_of_shards_runs_every_point_once_into_one_store(slurm, tmp_path):
    spec = tmp_path / "array.yaml"
    spec.write_text(textwrap.dedent(SPEC).replace("[0.3, 0.35, 0.4, 0.45, 0.5, 0.55]", str(VALUES)))
    out = tmp_path / "sw"
    cmd = [sys.executable, "-c", "from flexmm.cli import main; main()", "sweep", str(spec), "--out", str(out),
           "--cluster", "slurm", "--shards", str(N_TASKS), "--quiet"]
    submitted = subprocess.run(cmd, capture_output=True, text=True, env=slurm.env, timeout=300)
    assert submitted.returncode == 0, submitted.stderr
    job = submitted.stdout.strip()
    assert job.isdigit(), submitted.stdout
    slurm.wait_jobs(job, timeout=900)

    logs = sorted((out / "slurm").glob(f"{job}_*.out"))
    assert [p.name for p in logs] == [f"{job}_{k}.out" for k in range(N_TASKS)], slurm.logs()
    ran = [points_run(p.read_text()) for p in logs]
    assert sorted(v for r in ran for v in r) == VALUES, [p.read_text() for p in logs]  # each point once
    assert all(len(r) == 2 for r in ran)  # two points per task
    assert SweepStore(out).status().tolist() == [CODE[FINISHED]] * len(VALUES)
    ds = xr.load_dataset(out / "sweep.nc", engine="h5netcdf")  # written by the last task to finish
    assert (ds["status"].values == "finished").all() and np.isfinite(ds["amplitude"].values).all()
    assert not any("error" in p.read_text().lower() for p in logs)
