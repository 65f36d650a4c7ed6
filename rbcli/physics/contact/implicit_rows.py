"""The contacts of a force evaluation, kept for the linearly implicit contact of `reduced-implicit`
(tree/implicit_contact.py): each contact the force stage applies, with what its linearisation needs.

The force stage (sink.py, SINK_FORCE) applies every contact's force explicitly, as for any integrator;
where the contact work has these arrays (ContactWork.implicit_*: only in a run of an integrator with
`implicit_contact`, else None and nothing here compiles) it also appends the contact here: its bodies,
point, normal, the force it applied (normal part and tangential vector), the law's force before its
clamps (the dashpot that would pull, the tangential spring past mu f_n), the spring and dashpot constants
of its normal and tangential laws, the relative velocity it saw and its friction coefficient. The tree
stage then corrects those forces to the end of the step (backward Euler in the springs and dashpots,
law.py's formulas linearised, its clamps applied to the result) and clears the list; `implicit_begin`
clears it at each evaluation too, so an evaluation the step does not take (a recorded output's) leaves
nothing behind.

Contacts beyond the capacity (tables.py IMPLICIT_CAPACITY) keep their explicit force and are counted
(implicit_count[1]; `rbsim run` warns).
"""

from __future__ import annotations

import math
from typing import Any

from numba.core import types
from numba.extending import overload

from rbcli.physics.contact.law import history_elongation, relative_velocity
from rbcli.physics.step import STEP_KERNEL

_OPTIONS: Any = STEP_KERNEL  # typed Any: numba's stubs type jit_options as a TypedDict without `_nrt`


def _absent(work_type: Any) -> bool:  # noqa: ANN401 - a numba NamedTuple type
    """Whether the contact work type has no implicit arrays (None: not a reduced-implicit run), so the
    stages below compile to nothing (physics/dispatch.py's pattern, kept here: contact imports nothing
    above it)."""
    fields = dict(zip(work_type.fields, work_type.types, strict=True))
    return isinstance(fields["implicit_float"], types.NoneType)


def _kernel_only() -> None:
    raise TypeError("a contact stage dispatcher runs in compiled kernels only")


# implicit_float's columns
IMP_POINT = 0  # [m] (3) the contact point, world
IMP_NORMAL = 3  # (3) unit normal from b to a
IMP_FN = 6  # [N] the normal force applied, f_n = max(0, k d - c_n v_n)
IMP_FT = 7  # [N] (3) the tangential force applied (world)
IMP_KN = 10  # [N/m] k
IMP_CN = 11  # [N s/m] c_n
IMP_KT = 12  # [N/m] k_t
IMP_CT = 13  # [N s/m] c_t
IMP_VN = 14  # [m/s] v_n, a's point relative to b's, along n, at the evaluation
IMP_VT = 15  # [m/s] (3) v_t, the tangential relative velocity
IMP_MU = 18  # friction coefficient (0: frictionless)
IMP_ROWS = 19  # 1: the normal alone (frictionless); 3: with its two tangent directions
# the law's forces before its clamps: k d - c_n v_n (negative where the dashpot would pull) and
# -k_t u - c_t v_t (beyond mu f_n where the contact slides): the implicit solve linearises the law there
# and applies the clamps itself, to the forces at the end of the step
IMP_FN_LAW = 20  # [N]
IMP_FT_LAW = 21  # [N] (3)
# (IMPLICIT_COLUMNS, the row's width, is tables.py's: it allocates the arrays, numpy only)


def implicit_record(contact, work, x, s, geometry, k, zeta, mu, force) -> None:  # noqa: ANN001
    """Append one applied contact (module docstring), evaluated at offset s [s] into the step: `geometry` a
    law.ContactGeometry, k, zeta, mu its mixed material, `force` [N] the force the stage applied on
    body_a; nothing where the work has no implicit arrays."""
    _kernel_only()


@overload(implicit_record, jit_options=_OPTIONS)
def _implicit_record(contact, work, x, s, geometry, k, zeta, mu, force):  # noqa: ANN001, ANN202
    if _absent(work):
        return lambda contact, work, x, s, geometry, k, zeta, mu, force: None

    def record(contact, work, x, s, geometry, k, zeta, mu, force):  # noqa: ANN001, ANN202
        index = work.implicit_count[0]
        if index >= work.implicit_float.shape[0]:
            work.implicit_count[1] += 1
            return
        work.implicit_count[0] = index + 1
        ba, bb = geometry.body_a, geometry.body_b
        n0, n1, n2 = geometry.normal
        c0, c1, c2 = geometry.point
        m_eff, vn, v0, v1, v2 = relative_velocity(contact, work, x, ba, bb, n0, n1, n2, c0, c1, c2)
        cn = 2.0 * zeta * math.sqrt(k * m_eff)  # law.normal_force's and tangential_force's constants
        kt = contact.tangential_ratio * k
        ct = cn * math.sqrt(contact.tangential_ratio)
        work.implicit_int[index, 0], work.implicit_int[index, 1] = ba, bb
        row = work.implicit_float[index]
        fn = force[0] * n0 + force[1] * n1 + force[2] * n2
        t0, t1, t2 = force[0] - fn * n0, force[1] - fn * n1, force[2] - fn * n2
        row[IMP_POINT], row[IMP_POINT + 1], row[IMP_POINT + 2] = c0, c1, c2
        row[IMP_NORMAL], row[IMP_NORMAL + 1], row[IMP_NORMAL + 2] = n0, n1, n2
        row[IMP_VT], row[IMP_VT + 1], row[IMP_VT + 2] = v0, v1, v2
        row[IMP_FN] = fn
        row[IMP_FT], row[IMP_FT + 1], row[IMP_FT + 2] = t0, t1, t2
        row[IMP_KN], row[IMP_CN], row[IMP_KT], row[IMP_CT] = k, cn, kt, ct
        row[IMP_VN], row[IMP_MU] = vn, mu
        row[IMP_ROWS] = 3.0 if mu > 0.0 else 1.0
        row[IMP_FN_LAW] = k * geometry.overlap - cn * vn
        x0, x1, x2 = 0.0, 0.0, 0.0
        if mu > 0.0:  # the spring's stretch at the evaluation, xi_0 + s v_t (law.tangential_force)
            x0, x1, x2 = history_elongation(work, geometry.owner, geometry.partner, n0, n1, n2)
            x0, x1, x2 = x0 + s * v0, x1 + s * v1, x2 + s * v2
        row[IMP_FT_LAW] = -kt * x0 - ct * v0
        row[IMP_FT_LAW + 1] = -kt * x1 - ct * v1
        row[IMP_FT_LAW + 2] = -kt * x2 - ct * v2

    return record


def implicit_begin(work) -> None:  # noqa: ANN001
    """A force evaluation starts: the kept contacts are cleared (nothing without implicit arrays)."""
    _kernel_only()


@overload(implicit_begin, jit_options=_OPTIONS)
def _implicit_begin(work):  # noqa: ANN001, ANN202
    if _absent(work):
        return lambda work: None

    def begin(work):  # noqa: ANN001, ANN202
        work.implicit_count[0] = 0

    return begin
