"""What makes an output self-describing: resolved config, its hash, versions, git commit."""

from __future__ import annotations

import hashlib
import json
import platform
import subprocess
from functools import lru_cache
from importlib import metadata
from pathlib import Path

import yaml

from flexmm._version import __version__

LIBRARIES = ("numpy", "scipy", "numba", "xarray", "h5netcdf", "h5py", "pydantic")


def resolved_config(scene) -> dict:
    """The scene with every default filled in, as plain JSON-compatible data."""
    return scene.model_dump(mode="json")


def config_text(scene) -> str:
    """The resolved config as YAML text (remembered for the last few scenes: ``_remembered``)."""
    return _remembered(scene, "text", lambda: yaml.safe_dump(resolved_config(scene), sort_keys=False))


def config_hash(scene) -> str:
    """sha256 of the canonical JSON of the resolved config (independent of YAML layout)."""
    def digest() -> str:
        canon = json.dumps(resolved_config(scene), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(canon.encode()).hexdigest()

    return _remembered(scene, "sha256", digest)


def _remembered(scene, what: str, compute) -> str:
    """``compute()`` for ``scene``, reused for the last few scenes asked about: a run asks for its
    source's and its planned scene's text and hash several times, and a frozen scene's never change."""
    recent = _RECENT[0]  # read once: threads may replace it meanwhile
    for known, kind, value in recent:
        if known is scene and kind == what:
            return value
    value = compute()
    _RECENT[0] = ((scene, what, value), *recent[: _N_RECENT - 1])
    return value


_N_RECENT = 8
_RECENT: list = [()]


@lru_cache(maxsize=1)
def git_commit() -> str:
    """Commit of the flexmm source tree ('+dirty' if modified), or 'unknown'."""
    here = Path(__file__).resolve().parent.parent
    try:
        sha = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=here, capture_output=True, text=True, timeout=5
        )
        if sha.returncode != 0:
            return "unknown"
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=here, capture_output=True, text=True, timeout=5,
        )
        return sha.stdout.strip() + ("+dirty" if dirty.stdout.strip() else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


@lru_cache(maxsize=1)
def library_versions() -> str:
    """The versions of the libraries a run depends on (read once per process: a sweep worker
    writes hundreds of points a minute)."""
    parts = [f"python={platform.python_version()}"]
    for lib in LIBRARIES:
        try:
            parts.append(f"{lib}={metadata.version(lib)}")
        except metadata.PackageNotFoundError:
            pass
    return " ".join(parts)


def provenance_attrs(scene) -> dict[str, str]:
    return {
        "config": config_text(scene),
        "config_sha256": config_hash(scene),
        "flexmm_version": __version__,
        "git_commit": git_commit(),
        "libraries": library_versions(),
    }
