"""Kernel handles (physics/kernel_handle.py): a table converted once into numba's native form, opened in the
kernel as the very table (its arrays, not copies), so the runner's calls convert no array per call.

Checked against the table passed as it is: the same values read, writes through the handle land in the
numpy arrays, and a kernel compiled for handles serves a table it was not compiled with only through a
new handle (the Simulation makes one when a table is replaced).
"""

from __future__ import annotations

import numba
import numpy as np

import rbcli
from rbcli.physics.kernel_handle import KernelHandle, KernelHandleType, opened
from rbcli.scene.load import load_scene_text


def table() -> tuple:
    """A table as kernels take them, in plain tuples: (x float64 (4, 3), (counts int64 (3,), flags int8
    (2, 2), scale), None, size, on). Not named tuples of this module: `_store`'s cache index would then
    name a test module that another process (rbsim) cannot import when it loads that index."""
    inner = (np.arange(3), np.array([[1, 0], [0, 1]], dtype=np.int8), 2.5)
    return (np.arange(12.0).reshape(4, 3), inner, None, 7, True)


@numba.njit(_nrt=False)
def _read_and_write(value):  # noqa: ANN001, ANN202
    x, (counts, flags, scale), nothing, size, on = opened(value)
    total = x.sum() + counts.sum() * scale + flags.sum() + size + (1.0 if on else 0.0)
    x[3, 2] = -1.0  # written through to the caller's array
    counts[0] = 42
    return total, x.shape[0], nothing is None


def test_a_handle_opens_to_the_table_itself():
    plain, boxed = table(), table()
    handle = KernelHandle(boxed)
    assert isinstance(numba.typeof(handle), KernelHandleType)
    expected = _read_and_write(plain)  # opened(a table) is the table
    assert _read_and_write(handle) == expected == (66.0 + 3 * 2.5 + 2 + 7 + 1, 4, True)
    for a, b in ((plain[0], boxed[0]), (plain[1][0], boxed[1][0])):
        np.testing.assert_array_equal(a, b)  # the same writes, into the arrays the handle holds
    assert boxed[0][3, 2] == -1.0 and boxed[1][0][0] == 42


FAR = ("  - {{name: {name}, shape: {{type: box, size: [0.2, 0.2, 0.2]}}, spacing: 0.02, density: 500, "
       "position: [{x}, 0, 0], velocity: [{v}, 0, 0], angular_velocity: [1, 2, 3]}}")  # fmt: skip


def far_boxes() -> rbcli.Simulation:
    bodies = "\n".join(FAR.format(name=f"b{i}", x=5.0 * i, v=0.1 * (2 * i - 1)) for i in range(2))
    text = "name: far\nsimulation: {dt: 0.001, steps: 10, integrator: split2}\ncontact: {ground: -100}\n"
    return rbcli.Simulation(load_scene_text(text + "bodies:\n" + bodies + "\n"))


def test_the_runner_passes_handles_and_renews_a_replaced_table():
    sim = far_boxes()
    sim.step()
    passed = [numba.typeof(handle) for handle in sim._handles]  # model, forces, data, frames
    assert all(isinstance(t, KernelHandleType) for t in passed), passed
    assert any([signature[i] for i in (0, 1, 2, 7)] == passed for signature in sim._chunk.signatures)
    first = sim._handles[2]
    sim.step()
    assert sim._handles[2] is first  # converted once
    sim._kdata = sim.data.kernel()  # a new tuple of the same arrays (as tests of the contact search do)
    sim.step()
    assert sim._handles[2] is not first and sim._handles[2].value is sim._kdata
    reference = far_boxes()
    reference.step(3)
    np.testing.assert_array_equal(sim.data.state.x, reference.data.state.x)
    np.testing.assert_array_equal(sim.data.state.q, reference.data.state.q)
