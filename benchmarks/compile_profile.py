"""Where the test suite's numba compile time goes: each compile, its function, signature and test.

    python benchmarks/compile_profile.py [pytest args ...]      # run pytest, record, print the top costs
    python benchmarks/compile_profile.py --report FILE.json     # print the top costs of a recorded run
    PYTHONPATH=benchmarks pytest -p compile_profile -n 2 ...    # as a plugin: one record per xdist worker
    python benchmarks/compile_profile.py --workers FILE.json    # merge them: what each worker compiled, and
                                                                # what both compiled (duplicated work)

Runs pytest in this process (pass ``-p no:xdist``; CPU time of subprocesses is not counted)
with a listener on numba's ``numba:compile`` event, so each compilation of a kernel for a new
argument-type signature (a cache miss) is recorded with its wall and CPU seconds, inclusive and exclusive of the compilations it set off
(an integrator loop compiles the kernels it calls), and the test that paid for it. Loads from the
numba cache are not compilations; their CPU time is summed per test (a warm run's cost). Use an
empty ``NUMBA_CACHE_DIR`` to see what a fresh clone pays. The record is written to ``$COMPILE_PROFILE_OUT``
(default ``compile_profile.json``) and summarised: the top compilations by exclusive CPU time,
the functions with the most signatures, and compile CPU time per test file and per test.
"""

from __future__ import annotations

import json
import os
import sys
import time
from collections import defaultdict

TOP = int(os.environ.get("COMPILE_PROFILE_TOP", "40"))


class _Recorder:
    """Collects one row per ``numba:compile`` event (exclusive times via a stack of open events)."""

    def __init__(self):
        self.rows: list[dict] = []
        self.stack: list[list] = []
        self.test = "(collection)"
        self.loads: dict[str, float] = defaultdict(float)  # CPU-s loading from numba's cache, per test
        self.loaded: list[list] = []  # [function, signature, test] of each signature loaded from the cache

    def on_start(self, data) -> None:
        self.stack.append([time.perf_counter(), time.process_time(), 0.0, 0.0, data])

    def on_end(self, data) -> None:
        w0, c0, child_w, child_c, data = self.stack.pop()
        wall, cpu = time.perf_counter() - w0, time.process_time() - c0
        if self.stack:
            self.stack[-1][2] += wall
            self.stack[-1][3] += cpu
        disp = data["dispatcher"]
        fn = disp.py_func
        self.rows.append({
            "function": f"{fn.__module__}.{fn.__qualname__}",
            "signature": ", ".join(str(a) for a in data["args"]),
            "test": self.test,
            "wall_s": wall, "cpu_s": cpu, "self_wall_s": wall - child_w, "self_cpu_s": cpu - child_c,
            "depth": len(self.stack),
        })


def _install(rec: _Recorder) -> None:
    from numba.core import event

    class Listener(event.Listener):
        def on_start(self, ev):
            rec.on_start(ev.data)

        def on_end(self, ev):
            rec.on_end(ev.data)

    event.register("numba:compile", Listener())

    from numba.core import caching

    load = caching.Cache.load_overload

    def timed_load(self, sig, target_context):  # a warm run's cost: loading compiled code
        c0 = time.process_time()
        try:
            cres = load(self, sig, target_context)
            if cres is not None:
                fn = self._py_func
                rec.loaded.append([f"{fn.__module__}.{fn.__qualname__}", ", ".join(str(a) for a in sig), rec.test])
            return cres
        finally:
            rec.loads[rec.test] += time.process_time() - c0

    caching.Cache.load_overload = timed_load


class _Plugin:
    """pytest plugin: names the running test for the recorder."""

    def __init__(self, rec: _Recorder, dump):
        self.rec = rec
        self.test_cpu: dict[str, float] = {}
        self.dump, self.dumped = dump, time.perf_counter()

    def pytest_runtest_protocol(self, item, nextitem):
        self.rec.test = item.nodeid
        self._c0 = time.process_time()

    def pytest_runtest_logfinish(self, nodeid, location):
        self.test_cpu[nodeid] = time.process_time() - self._c0
        if time.perf_counter() - self.dumped > 30.0:  # a partial record while the run goes on
            self.dump()
            self.dumped = time.perf_counter()


def _short(sig: str, n: int = 110) -> str:
    return sig if len(sig) <= n else sig[: n - 3] + "..."


