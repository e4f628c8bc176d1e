"""A sharded sweep as a PBS job array (``--cluster pbs``): the script ``--dry-run`` prints, and its
submission with ``qsub``, which here is a stand-in (``fake_qsub.py``: there is no PBS server on
this machine) that records its arguments and runs the array's subjobs locally, all at once."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import xarray as xr
from test_sweep_shard import CLI, SPEC, points_run

from flexmm.sweep.store import CODE, FINISHED, SweepStore

HERE = Path(__file__).resolve().parent
N_TASKS = 3
VALUES = [round(0.3 + 0.03 * i, 2) for i in range(6)]


def spec_file(tmp_path: Path) -> Path:
    spec = tmp_path / "array.yaml"
    spec.write_text(textwrap.dedent(SPEC).replace("[0.3, 0.35, 0.4, 0.45, 0.5, 0.55]", str(VALUES)))
    return spec


def test_cluster_pbs_dry_run_prints_a_pbs_job_array(tmp_path):
    spec, out = spec_file(tmp_path), tmp_path / "sw"
    done = subprocess.run([*CLI, str(spec), "--out", str(out), "--cluster", "pbs", "--shards", "5", "-j", "2",
                           "--qsub=-l walltime=0:10:00", "--qsub=-q short", "--dry-run"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0] == "#!/bin/bash"
    for directive in ("#PBS -J 0-4", "#PBS -l select=1:ncpus=2", "#PBS -l walltime=0:10:00", "#PBS -q short",
                      "#PBS -j oe", f"#PBS -o {out}/pbs/flexmm.^array_index^.out"):
        assert directive in lines, done.stdout
    assert '--shard "$PBS_ARRAY_INDEX/5"' in done.stdout and '--workers "${NCPUS:-2}"' in done.stdout
    assert "SBATCH" not in done.stdout and not (out / "store").exists()  # nothing laid out or submitted


def test_an_unknown_cluster_lists_the_known_ones(tmp_path):
    done = subprocess.run([*CLI, str(spec_file(tmp_path)), "--cluster", "lsf", "--dry-run"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 2 and "expected one of slurm, pbs" in done.stderr and "Traceback" not in done.stderr


def test_cluster_pbs_submits_a_job_array_with_qsub_every_point_once(tmp_path):
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    qsub = bin_dir / "qsub"
    qsub.write_text(f"#!/bin/sh\nexec {sys.executable} {HERE / 'fake_qsub.py'} \"$@\"\n")
    qsub.chmod(0o755)
    record = tmp_path / "qsub.jsonl"
    env = {**os.environ, "PATH": f"{bin_dir}{os.pathsep}{os.environ['PATH']}", "FAKE_QSUB_LOG": str(record)}
    spec, out = spec_file(tmp_path), tmp_path / "sw"
    done = subprocess.run([*CLI, str(spec), "--out", str(out), "--cluster", "pbs", "--shards", str(N_TASKS),
                           "--quiet"], capture_output=True, text=True, env=env, timeout=900)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().endswith("[].fakepbs")  # the job id qsub printed

    calls = [json.loads(line) for line in record.read_text().splitlines()]
    assert len(calls) == 1 and calls[0]["argv"] == [str(out / "pbs" / "sweep.pbs")]
    assert calls[0]["directives"]["-J"] == f"0-{N_TASKS - 1}"
    logs = sorted((out / "pbs").glob("flexmm.*.out"))
    assert [p.name for p in logs] == [f"flexmm.{k}.out" for k in range(N_TASKS)]
    ran = [points_run(p.read_text()) for p in logs]
    assert [sorted(r) for r in ran] == [VALUES[2 * k: 2 * k + 2] for k in range(N_TASKS)], ran  # its shard, once
    assert SweepStore(out).status().tolist() == [CODE[FINISHED]] * len(VALUES)
    ds = xr.load_dataset(out / "sweep.nc", engine="h5netcdf")  # written by the last subjob to finish
    assert (ds["status"].values == "finished").all() and np.isfinite(ds["amplitude"].values).all()
