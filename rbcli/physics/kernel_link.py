"""Each of rbcli's kernels compiled once: a kernel calls another by its symbol, not by linking a copy.

numba compiles a function into an LLVM module of its own and, before optimising it and generating its
machine code, links in the module of every compiled function it calls, each already holding its own
callees (`CPUCodeLibrary.finalize`). So a callee's code is optimised and turned into machine code again
in every caller, in every caller's caller and so on: a joint solve four calls deep in the chunk loop was
compiled five times over, and a second kind of scene, whose loop is a new function, compiled again every
stage it shares with the first. Measured on the first run of a 1-link pendulum (empty numba cache,
docs/performance.md "Start-up"), numba held its LLVM lock for ~60 % of the run.

`install()` (called by kernel_cache.install, so by every module that defines kernels) makes a call from
one compiled function to a *separate kernel* (below) a call of that kernel's own symbol, resolved by
numba's JIT among the modules it has already loaded, instead of a link of its module: each separate
kernel is optimised and compiled once per signature, and cached on its own. The caller's compile result
records a loader per separate callee in numba's `reload_init` (which numba pickles into the caller's
cache entry and runs before mapping the caller's machine code into the JIT), so a process that loads the
caller from the cache first loads (or compiles) every callee its code refers to: a symbol is never left
unresolved. numba's symbol for a function holds a number given in the process that compiled it (the
`v<uid>` of its mangled name: the order in which that process met functions), so a callee this process
compiled itself has another symbol than the one a caller compiled elsewhere refers to: two processes
compiling on one empty cache (two test workers, a sweep's workers, two `rbsim run`s) would crash the one that
then loads the other's caller. Each loader knows the symbol its caller refers to and refuses a callee
whose symbol differs (`StaleKernelSymbol`): the caller is then compiled here, as on a cache miss
(kernel_cache's loads turn the refusal into one), and links the callee this process has.

Separate kernels: the stage-sized kernels marked `@separately_compiled` (a joint stage, the joint
solver's factor and solve, a contact search, the contact force and commit), bound to their own name in
their module (a loader in a new process finds them by it). A call of one costs what its linked call
cost: LLVM inlines no function that large, and the arguments are passed the same way. Small kernels stay
linked, where LLVM can inline them into the loops that call them per body or per contact. Steps are
bitwise what they were (tests/physics/test_trajectory_hashes.py).

This relies on numba internals (`CPUCodeLibrary.add_linking_library`, `Dispatcher.add_overload`, the
library's `_reload_init`), so it is installed only on the numba versions it was verified on
(kernel_cache.VERIFIED_NUMBA): elsewhere numba links as it always did. `RBSIM_LINK_KERNELS=1` turns it
off (every callee linked, as numba does), for comparisons.
"""

from __future__ import annotations

import importlib
import os
import sys
from typing import Any

_installed = False


class StaleKernelSymbol(Exception):  # noqa: N818 - a cache miss, not an error: the caller is compiled anew
    """A cached caller refers to a separate kernel by a symbol this process's copy of that kernel lacks."""


class KernelLoader:
    """A `reload_init` entry: compile (or load from numba's cache) one kernel for one signature, so that
    the symbol a caller's machine code refers to is in the JIT before that code is mapped; raises
    StaleKernelSymbol when this process's kernel has another symbol than `symbol`, the one the caller
    was compiled against (the module's docstring says when)."""

    __slots__ = ("module", "qualname", "args", "symbol")

    def __init__(self, module: str, qualname: str, args: tuple[Any, ...], symbol: str) -> None:
        self.module, self.qualname, self.args, self.symbol = module, qualname, args, symbol

    def __call__(self) -> None:
        kernel: Any = importlib.import_module(self.module)
        for part in self.qualname.split("."):
            kernel = getattr(kernel, part)
        kernel.compile(self.args)
        compiled = kernel.overloads.get(tuple(self.args))
        if compiled is None or compiled.fndesc.mangled_name != self.symbol:
            raise StaleKernelSymbol(f"{self.module}.{self.qualname}: {self.symbol} is not this process's")

    def _key(self) -> tuple[str, str, tuple[Any, ...], str]:
        return (self.module, self.qualname, self.args, self.symbol)

    def __reduce__(self) -> tuple[type, tuple[str, str, tuple[Any, ...], str]]:
        return (KernelLoader, self._key())

    def __eq__(self, other: object) -> bool:
        return isinstance(other, KernelLoader) and self._key() == other._key()

    def __hash__(self) -> int:
        return hash(self._key())

    def __repr__(self) -> str:
        return f"KernelLoader({self.module}.{self.qualname})"


_SEPARATE: set[tuple[str, str]] = set()
# (module, qualname) -> the positions of the arguments whose None alone makes the kernel empty (`empty_without`)
_EMPTY_WITHOUT: dict[tuple[str, str], tuple[int, ...]] = {}


