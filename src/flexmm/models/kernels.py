"""Static dispatch from a model's argument type to its compiled kernels.

Every model packs what its kernels read into a NamedTuple of its own (``ChainArgs``,
``SheetArgs``, ...). ``model_force(q, args, out)``, ``model_energy(q, args)`` and
``model_force_parallel(q, args, out)`` are ordinary functions for Python callers and numba
overloads for compiled ones: inside a compiled loop the argument type picks the kernel while
numba types the call, so the loop takes no function argument and numba caches it across
processes like any other kernel (one cache entry per model type). A model is added by giving it
an args NamedTuple and one row in ``KERNELS``; nothing registers itself on import.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from numba.extending import overload

from flexmm._jit import JIT_OPTIONS, NO_JIT
from flexmm.models.harmonic import HarmonicArgs, harmonic_energy, harmonic_force, harmonic_reference
from flexmm.models.hinge import ChainArgs, chain_energy, chain_force, chain_force_parallel, chain_reference
from flexmm.models.ligaments import NetworkArgs, network_energy, network_force, network_reference
from flexmm.models.mass_kernels import MassArgs, mass_energy, mass_force, mass_reference
from flexmm.models.loads import (
    LoadedChainArgs,
    chain_loaded_energy,
    chain_loaded_force,
    chain_loaded_reference,
)
from flexmm.models.sheet_kernels import SheetArgs, sheet_energy, sheet_force, sheet_reference
from flexmm.models.triangle_kernels import TriangleArgs, triangle_energy, triangle_force, triangle_reference


@dataclass(frozen=True)
class ModelKernels:
    """The compiled kernels of one args type, and its numpy reference (the tests' oracle).

    ``force(q, args, out)`` writes −∂E/∂q (ndof,) into ``out``; ``energy(q, args)`` returns E;
    ``parallel`` is ``force`` with threaded loops (None: the serial kernel serves);
    ``reference(q, args) -> (E, F)`` is the readable numpy version.
    """

    force: Callable
    energy: Callable
    reference: Callable
    parallel: Callable | None = None


KERNELS: dict[type, ModelKernels] = {
    ChainArgs: ModelKernels(chain_force, chain_energy, chain_reference, chain_force_parallel),
    LoadedChainArgs: ModelKernels(chain_loaded_force, chain_loaded_energy, chain_loaded_reference),
    SheetArgs: ModelKernels(sheet_force, sheet_energy, sheet_reference),
    MassArgs: ModelKernels(mass_force, mass_energy, mass_reference),
    HarmonicArgs: ModelKernels(harmonic_force, harmonic_energy, harmonic_reference),
    TriangleArgs: ModelKernels(triangle_force, triangle_energy, triangle_reference),
    NetworkArgs: ModelKernels(network_force, network_energy, network_reference),
}


def kernels_of(args_type: type) -> ModelKernels:
    """The kernels for an args type (a clear error for a type no model declared)."""
    try:
        return KERNELS[args_type]
    except KeyError:
        known = ", ".join(k.__name__ for k in KERNELS)
        raise TypeError(f"no model kernels for arguments of type {args_type.__name__} "
                        f"(known: {known})") from None


def model_force(q, args, out):
    """−∂E/∂q of the model whose arguments are ``args`` into ``out`` (ndof,)."""
    kernels_of(type(args)).force(q, args, out)


def model_energy(q, args):
    """Potential energy of the model whose arguments are ``args``."""
    return kernels_of(type(args)).energy(q, args)


def model_force_parallel(q, args, out):
    """``model_force`` with the model's threaded kernel where it has one."""
    k = kernels_of(type(args))
    (k.parallel or k.force)(q, args, out)


def _instance_class(args):
    cls = getattr(args, "instance_class", None)
    if cls is None:
        raise TypeError(f"model arguments must be a NamedTuple declared in KERNELS, got {args}")
    return cls


if not NO_JIT:

    @overload(model_force, jit_options=JIT_OPTIONS)
    def _model_force(q, args, out):
        kernel = kernels_of(_instance_class(args)).force

        def impl(q, args, out):
            kernel(q, args, out)

        return impl

    @overload(model_energy, jit_options=JIT_OPTIONS)
    def _model_energy(q, args):
        kernel = kernels_of(_instance_class(args)).energy

        def impl(q, args):
            return kernel(q, args)

        return impl

    @overload(model_force_parallel, jit_options=JIT_OPTIONS)
    def _model_force_parallel(q, args, out):
        k = kernels_of(_instance_class(args))
        kernel = k.parallel or k.force

        def impl(q, args, out):
            kernel(q, args, out)

        return impl
