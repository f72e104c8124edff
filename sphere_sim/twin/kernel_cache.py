"""Whether numba's on-disk cache already holds machine code for the compiled kernels.

The answer comes from numba's own caches, not from a stamp of ours: for each kernel
(``@numba.njit(cache=True)``) it reads the index file numba itself would read on the kernel's
first call and looks for an entry numba would accept: written by this numba version, for the
source file's current content, for this CPU and this function's bytecode, with its data file
present. Where the cache lives (``__pycache__`` beside the source, numba's user-wide directory
when that is not writable, or ``NUMBA_CACHE_DIR``) is numba's locator's choice in the caller's
own environment, so the answer is about the install location and environment that asks.

A stamp file would go stale whenever numba's cache changes under it (``make clean-cache``, a
numba upgrade, another ``NUMBA_CACHE_DIR``, an edited kernel); this check cannot, since it
reads what numba reads. It uses numba's cache internals (``_cache``, ``_cache_file``,
``_load_index``, ``_index_key``, as of numba 0.68); should they change, every kernel reads as
not cached: a cold start is announced that is not one (test_first_start then fails), never the
reverse.
"""

from __future__ import annotations

import importlib
import os
import pickle
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

# Every module of the package with a cached numba kernel that the twin runs (test_first_start
# reads the sources and checks that each is here or in STUDY_KERNEL_MODULES). The live plant
# integrates by the Rosenbrock W-method; check_fidelity's reference, a replay of a bag recorded
# by Radau, and every study integrate by the compiled Radau.
KERNEL_MODULES = (
    'sphere_sim.model.capacitance',
    'sphere_sim.model.capacitance_rbf',
    'sphere_sim.model.contact_law',
    'sphere_sim.model.dynamics',
    'sphere_sim.model.friction',
    'sphere_sim.model.gaps',
    'sphere_sim.model.rotations',
    'sphere_sim.model.vec3',
    'sphere_sim.integrate.block_lu',
    'sphere_sim.integrate.kernel_replay',
    'sphere_sim.integrate.newton_system',
    'sphere_sim.integrate.radau_compiled',
    'sphere_sim.integrate.rosenbrock_compiled',
)
# Modules whose cached kernels only a benchmark calls: compiled on their first use there, not
# ahead of a node's start, which never runs them (none at present).
STUDY_KERNEL_MODULES: tuple[str, ...] = ()


def kernel_name(dispatcher: Any) -> str:
    """``module.function`` of a numba dispatcher."""
    return f'{dispatcher.py_func.__module__}.{dispatcher.py_func.__qualname__}'


def cached_kernels(modules: Iterable[str] = KERNEL_MODULES) -> list[Any]:
    """The numba dispatchers of ``modules`` that numba compiles and caches on their own.

    A kernel marked ``inline='always'`` is compiled into its callers only and never has
    machine code of its own, so it is left out.
    """
    from numba.core.dispatcher import Dispatcher

    found: dict[str, Any] = {}
    for module_name in modules:
        module = importlib.import_module(module_name)
        for value in vars(module).values():
            if (isinstance(value, Dispatcher) and value.py_func.__module__ == module_name
                    and value.targetoptions.get('inline', 'never') != 'always'
                    and _cache_of(value) is not None):
                found[kernel_name(value)] = value
    return [found[name] for name in sorted(found)]


def _cache_of(dispatcher: Any) -> Any:
    """numba's on-disk cache of ``dispatcher``, or None (not ``cache=True``)."""
    from numba.core.caching import Cache

    cache = getattr(dispatcher, '_cache', None)
    return cache if isinstance(cache, Cache) else None


def has_machine_code(dispatcher: Any) -> bool:
    """Whether numba would load ``dispatcher`` from its on-disk cache instead of compiling it.

    True when the kernel's index holds an entry numba accepts now (see the module's
    docstring) and the entry's data file exists; any signature counts, since the workloads of
    :mod:`sphere_sim.twin.precompile` call each kernel with the types the twin uses.
    """
    cache = _cache_of(dispatcher)
    if cache is None:
        return False
    try:
        # The same index numba reads on a first call: {} when it is missing, from another
        # numba version, or for another content of the source file.
        overloads = cache._cache_file._load_index()
        if not overloads:
            return False
        # (signature, CPU and codegen, bytecode hashes): everything but the signature must
        # match for numba to load an entry.
        _, machine, code = cache._index_key(None, dispatcher.targetctx.codegen())
        return any(key[1:] == (machine, code)
                   and os.path.isfile(os.path.join(cache.cache_path, data_name))
                   for key, data_name in overloads.items())
    except (AttributeError, TypeError, ValueError, OSError, EOFError, pickle.UnpicklingError):
        # numba's internals moved, or an index is corrupt: numba would compile; so say we.
        return False


def missing_kernels(dispatchers: Sequence[Any]) -> list[str]:
    """Names of the ``dispatchers`` without machine code in numba's cache."""
    return [kernel_name(d) for d in dispatchers if not has_machine_code(d)]


def cache_directories(dispatchers: Iterable[Any]) -> list[Path]:
    """The directories numba caches ``dispatchers`` in, in this environment."""
    return sorted({Path(cache.cache_path) for cache in map(_cache_of, dispatchers)
                   if cache is not None})
