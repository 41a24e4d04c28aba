"""The compiled ray caster against a ray-by-ray oracle written from the geometry."""

from __future__ import annotations

import numpy as np

from tofpose.core.geometry import RigidTransform, rotation_from_euler_deg
from tofpose.sim.bench import R_FACING
from tofpose.sim.raycast import FIRST_DISC, NO_HIT, PLATE, WALL
from tofpose.sim.scene import TargetScene


def _oracle(sc, b):
    """Nearest hit of one unit ray ``b`` (3,): (distance, surface id, cos incidence)."""
    hits = []
    n = sc.plate_normal
    if sc.wall_point is not None and b @ n != 0:
        s = (sc.wall_point @ n) / (b @ n)
        if s > 0:
            hits.append((s, WALL, abs(b @ n)))
    if b @ n != 0:
        s = (sc.plate_centre @ n) / (b @ n)
        local = sc.plate_axes @ (b * s - sc.plate_centre)
        if s > 0 and np.all(np.abs(local) <= sc.plate_half_size):
            hits.append((s, PLATE, abs(b @ n)))
    for k, (c, dn_vec, r) in enumerate(
        zip(sc.disc_centres, sc.disc_normals, sc.disc_radii, strict=True)
    ):
        dn = b @ dn_vec
        if dn >= 0:
            continue
        s = (c @ dn_vec) / dn
        if s > 0 and np.linalg.norm(b * s - c) <= r:
            hits.append((s, FIRST_DISC + k, -dn))
    return min(hits, key=lambda h: h[0]) if hits else (np.inf, NO_HIT, 0.0)


def test_every_ray_hits_what_the_geometry_says():
    rng = np.random.default_rng(4)
    scene = TargetScene()
    T = RigidTransform(
        rotation_from_euler_deg(8.0, -12.0, 30.0) @ R_FACING, np.array([40.0, -25.0, 1500.0])
    )
    sc = scene.in_camera(T)
    # rays at the disc centres and around their rims, across the plate and beside it
    aims = [
        sc.disc_centres + rng.normal(0, 1, sc.disc_centres.shape) * sc.disc_radii[:, None]
        for _ in range(30)
    ]
    aims.append(sc.plate_centre + rng.uniform(-600, 600, (800, 3)))
    b = np.vstack(aims)
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    d, sid, cos = sc.raycast(b)
    want = [_oracle(sc, x) for x in b]
    np.testing.assert_array_equal(sid, [w[1] for w in want])
    np.testing.assert_allclose(d, [w[0] for w in want], rtol=1e-12)
    np.testing.assert_allclose(cos, [w[2] for w in want], rtol=1e-12, atol=1e-15)
    # every kind of surface is exercised
    assert {WALL, PLATE} <= set(sid.tolist()) and (sid >= FIRST_DISC).sum() > 100
    assert len(set(sid[sid >= FIRST_DISC].tolist())) == len(scene.catalog)
