"""Orientation forms of a scene resolved to unit quaternions (w, x, y, z), world-from-body.

Forms: `{wxyz: [...]}`, `{xyzw: [...]}`, `{matrix: 3x3}`, `{axis_angle: {axis, angle, degrees?}}`,
`{euler: {angles, convention, degrees?}}` with scipy's convention names (lowercase extrinsic, uppercase
intrinsic). The conversions themselves (axis-angle, Euler, matrix, random rotations) live in
physics/rotation.py (one home); this module only parses forms.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from rbcli.physics.rotation import matrix_to_quat, quat_from_axis_angle, quat_from_euler

# Report(subpath, message, expected, severity): how resolution tells the loader about a problem.
Report = Callable[[tuple[str | int, ...], str, str, str], None]

# a typed matrix with four decimals (0.7071) deviates ~1e-4 from orthonormal; accept that, refuse real errors
MATRIX_TOLERANCE = 1e-3
# below this a deviation is rounding, not worth a warning
QUIET_TOLERANCE = 1e-9


def resolve_orientation(spec: Mapping[str, Any] | None, report: Report) -> np.ndarray | None:
    """Unit quaternion (w, x, y, z) of a validated orientation mapping; None after reporting an error."""
    with np.errstate(all="ignore"):  # absurd magnitudes overflow to inf and are reported, not warned about
        return _resolve_orientation(spec, report)


def _resolve_orientation(spec: Mapping[str, Any] | None, report: Report) -> np.ndarray | None:
    if spec is None:
        return np.array([1.0, 0.0, 0.0, 0.0])
    if "wxyz" in spec or "xyzw" in spec:
        form = "wxyz" if "wxyz" in spec else "xyzw"
        q = np.asarray(spec[form], dtype=float)
        if form == "xyzw":
            q = np.roll(q, 1)
        norm = float(np.linalg.norm(q))
        if not np.isfinite(norm) or norm < 1e-12:
            what = "quaternion is zero" if np.isfinite(norm) else "quaternion is too large to normalise"
            report((form,), what, "a non-zero quaternion of modest size (it is normalised)", "error")
            return None
        if abs(norm - 1.0) > 1e-6:
            report((form,), f"quaternion has norm {norm:.6g}; normalised", "a unit quaternion", "warning")
        return q / norm
    if "matrix" in spec:
        r = np.asarray(spec["matrix"], dtype=float)
        deviation = float(np.max(np.abs(r.T @ r - np.eye(3))))
        det = float(np.linalg.det(r)) if np.all(np.isfinite(r.T @ r)) else float("nan")
        if not deviation <= MATRIX_TOLERANCE:  # nan (overflow) counts as not orthonormal
            report(
                ("matrix",),
                f"matrix is not orthonormal (max |R^T R - I| = {deviation:.3g})",
                "a rotation matrix: orthonormal rows and columns, determinant +1",
                "error",
            )
            return None
        if det < 0:
            report(("matrix",), "matrix is a reflection (determinant -1)", "a rotation: determinant +1", "error")
            return None
        if deviation > QUIET_TOLERANCE:
            report(("matrix",), f"matrix orthonormalised (deviation {deviation:.3g})", "", "warning")
        # nearest rotation (polar decomposition) before converting
        u, _, vt = np.linalg.svd(r)
        return matrix_to_quat(u @ vt)
    if "axis_angle" in spec:
        aa = spec["axis_angle"]
        axis = np.asarray(aa["axis"], dtype=float)
        axis_norm = np.linalg.norm(axis)
        if not np.isfinite(axis_norm):
            report(("axis_angle", "axis"), "rotation axis is too large", "an axis of modest size", "error")
            return None
        if axis_norm < 1e-12:
            report(("axis_angle", "axis"), "rotation axis is zero", "a non-zero axis", "error")
            return None
        angle = float(np.radians(aa["angle"]) if aa.get("degrees", False) else aa["angle"])
        return quat_from_axis_angle(axis, angle)
    if "euler" in spec:
        eu = spec["euler"]
        convention = str(eu["convention"])
        if any(a.lower() == b.lower() for a, b in zip(convention, convention[1:], strict=False)):
            report(
                ("euler", "convention"),
                f"convention '{convention}' turns about the same axis twice in a row",
                "three axes with no axis twice in a row, e.g. 'xyz', 'zyz', 'ZYX'",
                "error",
            )
            return None
        angles = np.asarray(eu["angles"], dtype=float)
        if eu.get("degrees", False):
            angles = np.radians(angles)
        return quat_from_euler(angles, convention)
    report((), "no orientation form given", "one of wxyz, xyzw, matrix, axis_angle, euler", "error")
    return None
