"""A sweep as a SLURM job array: the batch script, and its submission with ``sbatch``.

Task ``$SLURM_ARRAY_TASK_ID`` of an array of N tasks runs ``flexmm sweep SPEC --shard
$SLURM_ARRAY_TASK_ID/N`` into the one sweep directory (``flexmm.sweep.shard``), on as many
local worker processes as the task has CPUs (``--cpus-per-task``). The sweep directory must be
on a filesystem every node sees. A task that dies is rerun (``sbatch`` again, or ``scontrol
requeue``) and resumes its shard; the last task to finish writes ``sweep.nc``.
"""

from __future__ import annotations

import shlex
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from flexmm.errors import UsageError

SCRIPT = "sweep.sbatch"


@dataclass(frozen=True)
class ArrayJob:
    """What the job array runs: the ``flexmm sweep`` arguments (spec, --vary, --set, ...),
    the sweep directory, the number of tasks and the CPUs of each, extra ``#SBATCH`` options."""

    name: str
    sweep_args: tuple[str, ...]
    sweep_dir: Path
    n_tasks: int
    cpus_per_task: int = 1
    sbatch_options: tuple[str, ...] = ()


def flexmm_command() -> list[str]:
    """This flexmm as a command a batch job can run (this interpreter, the CLI module)."""
    return [sys.executable, "-c", "from flexmm.cli import main; main()"]


def job_script(job: ArrayJob) -> str:
    """The job array's batch script (``sbatch`` reads the ``#SBATCH`` lines)."""
    if job.n_tasks < 1:
        raise UsageError(f"--shards {job.n_tasks}: a job array needs at least one task")
    logs = job.sweep_dir / "slurm"
    lines = [
        "#!/bin/bash",
        f"#SBATCH --job-name={shlex.quote('flexmm-' + job.name)}",
        f"#SBATCH --array=0-{job.n_tasks - 1}",
        f"#SBATCH --cpus-per-task={job.cpus_per_task}",
        "#SBATCH --ntasks=1",
        f"#SBATCH --output={shlex.quote(str(logs / '%A_%a.out'))}",
        *(f"#SBATCH {opt}" for opt in job.sbatch_options),
        "set -euo pipefail",
        "# one numba/BLAS thread per worker process; one worker process per CPU of the task",
        "export NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1",
        " ".join([*map(shlex.quote, flexmm_command()), "sweep", *map(shlex.quote, job.sweep_args),
                  "--out", shlex.quote(str(job.sweep_dir)),
                  f'--shard "$SLURM_ARRAY_TASK_ID/{job.n_tasks}"',
                  '--workers "${SLURM_CPUS_PER_TASK:-1}"']),
        "",
    ]
    return "\n".join(lines)


def submit(job: ArrayJob, env: dict | None = None) -> tuple[Path, str]:
    """Write the script to SWEEP_DIR/slurm/sweep.sbatch and ``sbatch`` it: (script, job id)."""
    from flexmm.io.atomic import write_text_atomic

    sbatch = shutil.which("sbatch")
    if sbatch is None:
        raise UsageError("sbatch not found: run this on a SLURM login node, or print the script with "
                         "--dry-run and submit it there")
    (job.sweep_dir / "slurm").mkdir(parents=True, exist_ok=True)
    script = job.sweep_dir / "slurm" / SCRIPT
    write_text_atomic(script, job_script(job))
    done = subprocess.run([sbatch, "--parsable", str(script)], capture_output=True, text=True, env=env)
    if done.returncode != 0:
        raise UsageError(f"sbatch {script} failed: {done.stderr.strip() or done.stdout.strip()}")
    return script, done.stdout.strip().split(";")[0]
