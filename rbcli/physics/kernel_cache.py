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

A cache that cannot serve a stale kernel. numba keys a function's cache on its own source file (the
index holds a hash of that file's contents, and an index with another hash is discarded) and on its
bytecode, never on its callees: split2's chunk loop (chunk_loop.py) inlines and links accumulate_contact of
contact/force.py, so an edit of force.py left the cached loop running the old contact force (the
head-on restitution tests passed with the dashpot deleted, issue 30). `install()` therefore folds
`physics_source_hash()` (SHA-256 of every rbcli/physics/**/*.py file, path and contents) into the source
stamp of every cache index of a function that may call rbcli's kernels (`_may_call_rbcli`: defined in an
rbcli module, or naming an rbcli object among its globals, as the tests' and benchmarks' loops do).
An edit of any physics source changes the stamp of every such index, so numba discards the index at its
next load, compiles anew and overwrites the old data files (numbered from 1 again: nothing piles up).
rbcli/physics imports only numpy and numba, so its sources are all a kernel can call. The hash is taken
once per process, at the first cache load or save (~1 ms for ~60 files, 0.4 MB: benchmarks/
bench_startup.py's warm runs include it); functions of other packages keep numba's own stamp. Unlike
the fast load, this guard is installed on every numba that has the internals it uses
(`IndexDataCacheFile._source_stamp`, `Cache._load_overload` / `_save_overload`); where they are missing,
rbcli's kernels are not cached at all rather than cached stale. tests/physics/test_kernel_cache.py edits
a copy of the package in a subprocess and checks that the edit takes effect and that an unchanged copy
loads without compiling.

An index that cannot be read is a miss. numba unpickles an index's entries before it compares their
source stamp, and an entry's signature names the types of its arguments (rbcli's NamedTuple tables,
sinks): an index written before such a class was renamed or removed raised AttributeError at every
load, and the run failed, where the index was obsolete anyway (its stamp is another physics hash).
`_install_index_guard` makes any such failure return an empty index, as numba does for an index of
another version, so the function compiles and its index is written anew (test_kernel_cache.py).
"""

from __future__ import annotations

import hashlib
import os
import pickle
from typing import Any

from rbcli.physics.kernel_link import StaleKernelSymbol

# (major, minor) releases of numba whose cache loads were checked to work without the registry build
# (tests/physics/test_compile_only_what_is_used.py, the whole suite, NUMBA_BOUNDSCHECK runs)
VERIFIED_NUMBA = ((0, 68),)

_installed = False
_active = False
_guarded = False
_source_hash: str | None = None

PHYSICS_DIR = os.path.dirname(os.path.abspath(__file__))


def active() -> bool:
    """Whether loads of rbcli's kernels skip the registry build in this process."""
    return _active


def guarded() -> bool:
    """Whether rbcli's cached kernels are keyed on `physics_source_hash()` in this process."""
    return _guarded


def physics_source_hash() -> str:
    """SHA-256 (hex) of every .py file under rbcli/physics, relative path and contents, in sorted order;
    taken once per process (an edit takes effect in the next process, as any edit of Python code does)."""
    global _source_hash
    if _source_hash is None:
        files, folders = [], [PHYSICS_DIR]
        while folders:  # os.scandir, not pathlib's rglob: 0.8 ms instead of 1.4 ms for the 62 files
            with os.scandir(folders.pop()) as entries:
                for entry in entries:
                    if entry.is_dir(follow_symlinks=False):
                        if entry.name != "__pycache__":
                            folders.append(entry.path)
                    elif entry.name.endswith(".py"):
                        files.append(entry.path)
        digest = hashlib.sha256()
        for path in sorted(files):
            digest.update(os.path.relpath(path, PHYSICS_DIR).encode() + b"\0")
            with open(path, "rb") as source:
                digest.update(source.read())
            digest.update(b"\0")
        _source_hash = digest.hexdigest()
    return _source_hash


def _may_call_rbcli(py_func: Any) -> bool:  # noqa: ANN401 - any Python function numba caches
    """True for a function of an rbcli module, or one whose globals name an rbcli object (a kernel, a
    module, a constant's owner): its compiled code may hold rbcli's kernels, inlined or linked."""
    if (getattr(py_func, "__module__", None) or "").startswith("rbcli."):
        return True
    names = getattr(getattr(py_func, "__code__", None), "co_names", ())
    found = getattr(py_func, "__globals__", {})
    for name in names:
        value = found.get(name)
        owner = getattr(value, "__module__", None) or getattr(value, "__name__", None)
        if isinstance(owner, str) and (owner == "rbcli" or owner.startswith("rbcli.")):
            return True
    return False


