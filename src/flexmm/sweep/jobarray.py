"""A sweep as a batch system's job array (SLURM, PBS): the job script, and its submission.

Task K of an array of N tasks runs ``flexmm sweep SPEC --shard K/N`` into the one sweep directory
(``flexmm.sweep.shard``), on as many local worker processes as the task has CPUs. The sweep
directory must be on a filesystem every node sees. A task that dies is submitted again and
resumes its shard; the last task to finish writes ``sweep.nc``. Each batch system is an entry of
``SCHEDULERS``: how its directives are written, its array option, the variables holding the task
number and its CPUs, and its submit command.
"""

from __future__ import annotations

import re
import shlex
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from flexmm.errors import UsageError


@dataclass(frozen=True)
class Scheduler:
    """What a batch system needs from the job script and how the script is submitted."""

    name: str
    script: str  # the script's file name under SWEEP_DIR/<name>/
    prefix: str  # a directive line's start, e.g. "#SBATCH"
    directives: Callable[["ArrayJob", Path], list[str]]  # the array, CPUs, name, output (after the prefix)
    task_id: str  # variable holding the task's number (0 … N−1)
    cpus: str  # variable holding the task's CPUs
    submit: tuple[str, ...]  # the submit command (the script's path is appended)
    job_id: Callable[[str], str]  # the job id from the submit command's output

    def command(self) -> str:
        return self.submit[0]


def _slurm(job: "ArrayJob", logs: Path) -> list[str]:
    return [f"--job-name={shlex.quote('flexmm-' + job.name)}", f"--array=0-{job.n_tasks - 1}",
            f"--cpus-per-task={job.cpus_per_task}", "--ntasks=1", f"--output={shlex.quote(str(logs / '%A_%a.out'))}"]


def _word(text: str) -> str:
    """``text`` as one word of a directive: quoted only if it must be (PBS keeps ``^array_index^``)."""
    return text if re.fullmatch(r"[\w@%+=:,./^-]+", text) else shlex.quote(text)


def _pbs(job: "ArrayJob", logs: Path) -> list[str]:
    # PBS Pro: -J needs at least two subjobs (a one-task "array" is a plain job: PBS_ARRAY_INDEX unset)
    array = [f"-J 0-{job.n_tasks - 1}"] if job.n_tasks > 1 else []
    return [f"-N {_word(('flexmm-' + job.name)[:236])}", *array,
            f"-l select=1:ncpus={job.cpus_per_task}", "-j oe", f"-o {_word(str(logs / 'flexmm.^array_index^.out'))}"]


#: the batch systems ``--cluster`` accepts
SCHEDULERS = {
    "slurm": Scheduler("slurm", "sweep.sbatch", "#SBATCH", _slurm, "SLURM_ARRAY_TASK_ID", "SLURM_CPUS_PER_TASK",
                       ("sbatch", "--parsable"), lambda out: out.strip().split(";")[0]),
    "pbs": Scheduler("pbs", "sweep.pbs", "#PBS", _pbs, "PBS_ARRAY_INDEX", "NCPUS",
                     ("qsub",), lambda out: out.strip()),
}


def scheduler(name: str) -> Scheduler:
    """The entry of ``SCHEDULERS`` named ``name``; UsageError listing the valid names otherwise."""
    if name not in SCHEDULERS:
        raise UsageError(f"--cluster {name!r}: expected one of {', '.join(SCHEDULERS)} (for another batch "
                         "system, run a dask-jobqueue cluster and give --scheduler: docs/sweeps.md)")
    return SCHEDULERS[name]


@dataclass(frozen=True)
class ArrayJob:
    """What the job array runs: the ``flexmm sweep`` arguments (spec, --vary, --set, ...), the
    sweep directory, the number of tasks and the CPUs of each, extra directives (after the prefix)."""

    name: str
    sweep_args: tuple[str, ...]
    sweep_dir: Path
    n_tasks: int
    cpus_per_task: int = 1
    options: tuple[str, ...] = ()
    system: str = "slurm"

    @property
    def scheduler(self) -> Scheduler:
        return scheduler(self.system)

    @property
    def logs(self) -> Path:
        """SWEEP_DIR/<system>/: the script and the tasks' output."""
        return self.sweep_dir / self.system


def flexmm_command() -> list[str]:
    """This flexmm as a command a batch job can run (this interpreter, the CLI module)."""
    return [sys.executable, "-c", "from flexmm.cli import main; main()"]


def job_script(job: ArrayJob) -> str:
    """The job array's batch script (the batch system reads its directive lines)."""
    if job.n_tasks < 1:
        raise UsageError(f"--shards {job.n_tasks}: a job array needs at least one task")
    s = job.scheduler
    task = f"${{{s.task_id}:-0}}" if job.n_tasks == 1 else f"${s.task_id}"
    lines = [
        "#!/bin/bash",
        *(f"{s.prefix} {d}" for d in s.directives(job, job.logs)),
        *(f"{s.prefix} {opt}" for opt in job.options),
        "set -euo pipefail",
        "# one numba/BLAS thread per worker process; one worker process per CPU of the task",
        "export NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1",
        " ".join([*map(shlex.quote, flexmm_command()), "sweep", *map(shlex.quote, job.sweep_args),
                  "--out", shlex.quote(str(job.sweep_dir)),
                  f'--shard "{task}/{job.n_tasks}"',
                  f'--workers "${{{s.cpus}:-{job.cpus_per_task}}}"']),
        "",
    ]
    return "\n".join(lines)


def submit(job: ArrayJob, env: dict | None = None) -> tuple[Path, str]:
    """Write the script to SWEEP_DIR/<system>/<script> and submit it: (script, job id)."""
    from flexmm.io.atomic import write_text_atomic

    s = job.scheduler
    command = shutil.which(s.command(), path=(env or {}).get("PATH"))
    if command is None:
        raise UsageError(f"{s.command()} not found: run this on a {s.name.upper()} login node, or print the script "
                         "with --dry-run and submit it there")
    job.logs.mkdir(parents=True, exist_ok=True)
    script = job.logs / s.script
    write_text_atomic(script, job_script(job))
    done = subprocess.run([command, *s.submit[1:], str(script)], capture_output=True, text=True, env=env)
    if done.returncode != 0:
        raise UsageError(f"{s.command()} {script} failed: {done.stderr.strip() or done.stdout.strip()}")
    return script, s.job_id(done.stdout)
