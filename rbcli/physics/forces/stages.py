"""The force pass's stages, each called through a dispatcher that compiles to nothing when the scene
does not have it: numba compiles only the force types a scene has (physics/dispatch.py says why).

The force pass (forces/wrench_pass.accumulate_wrench, the stages of forces/stage_list.py FORCE_STAGES)
calls each stage that has a table through a dispatcher made here by `force_stage`, from the stage's
code and the tables it needs, each adding its rows to `counts` (the ForceData.term_evaluations
counter). Gravity has no table (a flag and a vector) and is not dispatched. The pipeline's own optional
stages (impulses, contact, kinematic bodies) are physics/stages.py.
"""

from __future__ import annotations

from collections.abc import Callable

from numba.extending import overload

from rbcli.physics.dispatch import DISPATCH_OPTIONS, absent, kernel_only, member


def _no_force_stage(model, forces, contact, force_data, t, x, q, P, L, F, tau, counts, dissipative) -> None:  # noqa: ANN001
    """What a force stage compiles to when one of its tables is None."""


def force_stage(run: Callable[..., None], *tables: str) -> Callable[..., None]:
    """The dispatcher of a force stage: compiles to `run(model, forces, contact, force_data, t, x, q, P, L,
    F, tau, counts, dissipative)` when each of `tables` ("forces.<field>", "force_data.<field>", or
    "contact": the model's contact table) is a table in the caller's argument types, and to nothing when
    one is None. `run` is a plain function of forces/wrench_pass.py, compiled with the step
    kernels' options into its caller."""
    owners = tuple(table.partition(".")[::2] for table in tables)

    def stage(model, forces, contact, force_data, t, x, q, P, L, F, tau, counts, dissipative) -> None:  # noqa: ANN001
        kernel_only()

    stage.__name__ = stage.__qualname__ = f"{run.__name__.lstrip('_')}_stage"

    @overload(stage, jit_options=DISPATCH_OPTIONS)
    def _stage(model, forces, contact, force_data, t, x, q, P, L, F, tau, counts, dissipative):  # noqa: ANN001, ANN202
        given = {"forces": forces, "contact": contact, "force_data": force_data}
        if absent(*(member(given[owner], field) if field else given[owner] for owner, field in owners)):
            return _no_force_stage
        return run

    return stage
