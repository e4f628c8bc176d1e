"""The single numba wrapper every compiled kernel goes through, and where its cache lives.

All numba flags live here: ``cache=True``, a fastmath subset that keeps NaN/inf checks
working (no ``nnan``/``ninf``), and ``FLEXMM_NO_JIT=1`` in the environment to run every
kernel as plain Python for debugging.

No reassociation and no contraction into fused multiply-adds by the optimiser: with them, a
kernel inlined into a stepper compiled in the same process (a cold numba cache) and the same
kernel loaded from the cache were optimised differently, and the same config gave results
differing in the last bits (≈ 1e-15) depending on the cache state. Without them the operations
keep their written order and rounding everywhere. Fused multiply-adds are written out instead
(``fma``): each is one ``llvm.fma`` (one rounding) where the compile target has FMA, or a
multiply then an add (two roundings) where it has not, whatever the optimiser does around it,
so a kernel's bits depend on the machine, never on the cache state.

Compiled once per machine. No kernel takes another compiled function as an argument (models
are reached through ``flexmm.models.kernels``, dispatched on the type of their arguments), so
every kernel, integrator loops included, is cached across processes. The cache directory is

1. ``$NUMBA_CACHE_DIR`` when set (numba's own variable; flexmm only checks it is writable);
2. otherwise ``$XDG_CACHE_HOME/flexmm/numba/<key>`` (``~/.cache/flexmm/numba/<key>``), where
   ``<key>`` hashes flexmm's version, the kernel sources and the numba version — numba checks
   only the timestamp of a cached function's own file, not of the kernels it inlined, so a
   key per source state keeps a changed hinge law from being served from a stale integrator.
   keys unused for a week are removed (``prune_cache``);
3. if that cannot be written, a per-user directory under the system's temporary directory, with
   a warning; if nothing is writable, caching is off (every process compiles) and a warning
   says so.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import sys
import tempfile
import time
import warnings
from pathlib import Path

import llvmlite.binding
import numba
from numba.core import types
from numba.extending import intrinsic, overload

NO_JIT = os.environ.get("FLEXMM_NO_JIT", "0") == "1"

#: LLVM's loop vectoriser gives up on a loop whose arrays need more run-time overlap checks than
#: this (numba cannot declare arrays non-aliasing); the default stops loops over ~10 arrays,
#: such as a uniform chain's fused reverse passes (design/kernels.py), from vectorising.
#: Process-wide, set before anything compiles; elementwise loops give the same bits either way.
VECTORIZE_MEMORY_CHECKS = 256
if not NO_JIT:
    llvmlite.binding.set_option("flexmm", f"-vectorize-memory-check-threshold={VECTORIZE_MEMORY_CHECKS}")

# NaN/inf semantics are kept so blow-ups are seen; see the module docstring for reassoc/contract.
FASTMATH = frozenset({"nsz", "arcp", "afn"})

#: numba options of every kernel (``jit`` adds ``parallel`` where asked)
JIT_OPTIONS = {
    "fastmath": set(FASTMATH), "nogil": True, "error_model": "numpy", "boundscheck": False,
}

prange = range if NO_JIT else numba.prange


def _target_has_fma() -> bool:
    """Whether numba compiles for a CPU with fused multiply-add instructions (the host, unless
    NUMBA_CPU_NAME / NUMBA_CPU_FEATURES say otherwise: a generic target gets none)."""
    features = numba.config.CPU_FEATURES
    if features:
        return "+fma" in features.split(",")
    if numba.config.CPU_NAME not in (None, "", "host"):
        return False
    return bool(llvmlite.binding.get_host_cpu_features().get("fma", False))


#: ``fma`` is one fused instruction (else a multiply and an add: never a slow library call)
HAS_FMA = not NO_JIT and _target_has_fma()


def fma(a, b, c):
    """a·b + c in compiled kernels: rounded once (``llvm.fma``, vectorises to vfmadd) where the
    target has FMA, else a·b then + c; the same in every compiled kernel and cache state.
    In Python (``FLEXMM_NO_JIT``) a·b + c, rounded twice."""
    return a * b + c


if not NO_JIT:

    @intrinsic
    def _fma(typingctx, a, b, c):
        if not all(isinstance(x, (types.Float, types.Integer)) for x in (a, b, c)):
            return None
        sig = types.float64(a, b, c)

        def codegen(context, builder, signature, args):
            x, y, z = (context.cast(builder, v, t, types.float64) for v, t in zip(args, signature.args))
            if HAS_FMA:
                return builder.fma(x, y, z)
            return builder.fadd(builder.fmul(x, y), z)

        return sig, codegen

    @overload(fma, jit_options=JIT_OPTIONS)
    def _fma_overload(a, b, c):
        return lambda a, b, c: _fma(a, b, c)

_PACKAGE = Path(__file__).resolve().parent
#: packages and modules whose source is compiled (their text keys the cache directory)
_KERNEL_SOURCES = ("_jit.py", "_trig.py", "stability.py", "models", "integrators",
                   "design/kernels.py", "design/kernels_extra.py", "design/terms.py", "design/sweeps.py",
                   "design/splitting.py", "design/midpoint.py")
#: cache directories of other source states are removed once unused this long
PRUNE_AGE_S = 7 * 86400.0


def source_key() -> str:
    """A short hash of flexmm's compiled sources, its version and numba's version."""
    h = hashlib.sha256()
    h.update(numba.__version__.encode())
    h.update(sys.version.encode())
    for name in _KERNEL_SOURCES:
        path = _PACKAGE / name
        files = sorted(path.rglob("*.py")) if path.is_dir() else [path]
        for f in files:
            if f.exists():
                h.update(f.relative_to(_PACKAGE).as_posix().encode())
                h.update(f.read_bytes())
    return h.hexdigest()[:16]


def _writable(path: Path) -> bool:
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path, prefix=".probe"):
            pass
        return True
    except OSError:
        return False


def _user_cache_root() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "flexmm" / "numba"


def prune_cache(root: Path, keep: str, max_age_s: float = PRUNE_AGE_S) -> None:
    """Remove cache directories of other source states under ``root`` unused for ``max_age_s``.

    The kept directory's time stamp is refreshed at each start, so a directory another
    installation still uses survives (best effort: errors are ignored).
    """
    now = time.time()
    try:
        os.utime(root / keep)
        for d in root.iterdir():
            if d.is_dir() and d.name != keep and now - d.stat().st_mtime > max_age_s:
                shutil.rmtree(d, ignore_errors=True)
    except OSError:
        pass


def _choose_cache_dir() -> tuple[Path | None, str]:
    """(cache directory or None when caching is off, a note when it is not the usual one)."""
    env = os.environ.get("NUMBA_CACHE_DIR")
    if env:
        if _writable(Path(env)):
            return Path(env), ""
        note = f"NUMBA_CACHE_DIR={env} is not writable"
    else:
        key = source_key()
        root = _user_cache_root()
        if _writable(root / key):
            prune_cache(root, key)
            return root / key, ""
        note = f"{root} is not writable"
        env = None
    uid = os.getuid() if hasattr(os, "getuid") else "user"
    fallback = Path(tempfile.gettempdir()) / f"flexmm-numba-{uid}" / source_key()
    if _writable(fallback):
        return fallback, f"{note}; compiled kernels are cached in {fallback} instead"
    return None, (f"{note} and neither is {fallback}: compiled kernels are not cached, so every "
                  "process compiles them again (set NUMBA_CACHE_DIR to a writable directory)")


CACHE_DIR, CACHE_NOTE = (None, "") if NO_JIT else _choose_cache_dir()
if CACHE_DIR is not None:
    numba.config.CACHE_DIR = str(CACHE_DIR)  # read when each kernel below enables caching
if CACHE_NOTE:
    warnings.warn(f"flexmm: {CACHE_NOTE}", RuntimeWarning, stacklevel=2)


def jit(fn=None, *, parallel: bool = False, inline: bool = False):
    """Compile ``fn`` with flexmm's numba settings (or return it untouched if NO_JIT). ``inline``:
    copied into every compiled caller (numba's IR inlining), so that arguments the caller passes
    as constants are constants of the copy (a law chosen outside a loop is folded inside it)."""

    def wrap(f):
        if NO_JIT:
            return f
        return numba.njit(f, cache=CACHE_DIR is not None, parallel=parallel, inline="always" if inline else "never",
                          **JIT_OPTIONS)

    return wrap if fn is None else wrap(fn)
