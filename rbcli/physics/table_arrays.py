"""The arrays of the model's read-only tables (force, joint and kinematic tables): contiguous, of the dtype
kernels expect, and frozen (numba then types them as read-only arrays, and no kernel or caller can change a
table after the model is built). One home for the three table modules."""

from __future__ import annotations

import numpy as np


def frozen_floats(values, *shape: int) -> np.ndarray:  # noqa: ANN001
    """float64 rows of `shape` (none: a 1-D column), contiguous and read-only."""
    out = np.ascontiguousarray(np.asarray(values, dtype=np.float64).reshape((-1, *shape)))
    out.setflags(write=False)
    return out


def frozen_ints(values) -> np.ndarray:  # noqa: ANN001
    """An int64 column, contiguous and read-only."""
    out = np.ascontiguousarray(np.asarray(values, dtype=np.int64).reshape(-1))
    out.setflags(write=False)
    return out


def frozen_bools(values) -> np.ndarray:  # noqa: ANN001
    """A bool column, contiguous and read-only."""
    out = np.ascontiguousarray(np.asarray(values, dtype=np.bool_).reshape(-1))
    out.setflags(write=False)
    return out
