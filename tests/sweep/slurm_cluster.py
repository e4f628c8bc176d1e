"""A real single-node SLURM cluster for the tests: munged, slurmctld and slurmd from Debian's
slurm-wlm, started in a temporary directory with a generated minimal slurm.conf.

Nothing system-wide is touched: munged gets its own key and socket, the daemons their own ports
(free ones, so parallel test sessions do not collide), spool, state and log files, and the
client commands find the cluster through ``SLURM_CONF`` (``SlurmCluster.env``). The daemons run
as the current user, which must be root (slurmd starts jobs as their submitting user).
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

DAEMONS = ("munged", "mungekey", "slurmctld", "slurmd", "sbatch", "squeue", "sinfo")


def missing() -> str | None:
    """Why a SLURM cluster cannot be started here (None if it can)."""
    if os.geteuid() != 0:
        return "a test SLURM cluster needs root (slurmd runs jobs as their submitting user)"
    absent = [d for d in DAEMONS if not shutil.which(d, path=os.environ.get("PATH", "") + ":/usr/sbin:/sbin")]
    if absent:
        return f"SLURM is not installed ({', '.join(absent)} missing): apt-get install slurm-wlm munge"
    return None


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _which(name: str) -> str:
    return shutil.which(name, path=os.environ.get("PATH", "") + ":/usr/sbin:/sbin") or name


@dataclass
class SlurmCluster:
    """A started cluster: its directory, the environment its clients need, its daemons."""

    root: Path
    cpus: int
    procs: list[subprocess.Popen] = field(default_factory=list)

    @property
    def conf(self) -> Path:
        return self.root / "slurm.conf"

    @property
    def env(self) -> dict[str, str]:
        return {**os.environ, "SLURM_CONF": str(self.conf)}

    def run(self, *cmd: str, timeout: float = 60) -> subprocess.CompletedProcess:
        return subprocess.run([_which(cmd[0]), *cmd[1:]], env=self.env, capture_output=True, text=True,
                              timeout=timeout)

    def logs(self) -> str:
        return "\n".join(f"--- {p.name}\n{p.read_text(errors='replace')[-3000:]}"
                         for p in sorted(self.root.glob("*.log")))

    def wait_idle(self, timeout: float = 60) -> None:
        """Until the node is up and idle (slurmd registered)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            out = self.run("sinfo", "-h", "-o", "%T").stdout.split()
            if out and all(s.rstrip("*") == "idle" for s in out):
                return
            time.sleep(0.3)
        raise RuntimeError(f"the SLURM node did not come up within {timeout:g} s\n{self.logs()}")

    def wait_jobs(self, job: str, timeout: float = 600) -> None:
        """Until no task of job ``job`` is queued or running."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if not self.run("squeue", "-h", "-j", job).stdout.strip():
                return
            time.sleep(0.5)
        raise RuntimeError(f"SLURM job {job} still queued or running after {timeout:g} s\n{self.logs()}")

    def stop(self) -> None:
        for proc in reversed(self.procs):
            proc.terminate()
        for proc in reversed(self.procs):
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def slurm_conf(root: Path, cpus: int, munge_socket: Path) -> str:
    """A minimal slurm.conf: one node (this host) with ``cpus`` CPUs, one partition, CPUs
    allocated one by one (so array tasks share the node), no cgroups, no accounting."""
    host = socket.gethostname()
    return "\n".join([
        "ClusterName=flexmmtest",
        f"SlurmctldHost={host}(127.0.0.1)",
        f"SlurmctldPort={_free_port()}",
        f"SlurmdPort={_free_port()}",
        "SlurmUser=root",
        "SlurmdUser=root",
        "AuthType=auth/munge",
        "CredType=cred/munge",
        f"AuthInfo=socket={munge_socket}",
        f"StateSaveLocation={root / 'state'}",
        f"SlurmdSpoolDir={root / 'spool'}",
        f"SlurmctldPidFile={root / 'slurmctld.pid'}",
        f"SlurmdPidFile={root / 'slurmd.pid'}",
        f"SlurmctldLogFile={root / 'slurmctld.log'}",
        f"SlurmdLogFile={root / 'slurmd.log'}",
        "ProctrackType=proctrack/linuxproc",
        "TaskPlugin=task/none",
        "JobAcctGatherType=jobacct_gather/none",
        "AccountingStorageType=accounting_storage/none",
        "JobCompType=jobcomp/none",
        "MpiDefault=none",
        "SwitchType=switch/none",
        "SchedulerType=sched/builtin",
        "SelectType=select/cons_tres",
        "SelectTypeParameters=CR_CPU",
        "ReturnToService=2",
        "SlurmdParameters=config_overrides",
        "SlurmctldTimeout=30",
        "SlurmdTimeout=30",
        "InactiveLimit=0",
        "MinJobAge=2",
        "KillWait=5",
        f"NodeName={host} NodeAddr=127.0.0.1 CPUs={cpus} State=UNKNOWN",
        f"PartitionName=test Nodes={host} Default=YES MaxTime=INFINITE State=UP OverSubscribe=NO",
        "",
    ])


def start(root: Path, cpus: int = 2) -> SlurmCluster:
    """Start munged, slurmctld and slurmd under ``root``; the cluster once its node is idle."""
    root.mkdir(parents=True, exist_ok=True)
    os.chmod(root, 0o700)  # munged wants its key and socket directory private
    for d in ("state", "spool"):
        (root / d).mkdir(exist_ok=True)
    key, sock = root / "munge.key", root / "munge.socket"
    subprocess.run([_which("mungekey"), "--create", "--keyfile", str(key), "--force"], check=True,
                   capture_output=True)
    os.chmod(key, 0o400)
    cluster = SlurmCluster(root, cpus)
    cluster.conf.write_text(slurm_conf(root, cpus, sock))
    try:
        cluster.procs.append(subprocess.Popen(
            [_which("munged"), "--foreground", "--force", f"--key-file={key}", f"--socket={sock}",
             f"--pid-file={root / 'munged.pid'}", f"--log-file={root / 'munged.log'}",
             f"--seed-file={root / 'munged.seed'}"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        deadline = time.monotonic() + 20
        while not sock.exists():
            if cluster.procs[0].poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"munged did not start\n{cluster.logs()}")
            time.sleep(0.05)
        for daemon in ("slurmctld", "slurmd"):
            cluster.procs.append(subprocess.Popen([_which(daemon), "-D", "-f", str(cluster.conf)], env=cluster.env,
                                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
            time.sleep(0.5)
            if cluster.procs[-1].poll() is not None:
                raise RuntimeError(f"{daemon} exited at start-up\n{cluster.logs()}")
        cluster.wait_idle()
    except BaseException:
        cluster.stop()
        raise
    return cluster