def report(rows: list[dict], test_cpu: dict[str, float], loads: dict[str, float], top: int = TOP) -> None:
    """Print the summary of recorded compile rows, cache loads and the CPU time of each test."""
    total = sum(r["self_cpu_s"] for r in rows)
    print(f"\n{len(rows)} compilations, {total:.0f} CPU-s "
          f"(wall {sum(r['self_wall_s'] for r in rows):.0f} s, exclusive of nested ones)")
    print(f"\n-- top {top} compilations by exclusive CPU-s (inclusive in brackets)")
    for r in sorted(rows, key=lambda r: -r["self_cpu_s"])[:top]:
        print(f"{r['self_cpu_s']:7.1f} [{r['cpu_s']:6.1f}] {r['function']}\n"
              f"          ({_short(r['signature'])})  <- {r['test']}")
    by_fn: dict[str, list] = defaultdict(lambda: [0, 0.0])
    for r in rows:
        by_fn[r["function"]][0] += 1
        by_fn[r["function"]][1] += r["self_cpu_s"]
    print(f"\n-- top {top} functions by exclusive CPU-s over all their signatures (count)")
    for name, (n, c) in sorted(by_fn.items(), key=lambda kv: -kv[1][1])[:top]:
        print(f"{c:7.1f}  {n:3d}  {name}")
    by_file: dict[str, float] = defaultdict(float)
    by_test: dict[str, float] = defaultdict(float)
    for r in rows:
        by_file[r["test"].split("::")[0]] += r["self_cpu_s"]
        by_test[r["test"]] += r["self_cpu_s"]
    file_cpu: dict[str, float] = defaultdict(float)
    for name, c in test_cpu.items():
        file_cpu[name.split("::")[0]] += c
    file_load: dict[str, float] = defaultdict(float)
    for name, c in loads.items():
        file_load[name.split("::")[0]] += c
    print(f"\n-- CPU-s per test file: all, compiling, loading from the cache "
          f"(totals {sum(test_cpu.values()):.0f}, {total:.0f}, {sum(loads.values()):.0f})")
    for name in sorted(set(by_file) | set(file_cpu), key=lambda n: -max(file_cpu.get(n, 0), by_file.get(n, 0))):
        print(f"{file_cpu.get(name, 0.0):7.1f} {by_file.get(name, 0.0):7.1f} {file_load.get(name, 0.0):7.1f}  {name}")
    print(f"\n-- top {top} tests by compile CPU-s")
    for name, c in sorted(by_test.items(), key=lambda kv: -kv[1])[:top]:
        print(f"{c:7.1f}  {name}")


def pytest_configure(config) -> None:
    """Loaded as a plugin (``-p compile_profile``): record this process (an xdist worker or the
    only one) to ``$COMPILE_PROFILE_OUT.<worker>.json``; the controller of an xdist run records
    nothing (it runs no tests)."""
    if getattr(config.option, "numprocesses", None) and not hasattr(config, "workerinput"):
        return
    worker = getattr(config, "workerinput", {}).get("workerid", "main")
    rec = _Recorder()
    _install(rec)
    c0, w0 = time.process_time(), time.perf_counter()
    out = f"{os.environ.get('COMPILE_PROFILE_OUT', 'compile_profile.json')}.{worker}.json"

    def dump():
        with open(out + ".tmp", "w") as f:
            json.dump({"worker": worker, "cpu_s": time.process_time() - c0, "wall_s": time.perf_counter() - w0,
                       "load": os.getloadavg(), "compilations": rec.rows, "test_cpu_s": plugin.test_cpu,
                       "load_cpu_s": rec.loads, "loaded": rec.loaded}, f)
        os.replace(out + ".tmp", out)

    plugin = _Plugin(rec, dump)
    config.pluginmanager.register(plugin, "compile_profile_recorder")
    config.add_cleanup(dump)


def workers_report(paths: list[str]) -> None:
    """Merge per-worker records: compile CPU-s per worker, and the (function, signature) pairs
    compiled by more than one worker (each paid it because neither found it cached)."""
    recs = []
    for path in paths:
        with open(path) as f:
            recs.append(json.load(f))
    seen: dict[tuple, list] = defaultdict(list)
    for rec in recs:
        c = sum(r["self_cpu_s"] for r in rec["compilations"])
        print(f"{rec['worker']}: {len(rec['compilations'])} compilations, {c:.0f} compile CPU-s of "
              f"{rec['cpu_s']:.0f} CPU-s, {rec['wall_s']:.0f} s wall")
        for r in rec["compilations"]:
            seen[(r["function"], r["signature"])].append((rec["worker"], r["self_cpu_s"], r["test"]))
    dup = {k: v for k, v in seen.items() if len({w for w, _, _ in v}) > 1}
    extra = sum(sum(c for _, c, _ in v) - max(c for _, c, _ in v) for v in dup.values())
    print(f"\n{len(dup)} signatures compiled in more than one worker: {extra:.0f} CPU-s paid twice")
    for (fn, sig), v in sorted(dup.items(), key=lambda kv: -sum(c for _, c, _ in kv[1]))[:TOP]:
        print(f"{sum(c for _, c, _ in v):7.1f}  {fn} ({_short(sig, 60)})")
        for w, c, t in v:
            print(f"           {w} {c:6.1f}  <- {t}")
    rows = [r for rec in recs for r in rec["compilations"]]
    test_cpu = {k: v for rec in recs for k, v in rec["test_cpu_s"].items()}
    loads = {k: v for rec in recs for k, v in rec.get("load_cpu_s", {}).items()}
    report(rows, test_cpu, loads)


def main(argv: list[str]) -> int:
    if argv[:1] == ["--workers"]:
        workers_report(argv[1:])
        return 0
    if argv[:1] == ["--report"]:
        with open(argv[1]) as f:
            rec = json.load(f)
        report(rec["compilations"], rec["test_cpu_s"], rec.get("load_cpu_s", {}))
        return 0
    import pytest

    rec = _Recorder()
    _install(rec)
    c0, w0 = time.process_time(), time.perf_counter()
    out = os.environ.get("COMPILE_PROFILE_OUT", "compile_profile.json")

    def dump():
        with open(out + ".tmp", "w") as f:
            json.dump({"argv": argv, "cpu_s": time.process_time() - c0, "wall_s": time.perf_counter() - w0,
                       "load": os.getloadavg(), "compilations": rec.rows, "test_cpu_s": plugin.test_cpu,
                       "load_cpu_s": rec.loads}, f)
        os.replace(out + ".tmp", out)

    plugin = _Plugin(rec, dump)
    code = pytest.main(argv, plugins=[plugin])
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    dump()
    report(rec.rows, plugin.test_cpu, rec.loads)
    print(f"\npytest: {cpu:.0f} CPU-s, {wall:.0f} s wall, load {os.getloadavg()[0]:.1f}; record in {out}")
    return int(code)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
