"""The simulated scene: a target plate with raised disc retro-reflectors, an optional
background wall, and clutter (extra bright spurious reflectors), posed in the camera frame.

``TargetScene.in_camera(T_camera_target)`` returns flat surfaces in the camera frame that
``raycast`` intersects with pixel rays. Surfaces are planes bounded by a rectangle (plate),
a disc (reflectors, clutter) or unbounded (wall).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tofpose.core.catalog import Catalog, paper_target
from tofpose.core.geometry import RigidTransform
from tofpose.sim.background import SceneBackground
from tofpose.sim.raycast import FIRST_DISC, NO_HIT, PLATE, WALL, cast_rays  # noqa: F401


@dataclass(frozen=True)
class Clutter:
    """A spurious bright reflection: a disc in the target frame, facing ``normal``."""

    position_mm: tuple[float, float, float]
    diameter_mm: float
    gain: float = 1.0  # retro gain relative to a catalog reflector
    normal: tuple[float, float, float] = (0.0, 0.0, 1.0)


@dataclass(frozen=True)
class TargetScene:
    """Target geometry and surface properties.

    Attributes
    ----------
    catalog : Catalog
        Reflector discs (target frame, facing +z).
    plate_reflectance : float
        Lambertian reflectance of the black plate at 850 nm.
    reflector_diffuse_reflectance : float
        Diffuse reflectance of the white reflectors (for ambient light).
    wall_distance_mm : float or None
        A Lambertian wall parallel to the plate, this far behind it; None for no wall.
    wall_reflectance : float
    clutter : tuple of Clutter
    reflector_gains : per catalog reflector, its retro-reflective return relative to a
        new one (ageing, dirt, a batch of different film: real targets spread by 10-30 %);
        None: all 1.
    background : a real scene around the target (``tofpose.sim.background``: people,
        furniture, an arm in front of the markers), composited by depth; None: only the
        wall, if any.
    retro_falloff_exponent : the retro-reflectors' return falls off as cos^n of the
        incidence angle (n = 3 here, times the cos of the projected area: cos^4 in all
        for n = 3; cube-corner sheeting falls off faster, glass beads slower).

    Plate brightness: ``plate_reflectance`` 0.10 is black anodised aluminium; a
    mock-up covered in multi-layer insulation (MLI) returns 0.3-0.6 of a white diffuser at
    850 nm in the directions a camera beside its illuminator sees.
    """

    catalog: Catalog = field(default_factory=paper_target)
    plate_reflectance: float = 0.10
    reflector_diffuse_reflectance: float = 0.8
    wall_distance_mm: float | None = 2000.0
    wall_reflectance: float = 0.4
    clutter: tuple[Clutter, ...] = ()
    reflector_gains: tuple[float, ...] | None = None
    retro_falloff_exponent: float = 3.0
    background: SceneBackground | None = None

    def __post_init__(self) -> None:
        if self.reflector_gains is not None and len(self.reflector_gains) != len(self.catalog):
            raise ValueError(
                f"reflector_gains has {len(self.reflector_gains)} values, the catalog "
                f"{len(self.catalog)} reflectors"
            )

    def in_camera(self, T_camera_target: RigidTransform) -> SceneInCamera:
        """Surfaces transformed into the camera frame. Raises ``ValueError`` when the
        target origin is not in front of the camera."""
        R, t = T_camera_target.R, np.asarray(T_camera_target.t_mm, float)
        if t[2] <= 0:
            raise ValueError(f"target is behind the camera (target origin z = {t[2]:.1f} mm <= 0)")
        normal = R[:, 2]
        cat = self.catalog
        centres = T_camera_target.apply(cat.positions_mm)
        radii = cat.diameters_mm / 2
        gains = (
            np.ones(len(cat))
            if self.reflector_gains is None
            else np.asarray(self.reflector_gains, float)
        )
        normals = np.repeat(normal[None], len(cat), axis=0)
        if self.clutter:
            c_pos = np.array([c.position_mm for c in self.clutter], float)
            c_norm = np.array([c.normal for c in self.clutter], float)
            c_norm /= np.linalg.norm(c_norm, axis=1, keepdims=True)
            centres = np.vstack((centres, T_camera_target.apply(c_pos)))
            radii = np.concatenate((radii, [c.diameter_mm / 2 for c in self.clutter]))
            gains = np.concatenate((gains, [c.gain for c in self.clutter]))
            normals = np.vstack((normals, c_norm @ R.T))
        wall_point = None
        if self.wall_distance_mm is not None:
            wall_point = t - normal * self.wall_distance_mm
        return SceneInCamera(
            plate_centre=t,
            plate_axes=R[:, :2].T.copy(),
            plate_half_size=np.asarray(cat.plate_size_mm, float) / 2,
            plate_normal=normal,
            disc_centres=centres,
            disc_normals=normals,
            disc_radii=radii,
            disc_gains=gains,
            wall_point=wall_point,
            scene=self,
        )


@dataclass(frozen=True)
class SceneInCamera:
    """Scene surfaces in the camera frame (all arrays in mm).

    plate_axes : ndarray of shape (2, 3), the plate's in-plane x and y axes.
    disc_* : arrays of shape (D, 3) or (D,), catalog reflectors first, then clutter.
    """

    plate_centre: np.ndarray
    plate_axes: np.ndarray
    plate_half_size: np.ndarray
    plate_normal: np.ndarray
    disc_centres: np.ndarray
    disc_normals: np.ndarray
    disc_radii: np.ndarray
    disc_gains: np.ndarray
    wall_point: np.ndarray | None
    scene: TargetScene

    def raycast(self, bearings: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Nearest intersection of unit rays from the camera centre (the compiled
        ``tofpose.sim.raycast.cast_rays``).

        Parameters
        ----------
        bearings : ndarray of shape (M, 3), unit vectors.

        Returns
        -------
        distance_mm : ndarray of shape (M,), radial distance to the hit (inf if none).
        surface_id : ndarray of shape (M,) uint8: NO_HIT, WALL, PLATE or FIRST_DISC + k.
        cos_incidence : ndarray of shape (M,), cosine between the ray and the normal.
        """
        has_wall = self.wall_point is not None
        return cast_rays(
            np.ascontiguousarray(bearings, dtype=np.float64),
            np.asarray(self.wall_point if has_wall else np.zeros(3), np.float64),
            has_wall,
            np.asarray(self.plate_centre, np.float64),
            np.asarray(self.plate_normal, np.float64),
            np.ascontiguousarray(self.plate_axes, dtype=np.float64),
            np.asarray(self.plate_half_size, np.float64),
            np.ascontiguousarray(self.disc_centres, dtype=np.float64).reshape(-1, 3),
            np.ascontiguousarray(self.disc_normals, dtype=np.float64).reshape(-1, 3),
            np.ascontiguousarray(self.disc_radii, dtype=np.float64).reshape(-1),
        )
