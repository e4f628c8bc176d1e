"""A stand-in for PBS Pro's ``qsub`` (there is no PBS server here): records its arguments, reads
the script's ``#PBS`` directives and runs the job array's subjobs on this machine, all at once,
as PBS would on free nodes: each with ``PBS_ARRAY_INDEX``, ``NCPUS`` (from ``-l select=1:ncpus=``),
``PBS_JOBID`` set and its output (``-j oe``) in the ``-o`` path with ``^array_index^`` replaced.
Unlike qsub it returns only once every subjob has ended. Usage: ``qsub [options] SCRIPT``;
the record goes to ``$FAKE_QSUB_LOG`` (one JSON line per call)."""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys


def directives(script: str) -> dict[str, str]:
    out: dict[str, str] = {}
    for line in script.splitlines():
        if line.startswith("#PBS "):
            words = shlex.split(line[5:])
            out[words[0]] = " ".join(words[1:])
    return out


def main(argv: list[str]) -> int:
    path = argv[-1]
    with open(path) as fh:
        script = fh.read()
    d = directives(script)
    with open(os.environ["FAKE_QSUB_LOG"], "a") as fh:
        fh.write(json.dumps({"argv": argv, "directives": d}) + "\n")
    m = re.fullmatch(r"(\d+)-(\d+)", d.get("-J", ""))
    indices = range(int(m[1]), int(m[2]) + 1) if m else [None]
    ncpus = re.search(r"ncpus=(\d+)", d.get("-l", ""))
    job = f"{os.getpid()}[].fakepbs" if m else f"{os.getpid()}.fakepbs"
    procs = []
    for k in indices:
        env = {**os.environ, "NCPUS": ncpus[1] if ncpus else "1", "PBS_JOBID": job}
        if k is not None:
            env["PBS_ARRAY_INDEX"] = str(k)
        out = d.get("-o", f"{path}.o").replace("^array_index^", str(k if k is not None else ""))
        with open(out, "w") as log:
            procs.append(subprocess.Popen(["bash", path], stdout=log, stderr=subprocess.STDOUT, env=env))
    codes = [p.wait() for p in procs]
    print(job)
    return 0 if not any(codes) else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
