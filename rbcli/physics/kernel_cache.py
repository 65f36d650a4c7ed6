"""Load rbcli's kernels from numba's cache without first building numba's compiler tables.

numba's `Cache.load_overload` begins every load with `target_context.refresh()`. The first refresh of a
process imports ~200 of numba's modules (`CPUContext.load_additional_registries`: numba.np.arraymath,
whose `_check_blas` imports scipy.linalg, the random, typed-container and datetime implementations, ...)
and installs their typing and lowering tables: ~0.3-0.5 s, about half of a short `rbsim run` (docs/
performance.md, "Start-up"). A load does not use those tables: the cache file holds the linked machine
code of the function and every callee, its cpython wrapper included; loading it unpickles the function's
descriptor and environment, maps the object code into the JIT (whose external symbols are numba's C
helpers, registered when numba is imported, and the reference-counting runtime, initialised below) and
takes the entry point. The tables are needed to compile, and numba's compiler refreshes the context
itself before compiling anything (`CompilerBase.__init__`), so a process that later compiles a kernel
(a cache miss, a new signature) builds them then, as before.

`install()` makes loads of rbcli's own kernels (functions defined in `rbcli.*` modules) skip that first
refresh; every other function's loads go through numba's code unchanged. A load that fails this way is
retried the ordinary way. It relies on numba internals (`Cache._load_overload`, `rtsys.initialize`),
checked when installing, and it is installed only on the numba versions it was verified on
(VERIFIED_NUMBA: a newer numba may change what a load needs, and a load that went wrong would not
raise, it would crash): elsewhere nothing is changed and start-up costs what numba's own path costs.
tests/physics/test_compile_only_what_is_used.py checks that a fresh process loads its kernels this way,
without importing numba.np.arraymath, and gets the bits of the process that compiled them.
"""

from __future__ import annotations

from typing import Any

# (major, minor) releases of numba whose cache loads were checked to work without the registry build
# (tests/physics/test_compile_only_what_is_used.py, the whole suite, NUMBA_BOUNDSCHECK runs)
VERIFIED_NUMBA = ((0, 68),)

_installed = False
_active = False


def active() -> bool:
    """Whether loads of rbcli's kernels skip the registry build in this process."""
    return _active


def install() -> None:
    """Make cache loads of rbcli's kernels skip numba's registry refresh (idempotent)."""
    global _installed, _active
    if _installed:
        return
    _installed = True
    try:
        import numba
        from numba.core.caching import Cache
        from numba.core.runtime import rtsys
    except ImportError:  # pragma: no cover - a numba without these internals: leave it as it is
        return
    if tuple(int(p) for p in numba.__version__.split(".")[:2]) not in VERIFIED_NUMBA:  # pragma: no cover
        return
    ordinary = Cache.load_overload
    if not hasattr(Cache, "_load_overload") or getattr(ordinary, "_rbcli", False):  # pragma: no cover
        return

    def load_overload(self: Any, sig: Any, target_context: Any) -> Any:
        module = getattr(getattr(self, "_py_func", None), "__module__", None) or ""
        if not module.startswith("rbcli."):
            return ordinary(self, sig, target_context)
        try:
            rtsys.initialize(target_context)  # the kernels' reference counting calls NRT_* helpers
            return self._load_overload(sig, target_context)
        except Exception:  # noqa: BLE001 - whatever failed, numba's own path decides (and reports)
            return ordinary(self, sig, target_context)

    load_overload._rbcli = True  # type: ignore[attr-defined]
    Cache.load_overload = load_overload  # type: ignore[method-assign]
    _active = True
