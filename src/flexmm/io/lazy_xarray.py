"""xarray for flexmm's dataset readers, without importing dask before a dask array can exist.

xarray asks, for every array it wraps, whether it is a dask array: the first ``xr.Variable``
of a process imports ``dask`` and ``dask.array`` (and through them ``scipy.fft``) when dask is
installed — ~0.3 s of CPU, a third of what ``flexmm run`` paid for its printed summary of the
demo (issue 37), for a question whose answer is "no" until something imports ``dask.array``
itself. ``xarray()`` returns the module with its two dask checks answered from ``sys.modules``:

- xarray's record of dask (``xarray.namedarray.pycompat._cached_duck_array_modules["dask"]``,
  read by ``array_type`` and ``mod_version``): no array types while ``dask.array`` is not
  imported (no object can be a dask array then), dask's own once it is, the version by
  importing dask when asked;
- ``xarray.namedarray.utils.is_dask_collection`` (asked of every array an index is made from,
  it imports ``dask.base``, ~0.1 s): False while ``dask`` is not imported, dask's answer once it is;
- ``get_dask_scheduler`` of ``xarray.backends.locks`` and ``.writers`` (asked by every
  ``to_netcdf``: it imports ``dask.distributed`` where installed, ~0.27 s of ``flexmm analyze``
  writing analysis.nc): None (no scheduler active) while ``dask`` is not imported.

Both answers are the ones xarray would give. Where xarray has no such record or function
(another version), nothing is changed and xarray imports dask as before.
"""

from __future__ import annotations

import sys


class _DaskWhenImported:
    """xarray's ``DuckArrayModule("dask")``, resolved when dask is in use rather than up front."""

    @property
    def type(self) -> tuple:
        array = sys.modules.get("dask.array")
        return (array.Array,) if array is not None and hasattr(array, "Array") else ()

    def _loaded(self):
        from xarray.namedarray.pycompat import DuckArrayModule

        return DuckArrayModule("dask")

    @property
    def module(self):
        return self._loaded().module

    @property
    def version(self):
        return self._loaded().version

    @property
    def available(self) -> bool:
        return self._loaded().available


def _when_dask_imported(fn, otherwise):
    """``fn`` where dask is imported, else ``otherwise`` (what ``fn`` answers while dask is unused)."""

    def deferred(*args, **kwargs):
        return fn(*args, **kwargs) if "dask" in sys.modules else otherwise

    deferred.deferred = True
    return deferred


#: (module, function, its answer while dask is not imported)
_DEFERRED = (("xarray.namedarray.utils", "is_dask_collection", False),
             ("xarray.backends.locks", "get_dask_scheduler", None),
             ("xarray.backends.writers", "get_dask_scheduler", None))


def xarray():
    """The ``xarray`` module, its dask checks deferred until dask is imported (module docstring)."""
    import xarray as xr

    pycompat = sys.modules.get("xarray.namedarray.pycompat")
    cache = getattr(pycompat, "_cached_duck_array_modules", None)
    if isinstance(cache, dict) and "dask" not in cache and "dask.array" not in sys.modules:
        cache["dask"] = _DaskWhenImported()
    for module, name, otherwise in _DEFERRED:
        fn = getattr(sys.modules.get(module), name, None)
        if callable(fn) and not getattr(fn, "deferred", False):
            setattr(sys.modules[module], name, _when_dask_imported(fn, otherwise))
    return xr


__all__ = ["xarray"]
