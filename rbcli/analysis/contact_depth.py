"""How deep bodies went into a plane, and how fast their particles move: checks of contact scenes (numpy).

`depth_below_plane` is what the capsule ragdoll's test and benchmark measure against issue 47's target
(no part deeper than 10 % of its radius), `fastest_particle_speeds` what the ragdoll's rest is judged by.
"""

from __future__ import annotations

import numpy as np

from rbcli.physics.contact.tables import ContactTable
from rbcli.physics.model import Model
from rbcli.physics.rotation import quat_rotate
from rbcli.scene.compile_contact import PRIMITIVE_CAPSULE


def depth_below_plane(table: ContactTable, x: np.ndarray, q: np.ndarray, plane: int = 0) -> np.ndarray:
    """Per body, how far [1, of its radius] its lowest point is below `plane` (0 when above): a capsule's
    from its segment (primitive_offset, its axis R[:, 2], size (radius, half-length)), any other body's
    from its contact spheres (each with its own radius). Boxes are not measured (0)."""
    normal, point = table.plane_normal[plane], table.plane_point[plane]
    depth = np.zeros(x.shape[0])
    for b in range(x.shape[0]):
        if table.primitive_kind[b] == PRIMITIVE_CAPSULE:
            centre = x[b] + quat_rotate(q[b], table.primitive_offset[b])
            axis = quat_rotate(q[b], table.primitive_rotation[b][:, 2])
            radius, half = table.primitive_size[b, 0], table.primitive_size[b, 1]
            low = normal @ (centre - point) - abs(normal @ axis) * half - radius
        elif table.primitive_kind[b] < 0:
            mine = np.flatnonzero(table.sphere_body == b)
            if not mine.shape[0]:
                continue
            centres = x[b] + quat_rotate(q[b], table.sphere_offset[mine])
            lows = (centres - point) @ normal - table.sphere_radius[mine]
            low, radius = float(lows.min()), float(table.sphere_radius[mine][int(np.argmin(lows))])
        else:
            continue
        depth[b] = max(0.0, -low / radius)
    return depth


def fastest_particle_speeds(model: Model, q: np.ndarray, v: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """Per body, its fastest particle's speed [m/s]: max |v + omega x r| over its particles (r from the
    centre of mass, world frame)."""
    speeds = np.zeros(model.body_mass.shape[0])
    for b in range(speeds.shape[0]):
        start, count = model.body_particle_start[b], model.body_particle_count[b]
        r = quat_rotate(q[b], model.particle_offset[start : start + count])
        speeds[b] = np.linalg.norm(v[b] + np.cross(omega[b], r), axis=1).max()
    return speeds
