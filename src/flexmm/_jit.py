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
2. otherwise one directory per module, ``$XDG_CACHE_HOME/flexmm/numba/<module>-<key>``
   (``~/.cache/flexmm/numba/…``), where ``<key>`` hashes the sources of the module and of every
   flexmm module it imports, directly or not, and numba's and Python's versions
   (``module_key``) — numba checks only the timestamp of a cached function's own file, not of
   the kernels it inlined, so the key keeps a changed hinge law from being served from a stale
   integrator, and a change recompiles only the modules that import the changed one; every
   checkout or installation of the same sources shares these directories (``_ModuleDirLocator``).
   A module's other versions unused for a week are removed when it is used (``prune_cache``);
   processes sharing a cache compile a function one at a time (a lock file beside its cache),
   so a kernel that one is compiling is loaded, not compiled again, by the others
   (``_one_compile_at_a_time``);
3. if that cannot be written, a per-user directory under the system's temporary directory, with
   a warning; if nothing is writable, caching is off (every process compiles) and a warning
   says so.
"""

from __future__ import annotations

import ast
import errno
import hashlib
import os
import re
import shutil
import sys
import tempfile
import time
import warnings

try:
    import fcntl
except ImportError:  # not POSIX: processes compile without waiting for each other
    fcntl = None
from pathlib import Path

import llvmlite.binding
import numba
from numba.core import caching, sigutils, types
from numba.core.compiler_lock import global_compiler_lock
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


def runtime(x):
    """``x`` as a run-time value in compiled code: numba types a constant argument (``True``, ``0``)
    as a literal and compiles the called function once per constant; through ``runtime`` the
    callee compiles once for the type (for arguments that only steer a branch or an offset)."""
    return x


if not NO_JIT:

    @intrinsic
    def _runtime(typingctx, x):
        t = types.unliteral(x)

        def codegen(context, builder, signature, args):
            return context.cast(builder, args[0], signature.args[0], t)

        return t(x), codegen

    @overload(runtime, inline="always", jit_options=JIT_OPTIONS)
    def _runtime_overload(x):
        return lambda x: _runtime(x)

_PACKAGE = Path(__file__).resolve().parent
#: cache directories unused this long are removed
PRUNE_AGE_S = 7 * 86400.0


def _module_path(module: str) -> Path | None:
    """The source file of module ``module`` (a flexmm module, or one already imported), else None."""
    parts = module.split(".")
    if parts[0] == "flexmm":
        base = _PACKAGE.joinpath(*parts[1:])
        for path in (base.with_suffix(".py"), base / "__init__.py"):
            if path.is_file():
                return path
        return None
    file = getattr(sys.modules.get(module), "__file__", None)
    return Path(file) if file and file.endswith(".py") else None


#: an import statement at the start of a line (a parenthesised name list may span lines)
_IMPORT_LINE = re.compile(rb"^[ \t]*(?:from[ \t]+\.*[\w.]*[ \t]+import[ \t]*(?:\([^)]*\)|[^\n]*)|import[ \t]+[^\n]*)",
                          re.MULTILINE)


def _import_statements(source: bytes) -> list:
    """The import statements of ``source`` (parsing only them is ~20 times faster than the whole
    text; a line in a string that reads as an import only adds a dependency)."""
    nodes = []
    for match in _IMPORT_LINE.finditer(source):
        try:
            nodes.extend(ast.parse(match.group(0).strip()).body)
        except SyntaxError:
            pass
    return nodes


def module_imports(module: str, source: bytes, is_package: bool = False) -> set[str]:
    """The flexmm modules that the source of ``module`` imports, at any depth of its text.

    ``from flexmm.p import n`` counts as ``flexmm.p.n`` when that is a module, else as ``flexmm.p``
    (where ``n`` is defined); relative imports are resolved against ``module``.
    """
    found = set()
    package = module if is_package else module.rpartition(".")[0]
    for node in _import_statements(source):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                base = f"{base}.{node.module}" if node.module else base
            else:
                base = node.module or ""
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                found.add(sub if _module_path(sub) is not None else base)
    return {m for m in found if m.split(".")[0] == "flexmm" and _module_path(m) is not None}


_SOURCES: dict[str, tuple[bytes, set[str]]] = {}


def _source_and_imports(module: str) -> tuple[bytes, set[str]]:
    if module not in _SOURCES:
        path = _module_path(module)
        source = path.read_bytes() if path is not None else b""
        _SOURCES[module] = source, module_imports(module, source, path is not None and path.name == "__init__.py")
    return _SOURCES[module]


def module_key(module: str, sources=_source_and_imports) -> str:
    """A short hash of the sources of ``module`` and of every flexmm module it imports, directly or
    through others, with numba's and Python's versions: the key of ``module``'s cache directory.

    A compiled function can call (and inline) only what its module reaches through imports, so
    a changed source changes the keys of the modules that import it, directly or not, and of no
    other. ``sources(name) -> (source bytes, imported module names)`` (tests pass edited texts).
    """
    seen, todo = set(), [module]
    while todo:
        name = todo.pop()
        if name not in seen:
            seen.add(name)
            todo.extend(sources(name)[1])
    h = hashlib.sha256()
    h.update(numba.__version__.encode())
    h.update(sys.version.encode())
    for name in sorted(seen):
        h.update(name.encode() + b"\0" + sources(name)[0] + b"\0")
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


def prune_cache(root: Path, keep=lambda name: False, max_age_s: float = PRUNE_AGE_S) -> None:
    """Remove the directories under ``root`` unused for ``max_age_s`` except those whose name
    ``keep`` accepts (best effort: errors are ignored)."""
    now = time.time()
    try:
        for d in root.iterdir():
            if d.is_dir() and not keep(d.name) and now - d.stat().st_mtime > max_age_s:
                shutil.rmtree(d, ignore_errors=True)
    except OSError:
        pass


def _current_module(name: str) -> bool:
    """Whether ``name`` is a directory name ``<module>-<key>`` of an existing flexmm module (its
    stale versions are pruned when the module is used: ``module_cache_dir``)."""
    module, _, key = name.rpartition("-")
    return len(key) == 16 and module.split(".")[0] == "flexmm" and _module_path(module) is not None


def _choose_cache_dir() -> tuple[Path | None, bool, str]:
    """(cache directory or None when caching is off, whether each module gets a subdirectory
    keyed by its sources there, a note when it is not the usual one)."""
    env = os.environ.get("NUMBA_CACHE_DIR")
    if env:
        if _writable(Path(env)):
            return Path(env), False, ""
        note = f"NUMBA_CACHE_DIR={env} is not writable"
    else:
        root = _user_cache_root()
        if _writable(root):
            prune_cache(root, keep=_current_module)  # old layouts, removed modules
            return root, True, ""
        note = f"{root} is not writable"
    uid = os.getuid() if hasattr(os, "getuid") else "user"
    fallback = Path(tempfile.gettempdir()) / f"flexmm-numba-{uid}"
    if _writable(fallback):
        return fallback, True, f"{note}; compiled kernels are cached in {fallback} instead"
    return None, False, (f"{note} and neither is {fallback}: compiled kernels are not cached, so every "
                         "process compiles them again (set NUMBA_CACHE_DIR to a writable directory)")


CACHE_DIR, CACHE_KEYED, CACHE_NOTE = (None, False, "") if NO_JIT else _choose_cache_dir()
if CACHE_DIR is not None:
    numba.config.CACHE_DIR = str(CACHE_DIR)
if CACHE_NOTE:
    warnings.warn(f"flexmm: {CACHE_NOTE}", RuntimeWarning, stacklevel=2)


_MODULE_DIRS: dict[tuple[Path, str], Path] = {}  # (cache root, module) -> its directory, found once a process


def module_cache_dir(module: str) -> Path | None:
    """Where the compiled functions of ``module`` are cached: ``CACHE_DIR/<module>-<module_key>``
    (its time stamp refreshed), or ``CACHE_DIR`` itself when set by ``NUMBA_CACHE_DIR``.

    Found, refreshed and pruned once per module and process, not once per function: a module
    holds tens of kernels and the cache root hundreds of directories, and listing them for each
    kernel cost ~0.4 s of every ``import flexmm.api``."""
    if CACHE_DIR is None or not CACHE_KEYED:
        return CACHE_DIR
    known = _MODULE_DIRS.get((CACHE_DIR, module))
    if known is not None:
        return known
    name = f"{module}-{module_key(module)}"
    path = CACHE_DIR / name
    try:
        path.mkdir(exist_ok=True)
        os.utime(path)
    except OSError:
        return None
    prune_cache(CACHE_DIR, keep=lambda d: d == name or not d.startswith(f"{module}-"))  # its other versions
    _MODULE_DIRS[CACHE_DIR, module] = path
    return path


class _ModuleDirLocator(getattr(caching, "UserProvidedCacheLocator", None)
                        or caching._UserProvidedCacheLocator):
    """numba's locator for a cache directory of its own, without the subdirectory numba adds per
    source directory path: a module's keyed directory already names the module and the version of
    its sources, so every checkout or installation of the same sources shares its compiled code
    (numba checks a function's own file by a hash of its text, and its signatures in the index)."""

    active = False  # set by ``jit`` while it decorates a function of a keyed module directory

    def __init__(self, py_func, py_file):
        super().__init__(py_func, py_file)
        self._cache_path = numba.config.CACHE_DIR

    @classmethod
    def from_function(cls, py_func, py_file):
        return super().from_function(py_func, py_file) if cls.active else None


_CACHE_IMPL = getattr(caching, "CacheImpl", None) or caching._CacheImpl
_CACHE_IMPL._locator_classes = [_ModuleDirLocator, *_CACHE_IMPL._locator_classes]


#: how long a process waits for another one compiling the same function before compiling it too
COMPILE_WAIT_S = 1800.0
_HELD: set[str] = set()  # the functions this process holds the compile lock of (nested compiles)


def _one_compile_at_a_time(disp, where: Path):
    """Make ``disp`` compile a new signature only while it holds a lock file for its function
    beside its cache, so processes sharing an empty cache (two test workers, a sweep's workers)
    compile each kernel once: the others wait, then load it from the cache. It also keeps two
    processes from rewriting the function's cache index at once (numba reads, extends and writes
    it back, so one process's entry could be lost, or point at the other's code). Locks are per
    function and taken inside numba's own (per-process) compile lock; a function's compile takes
    the locks of the functions it calls, never the reverse, so two processes cannot wait on each
    other."""
    if fcntl is None:
        return
    fn = disp.py_func
    name = f"{fn.__module__}.{fn.__qualname__}:{fn.__code__.co_firstlineno}"
    path = where / f".compile-{hashlib.sha1(name.encode()).hexdigest()[:16]}.lock"
    compile_ = disp.compile

    def compile(sig):
        with global_compiler_lock:
            if name in _HELD or tuple(sigutils.normalize_signature(sig)[0]) in disp.overloads:
                return compile_(sig)
            try:
                fd = os.open(path, os.O_CREAT | os.O_RDWR, 0o666)
            except OSError:
                return compile_(sig)
            try:
                deadline = time.monotonic() + COMPILE_WAIT_S
                while True:
                    try:
                        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                        break
                    except OSError as exc:
                        if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                            return compile_(sig)  # no flock on this filesystem: compile unlocked
                        if time.monotonic() > deadline:  # a stuck holder: compile anyway
                            return compile_(sig)
                        time.sleep(0.05)
                _HELD.add(name)
                try:
                    return compile_(sig)  # loads from the cache what the holder just saved
                finally:
                    _HELD.discard(name)
            finally:
                os.close(fd)  # releases the lock

    compile.lock_path, compile.unlocked = path, compile_
    disp.compile = compile


def jit(fn=None, *, parallel: bool = False, inline: bool = False):
    """Compile ``fn`` with flexmm's numba settings (or return it untouched if NO_JIT). ``inline``:
    copied into every compiled caller (numba's IR inlining), so that arguments the caller passes
    as constants are constants of the copy (a law chosen outside a loop is folded inside it)."""

    def wrap(f):
        if NO_JIT:
            return f
        how = "always" if inline else "never"
        where = module_cache_dir(f.__module__)
        if where is None:
            return numba.njit(f, cache=False, parallel=parallel, inline=how, **JIT_OPTIONS)
        saved, numba.config.CACHE_DIR = numba.config.CACHE_DIR, str(where)  # read by numba right here
        _ModuleDirLocator.active = CACHE_KEYED
        try:
            disp = numba.njit(f, cache=True, parallel=parallel, inline=how, **JIT_OPTIONS)
        finally:
            numba.config.CACHE_DIR = saved
            _ModuleDirLocator.active = False
        _one_compile_at_a_time(disp, where)
        return disp

    return wrap if fn is None else wrap(fn)
