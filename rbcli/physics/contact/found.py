"""The stub every contact search hands its contacts to (search.py's module docstring: a sink module
registers a numba `overload` of it for its sink type). A module of its own so that the searches of
search.py and primitive_search.py share it without importing each other."""

from __future__ import annotations


def contact_found(sink, contact, work, owner, partner, ba, bb, n0, n1, n2, overlap, c0, c1, c2, k, zeta, mu):  # noqa: ANN001, ANN201
    """One contact for `sink` (kernels only; implemented per sink type by an overload in the sink's
    module): owner and partner (sphere indices; a plane: PLANE_PARTNER_BASE - p), their bodies ba and bb
    (bb = -1: a plane), the unit normal n towards the owner, the overlap d [m], the contact point c [m,
    world], the mixed stiffness k [N/m], damping ratio zeta [1] and friction mu [1]."""
    raise TypeError("contact_found runs in compiled kernels only, with a sink type that registers it")