# what unpickling an index written by another version of rbcli (or numba) raises: a class or module it
# names is gone or moved, or the bytes are cut short
_UNREADABLE_INDEX = (AttributeError, ImportError, EOFError, TypeError, ValueError, IndexError, pickle.UnpicklingError)


def _install_index_guard() -> None:
    """An index whose entries cannot be unpickled reads as empty (module docstring)."""
    try:
        from numba.core.caching import IndexDataCacheFile
    except ImportError:  # pragma: no cover - a numba without this internal: its own behaviour stays
        return
    load_index = getattr(IndexDataCacheFile, "_load_index", None)
    if load_index is None or getattr(load_index, "_rbcli", False):  # pragma: no cover - other numba, or done
        return

    def guarded_load_index(self: Any) -> Any:  # noqa: ANN401
        try:
            return load_index(self)
        except _UNREADABLE_INDEX:  # obsolete: compiled anew, the index overwritten by the next save
            return {}

    guarded_load_index._rbcli = True  # type: ignore[attr-defined]
    IndexDataCacheFile._load_index = guarded_load_index  # type: ignore[method-assign]


def _install_guard(Cache: Any) -> None:  # noqa: ANN401, N803 - numba's Cache class
    """Key the cache indexes of functions that may call rbcli's kernels on the physics sources too."""
    global _guarded
    load, save = getattr(Cache, "_load_overload", None), getattr(Cache, "_save_overload", None)
    if getattr(load, "_rbcli", False):  # pragma: no cover - installed by another copy of rbcli in this process
        _guarded = True
        return
    if load is None or save is None:  # pragma: no cover - a numba without these internals
        _disable_rbcli_caching(Cache)
        return

    def stamped(self: Any) -> bool:  # noqa: ANN401
        """Fold the physics hash into this cache's source stamp once; False: leave this function alone."""
        state = getattr(self, "_rbcli_stamped", None)
        if state is None:
            state = _may_call_rbcli(getattr(self, "_py_func", None))
            cache_file: Any = getattr(self, "_cache_file", None)
            if state and not hasattr(cache_file, "_source_stamp"):  # pragma: no cover - other numba
                self.disable()
            elif state:
                cache_file._source_stamp = (cache_file._source_stamp, physics_source_hash())
            self._rbcli_stamped = state
        return state

    def load_overload(self: Any, sig: Any, target_context: Any) -> Any:  # noqa: ANN401
        stamped(self)
        try:
            return load(self, sig, target_context)
        except StaleKernelSymbol:  # compiled against a callee this process compiled anew: a cache miss
            return None

    def save_overload(self: Any, sig: Any, data: Any) -> Any:  # noqa: ANN401
        stamped(self)
        return save(self, sig, data)

    load_overload._rbcli = True  # type: ignore[attr-defined]
    Cache._load_overload = load_overload
    Cache._save_overload = save_overload
    _guarded = True


def _disable_rbcli_caching(Cache: Any) -> None:  # pragma: no cover - a numba without the internals  # noqa: ANN401, N803
    """No cache for functions that may call rbcli's kernels: compiled every run, never stale."""
    ordinary_load, ordinary_save = Cache.load_overload, Cache.save_overload

    def load_overload(self: Any, sig: Any, target_context: Any) -> Any:  # noqa: ANN401
        return None if _may_call_rbcli(getattr(self, "_py_func", None)) else ordinary_load(self, sig, target_context)

    def save_overload(self: Any, sig: Any, data: Any) -> Any:  # noqa: ANN401
        return None if _may_call_rbcli(getattr(self, "_py_func", None)) else ordinary_save(self, sig, data)

    Cache.load_overload, Cache.save_overload = load_overload, save_overload


def install() -> None:
    """Key rbcli's cached kernels on the physics sources, and make their cache loads skip numba's registry
    refresh where that was verified (idempotent; call it before any kernel runs: every module of
    rbcli.physics that defines kernels does, at import)."""
    global _installed, _active
    if _installed:
        return
    _installed = True
    import numba
    from numba.core.caching import Cache

    _install_guard(Cache)
    _install_index_guard()
    if tuple(int(p) for p in numba.__version__.split(".")[:2]) in VERIFIED_NUMBA:
        from rbcli.physics import kernel_link

        kernel_link.install()  # each stage kernel compiled once, called by symbol (kernel_link.py)
    try:
        from numba.core.runtime import rtsys
    except ImportError:  # pragma: no cover - a numba without these internals: leave its loads as they are
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
        except StaleKernelSymbol:  # kernel_link.py: compiled against another copy of a callee: a miss
            return None
        except Exception:  # noqa: BLE001 - whatever failed, numba's own path decides (and reports)
            return ordinary(self, sig, target_context)

    load_overload._rbcli = True  # type: ignore[attr-defined]
    Cache.load_overload = load_overload  # type: ignore[method-assign]
    _active = True