def empty_without(*names: str) -> Any:  # noqa: ANN401 - a decorator
    """Decorator (over `separately_compiled`) naming the arguments whose None alone prunes the kernel to
    nothing; by default any None argument is taken to (`_prunes_to_nothing`). For a kernel that takes
    other tables that may be None and still works without them: joints/rattle.py's `joint_update`, which
    passes the contact and kinematic tables (None in most jointed scenes) to the force pass and
    kinematic_end, and is empty only without the joint table. Linked as if empty, its code was compiled
    again into each loop that called it."""

    def mark(kernel: Any) -> Any:  # noqa: ANN401
        function = kernel.py_func
        arguments = function.__code__.co_varnames[: function.__code__.co_argcount]
        _EMPTY_WITHOUT[(function.__module__, function.__qualname__)] = tuple(arguments.index(n) for n in names)
        return kernel

    return mark


def separately_compiled(kernel: Any) -> Any:  # noqa: ANN401 - a numba dispatcher, returned as it is
    """Decorator (over `numba.njit`) of a stage-sized kernel: compiled once, called by symbol.

    For kernels that do a table's worth of work per call (a joint stage, a contact search): a call of
    one of them costs what a linked call cost (LLVM inlines no function that large). Small kernels
    called per body or per contact stay linked, so that LLVM can inline them into their loops: made
    separate too, the free bodies' split2 step ran 2.6x slower (kinematics.turn called per body)."""
    function = kernel.py_func
    _SEPARATE.add((function.__module__, function.__qualname__))
    return kernel


def is_separate_kernel(dispatcher: Any) -> bool:  # noqa: ANN401 - a numba dispatcher
    """Whether calls of this dispatcher's compiled code go by symbol (see the module's docstring)."""
    function = dispatcher.py_func
    module = getattr(function, "__module__", None) or ""
    if (module, function.__qualname__) not in _SEPARATE:
        return False
    # the module's own binding of the function: a loader in another process finds it by that name
    return getattr(sys.modules.get(module), function.__qualname__, None) is dispatcher


def _prunes_to_nothing(args: tuple[Any, ...], function: Any = None) -> bool:  # noqa: ANN401
    """A stage compiled for an absent table (a None argument: the joint stages of a scene without joints)
    is empty; linked, LLVM removes the call, where a call by symbol would pass every argument each step
    (a free body's split2 step went 82 -> 160 ns with its four empty joint stages called). Only the
    arguments `empty_without` names count, for a kernel that declares them."""
    from numba.core import types  # numba inside functions only: this module defines no kernel

    positions: Any = range(len(args))
    if function is not None:
        positions = _EMPTY_WITHOUT.get((function.__module__, function.__qualname__), positions)
    return any(isinstance(args[i], types.NoneType) for i in positions)


def active() -> bool:
    """Whether this process compiles rbcli's kernels separately."""
    return _installed


def install() -> None:
    """Compile each separate kernel once, called by symbol (idempotent). kernel_cache.install calls it on
    the numba versions it was verified on (VERIFIED_NUMBA) only."""
    global _installed
    if _installed or os.environ.get("RBSIM_LINK_KERNELS") == "1":
        return
    from numba.core import codegen
    from numba.core.dispatcher import Dispatcher

    library_class: Any = codegen.CPUCodeLibrary
    link = getattr(library_class, "add_linking_library", None)
    add_overload = getattr(Dispatcher, "add_overload", None)
    if link is None or add_overload is None:  # pragma: no cover - other numba internals
        return
    if getattr(link, "_rbcli", False):  # pragma: no cover - installed by another copy of rbcli
        _installed = True
        return

    def add_overload_tagged(self: Any, cres: Any) -> Any:  # noqa: ANN401
        """Tag a separate kernel's library (compiled or loaded from the cache) with what loads it, and give
        a library loaded from the cache back its loaders (why: the comment below)."""
        library = getattr(cres, "library", None)
        if library is not None and getattr(cres, "reload_init", None):
            # numba runs a cached function's reload_init when loading it but does not keep it on the
            # library; a caller compiled later links this library and inherits the library's set
            # (`finalize`), so without this its cache entry would lack the loaders of the separate kernels
            # this code calls, and a new process loading that caller alone would call unresolved symbols
            library._reload_init.update(cres.reload_init)
        if library is not None and is_separate_kernel(self) and not _prunes_to_nothing(cres.signature.args,
                                                                                       self.py_func):  # fmt: skip
            function = self.py_func
            library._rbcli_loader = KernelLoader(function.__module__, function.__qualname__,
                                                 tuple(cres.signature.args), cres.fndesc.mangled_name)  # fmt: skip
        return add_overload(self, cres)

    def add_linking_library(self: Any, library: Any) -> Any:  # noqa: ANN401
        """Link a callee's module into this one, unless it is a separate kernel: then call it by symbol."""
        loader = getattr(library, "_rbcli_loader", None)
        if loader is None:
            return link(self, library)
        library._ensure_finalized()  # its code is in the JIT before this library's code refers to it
        self._reload_init.add(loader)
        return None

    add_linking_library._rbcli = True  # type: ignore[attr-defined]
    library_class.add_linking_library = add_linking_library
    Dispatcher.add_overload = add_overload_tagged  # type: ignore[method-assign]
    _installed = True
