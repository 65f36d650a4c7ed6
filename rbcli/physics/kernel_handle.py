"""Kernel arguments boxed once: a handle that hands a compiled function a whole table as one pointer.

A call from Python of a compiled function converts every argument on every call: numba fingerprints
each array of a named tuple to find its type and unboxes it into its native struct, ~0.15 us per array
(~0.07 in a plain tuple). The chunk loop of a contact scene takes ~120 arrays (the model with its
contact table, the force tables, the data with the contact work, the frame buffers): ~15 us per call,
against ~6 us without contact, where the step itself costs ~0.15 us. A user stepping one step per call
(`Simulation.step()` in a loop) paid 2.3x for a `contact:` section with nothing near (issue 47 item 6).

`KernelHandle(value)` converts `value` (a tuple of arrays and scalars, as a kernel takes it) once, into
a buffer in numba's own native layout (numba's unboxing, compiled for its type by `_store`), and keeps
`value` alive. numba types the handle as `KernelHandleType(type of value)` and unboxes it as the buffer's
address (~0.5 us whatever the value holds); `opened(handle)` in the kernel loads the value from the
buffer, and `opened(anything else)` is that value, so one kernel source serves both. The arrays are
never reallocated (Data allocates them once; everything writes them in place), so the native form stays
true while the handle lives; a kernel compiled without reference counting (STEP_KERNEL, CHUNK_KERNEL) is
given arrays without a meminfo either way. Handles hold rbcli's own tables only: numba's cache index of
`_store` names the type of every value it was compiled for, and a process that loads the index must be
able to import each (a test's own named tuple there broke `rbsim run` in the next process).
"""

from __future__ import annotations

from typing import Any

import numba
import numpy as np
from numba.core import cgutils, types
from numba.core.imputils import impl_ret_borrowed
from numba.extending import NativeValue, intrinsic, models, register_model, typeof_impl, unbox

from rbcli.physics.step import STEP_KERNEL


class KernelHandleType(types.Type):
    """The numba type of a KernelHandle whose value has numba type `inner`."""

    def __init__(self, inner: types.Type) -> None:
        self.inner = inner
        super().__init__(name=f"KernelHandle({inner})")

    @property
    def key(self) -> types.Type:
        return self.inner


register_model(KernelHandleType)(models.OpaqueModel)  # the buffer's address


# bytes of a value's native form, per numba type: a Simulation makes four handles, and a run of few steps
# (a sweep's variant, a test) paid ~0.7 ms sizing them again
_NATIVE_SIZES: dict[types.Type, int] = {}


class KernelHandle:
    """`value` in numba's native form, for kernels that open it (`opened`). Keep the handle while a kernel
    may use it, and the arrays of `value` where they are (the buffer holds their addresses)."""

    __slots__ = ("_buffer", "_numba_type_", "address", "value")

    def __init__(self, value: Any) -> None:  # noqa: ANN401 - a tuple of arrays and scalars
        from numba.core.registry import cpu_target

        inner = numba.typeof(value)  # what the dispatcher would find for `value` as an argument
        size = _NATIVE_SIZES.get(inner)
        if size is None:  # llvmlite parses the type's IR to size it: ~0.2 ms, paid once per type
            context = cpu_target.target_context
            size = _NATIVE_SIZES[inner] = int(context.get_abi_sizeof(context.get_data_type(inner)))
        self.value = value
        self._buffer = np.zeros(max(size, 8), dtype=np.uint8)  # malloc's alignment: 16 bytes
        self.address = int(self._buffer.ctypes.data)
        self._numba_type_ = KernelHandleType(inner)
        _store(self._buffer, value)


@typeof_impl.register(KernelHandle)
def _typeof_handle(val: KernelHandle, c: Any) -> types.Type:  # noqa: ANN401
    return val._numba_type_


@unbox(KernelHandleType)
def _unbox_handle(typ, obj, c):  # noqa: ANN001, ANN202
    address = c.pyapi.object_getattr_string(obj, "address")
    pointer = c.pyapi.long_as_voidptr(address)
    c.pyapi.decref(address)
    return NativeValue(pointer, is_error=cgutils.is_null(c.builder, pointer))


@intrinsic
def _store_into(typingctx, buffer, value):  # noqa: ANN001, ANN202
    """Write `value` in its native (data) layout at the start of the uint8 array `buffer`."""

    def codegen(context, builder, signature, args):  # noqa: ANN001, ANN202
        model = context.data_model_manager[value]
        array = context.make_array(buffer)(context, builder, args[0])
        pointer = builder.bitcast(array.data, model.get_data_type().as_pointer())
        builder.store(model.as_data(builder, args[1]), pointer)
        return context.get_dummy_value()

    return types.none(buffer, value), codegen


# STEP_KERNEL: no reference counting, as the kernels, so the arrays are unboxed as the kernels' own
# arguments would be (no meminfo)
@numba.njit(**STEP_KERNEL)
def _store(buffer, value) -> None:  # noqa: ANN001
    """`value`'s native form into `buffer` (KernelHandle)."""
    _store_into(buffer, value)  # type: ignore[call-arg]  # numba's stubs: an intrinsic's typing context


@intrinsic
def opened(typingctx, value):  # noqa: ANN001, ANN202
    """Kernels only: the value a KernelHandle holds; any other value is returned as it is."""
    if isinstance(value, KernelHandleType):
        inner = value.inner

        def load(context, builder, signature, args):  # noqa: ANN001, ANN202
            model = context.data_model_manager[inner]
            pointer = builder.bitcast(args[0], model.get_data_type().as_pointer())
            return model.load_from_data_pointer(builder, pointer)

        return inner(value), load

    def same(context, builder, signature, args):  # noqa: ANN001, ANN202
        return impl_ret_borrowed(context, builder, value, args[0])

    return value(value), same
