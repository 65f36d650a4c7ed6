"""Compile-time dispatch: a stage called through a `numba.extending.overload` that compiles to nothing
when its table (or its work arrays) is None, and to the stage otherwise.

A kernel's run-time test (`if table.rows:`) skips the work, not the compilation: numba types and
compiles both sides of a branch. So the chunk loops take the model and the force tables in their kernel
forms (`Model.kernel()`, `ForceTables.kernel()`), in which a table the scene lacks is None, and numba
types it as NoneType; a dispatcher's overload sees the argument types when a kernel that calls it is
compiled and chooses a no-op or the stage. The dispatchers: the force pass's (forces/stages.py
`force_stage`) and the pipeline's (physics/stages.py). Plain functions only (no kernels here), so
importing this module compiles nothing.
"""

from __future__ import annotations

from typing import Any

from numba.core import types

from rbcli.physics.step import STEP_KERNEL

# the dispatchers' implementations compile with the step kernels' options (cached, no reference counting);
# typed Any: numba's stubs type jit_options as a TypedDict without its private `_nrt`
DISPATCH_OPTIONS: Any = STEP_KERNEL


def absent(*argument_types: types.Type) -> bool:
    """True when any of a stage's tables or work arrays is None (numba's NoneType): the stage is absent."""
    return any(isinstance(t, types.NoneType) for t in argument_types)


def member(tuple_type: Any, name: str) -> types.Type:  # noqa: ANN401 - a numba NamedTuple type
    """The numba type of field `name` of a named tuple type (ForceTables or KernelForceTables, ForceData)."""
    return dict(zip(tuple_type.fields, tuple_type.types, strict=True))[name]


def kernel_only(*_args: object) -> None:
    """The Python body of every dispatcher: they run in compiled kernels only."""
    raise TypeError("a stage dispatcher runs in compiled kernels only (physics/dispatch.py)")
