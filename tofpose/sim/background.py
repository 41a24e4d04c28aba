"""A real scene around the target: what a lab's camera sees besides the target (people,
furniture, walls, an arm reaching in front of the markers, shiny fittings), as per-pixel
maps of distance and reflectance that the renderer composites with the target by depth.

``SceneBackground`` holds the maps. It comes from a frame of any recording
(``SceneBackground.from_frame`` / ``from_recording``: a real ToF scene without the target
in it) or from ``synthetic_room``, a procedural indoor scene for the robustness study
(``tofpose.sim.randomise``, family ``background``), since the project ships no real
recordings.

Per ray, the renderer takes the background where it is nearer than the target or where
the ray misses the target (``tofpose.sim.render``): a person behind the target shows
around it, an arm in front of it hides the markers it covers. Background surfaces are
Lambertian (a shiny fitting is a reflectance above 1) and report the surface id ``WALL``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tofpose.core.camera import CameraModel


@dataclass(frozen=True, eq=False)
class SceneBackground:
    """The scene besides the target, per pixel of ``camera``.

    distance_mm : (H, W) float, radial distance along the pixel's ray (what a ToF camera
        reads); NaN or inf where nothing returns light.
    reflectance : (H, W) float >= 0, Lambertian reflectance at the illumination's
        wavelength (above 1: specular or retro-reflective spots).
    camera : the camera whose pixels the maps are (its height and width).
    """

    distance_mm: np.ndarray
    reflectance: np.ndarray
    camera: CameraModel

    def __post_init__(self) -> None:
        shape = (self.camera.height, self.camera.width)
        for name in ("distance_mm", "reflectance"):
            a = np.asarray(getattr(self, name))
            if a.shape != shape:
                raise ValueError(
                    f"background {name} has shape {a.shape}, the camera's image is {shape}"
                )
        rho = np.asarray(self.reflectance, float)
        if not np.all(np.isfinite(rho)) or np.any(rho < 0):
            raise ValueError("background reflectance must be finite and >= 0 everywhere")

    @classmethod
    def from_frame(
        cls,
        gray: np.ndarray,
        distance_mm: np.ndarray,
        camera: CameraModel,
        illumination_gain: float,
        integration_time_us: float,
        dark_counts: float = 0.0,
    ) -> SceneBackground:
        """From a recorded (gray, distance) pair of a scene without the target: the
        reflectance each pixel's amplitude implies at its distance, ``(gray - dark) *
        d^2 / (K * T)`` (``K`` = ``illumination_gain``, ``T`` = ``integration_time_us``
        of the recording; surfaces taken as facing the camera). ``dark_counts``: the
        gray level of pixels with no return (the ambient light and offset left in the
        gray image; the frame's 2nd percentile is a good estimate), taken off so that
        the re-rendered frame does not count the recording's ambient light twice.
        Pixels without a valid distance return nothing."""
        g = np.asarray(gray, float) - float(dark_counts)
        d = np.asarray(distance_mm, float)
        if g.shape != d.shape:
            raise ValueError(f"gray {g.shape} and distance {d.shape} differ in shape")
        if illumination_gain <= 0 or integration_time_us <= 0:
            raise ValueError("illumination_gain and integration_time_us must be positive")
        valid = np.isfinite(d) & (d > 0) & np.isfinite(g) & (g > 0)
        rho = np.zeros_like(d)
        rho[valid] = g[valid] * d[valid] ** 2 / (illumination_gain * integration_time_us)
        return cls(np.where(valid, d, np.inf), rho, camera)

    @classmethod
    def from_recording(
        cls,
        path: str | Path,
        index: int,
        illumination_gain: float,
        integration_time_us: float,
        dark_counts: float = 0.0,
    ) -> SceneBackground:
        """Frame ``index`` of a recording (``tofpose.io.recording``) as a background, through
        the recording's camera (``from_frame``)."""
        from tofpose.io.recording import open_recording

        with open_recording(path) as rec:
            if not 0 <= index < rec.n_frames:
                raise IndexError(f"{path} has {rec.n_frames} frames, no frame {index}")
            gray, dist, _ = rec.frame(index)
            return cls.from_frame(
                gray, dist, rec.camera, illumination_gain, integration_time_us, dark_counts
            )

    def along(self, bearings: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(distance_mm, reflectance), each (M,), for unit rays (M, 3) from the camera
        centre: the maps at the pixel each ray passes through (nearest pixel: the
        background is constant over a pixel, so its own edges fall on pixel borders and
        mix only with the target, not with each other); inf and 0 for rays outside the
        image or behind the camera."""
        b = np.asarray(bearings, float).reshape(-1, 3)
        d = np.full(len(b), np.inf)
        rho = np.zeros(len(b))
        front = b[:, 2] > 1e-9
        if not front.any():
            return d, rho
        uv = self.camera.project(b[front])
        u = np.rint(uv[:, 0]).astype(np.int64)
        v = np.rint(uv[:, 1]).astype(np.int64)
        inside = (u >= 0) & (u < self.camera.width) & (v >= 0) & (v < self.camera.height)
        idx = np.flatnonzero(front)[inside]
        dist = np.asarray(self.distance_mm, float)[v[inside], u[inside]]
        d[idx] = np.where(np.isfinite(dist) & (dist > 0), dist, np.inf)
        rho[idx] = np.asarray(self.reflectance, float)[v[inside], u[inside]]
        return d, rho


# -- a procedural indoor scene ------------------------------------------------------------
def _planes(rays, hits, normal, offset, rho):
    """Intersect rays (M, 3) with the plane n.x = offset, keep the nearest in ``hits``."""
    denom = rays @ normal
    with np.errstate(divide="ignore", invalid="ignore"):
        s = offset / denom
    _keep(hits, np.where((denom > 1e-9) & (s > 0), s, np.inf), rho)


def _box(rays, hits, lo, hi, rho):
    """Axis-aligned box [lo, hi] (mm, camera frame), slab method."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = lo[None] / rays
        t2 = hi[None] / rays
    near = np.nanmax(np.minimum(t1, t2), axis=1)
    far = np.nanmin(np.maximum(t1, t2), axis=1)
    _keep(hits, np.where((near <= far) & (near > 0), near, np.inf), rho)


def _cylinder(rays, hits, point, axis, radius, half_length, rho):
    """A capless cylinder about ``axis`` (unit) through ``point``, +-half_length."""
    p = point[None] * np.ones((len(rays), 1))
    a = axis
    d_perp = rays - (rays @ a)[:, None] * a[None]
    p_perp = -p - ((-p) @ a)[:, None] * a[None]  # origin - point, perpendicular part
    qa = np.einsum("ij,ij->i", d_perp, d_perp)
    qb = 2.0 * np.einsum("ij,ij->i", d_perp, p_perp)
    qc = np.einsum("ij,ij->i", p_perp, p_perp) - radius**2
    disc = qb * qb - 4 * qa * qc
    with np.errstate(invalid="ignore", divide="ignore"):
        s = (-qb - np.sqrt(disc)) / (2 * qa)
    along = (rays * s[:, None] - point[None]) @ a
    ok = (disc >= 0) & (s > 0) & (np.abs(along) <= half_length)
    _keep(hits, np.where(ok, s, np.inf), rho)


def _keep(hits, s, rho):
    d, r = hits
    nearer = s < d
    d[nearer] = s[nearer]
    r[nearer] = rho


def synthetic_room(
    camera: CameraModel,
    rng: np.random.Generator,
    target_range_mm: float,
    target_centre_mm: np.ndarray | None = None,
    arm_probability: float = 0.3,
) -> SceneBackground:
    """A random indoor lab scene around a target at ``target_range_mm`` (its centre at
    ``target_centre_mm`` in the camera frame, default on the optical axis): a back wall
    1-4 m behind the target (reflectance 0.2-0.8), a floor 0.8-1.5 m below the camera
    and at least 0.6 m below the target's centre (0.1-0.5), 1-3 pieces of furniture
    (boxes, 0.05-0.9) between 0.3 m behind the target and the wall, a standing person
    (a cylinder of 0.2 m radius, 0.2-0.7) 0.3-2 m behind the target (the scene is
    behind the target; what reaches in front of it is the arm), 0-4 shiny fittings
    (discs of 10-40 mm with a reflectance of 2-20: metal, glossy paint, a safety vest's
    stripe), and, with ``arm_probability``, an arm (a cylinder of 40-60 mm
    radius, 0.3-0.6) 0.3-1 m in front of the target (at least half its range from the
    camera) reaching across part of it."""
    h, w = camera.height, camera.width
    rays = camera.pixel_bearings().reshape(-1, 3)
    d = np.full(len(rays), np.inf)
    rho = np.zeros(len(rays))
    hits = (d, rho)
    centre = (
        np.array([0.0, 0.0, target_range_mm])
        if target_centre_mm is None
        else np.asarray(target_centre_mm, float)
    )
    z_t = float(centre[2])
    wall_z = z_t + rng.uniform(1000.0, 4000.0)
    _planes(rays, hits, np.array([0.0, 0.0, 1.0]), wall_z, rng.uniform(0.2, 0.8))
    # the floor (image y points down) 0.8-1.5 m below the camera and below the target
    floor_mm = max(rng.uniform(800.0, 1500.0), float(centre[1]) + 600.0)
    _planes(rays, hits, np.array([0.0, 1.0, 0.0]), floor_mm, rng.uniform(0.1, 0.5))
    half_fov = np.array([w / (2 * camera.fx), h / (2 * camera.fy)])
    for _ in range(rng.integers(1, 4)):
        z0 = rng.uniform(z_t + 300.0, wall_z - 300.0)
        size = rng.uniform([300.0, 300.0, 300.0], [1200.0, 1500.0, 800.0])
        x0 = rng.uniform(-1.2, 1.2) * half_fov[0] * z0
        y1 = rng.uniform(0.0, 1.0) * half_fov[1] * z0 + 400.0
        lo = np.array([x0 - size[0] / 2, y1 - size[1], z0])
        _box(rays, hits, lo, lo + size, rng.uniform(0.05, 0.9))
    zp = rng.uniform(z_t + 300.0, z_t + 2000.0)
    xp = rng.choice([-1.0, 1.0]) * rng.uniform(0.3, 1.2) * half_fov[0] * zp
    _cylinder(
        rays,
        hits,
        np.array([xp, 0.0, zp]),
        np.array([0.0, 1.0, 0.0]),
        200.0,
        900.0,
        rng.uniform(0.2, 0.7),
    )
    for _ in range(rng.integers(0, 5)):
        # a shiny fitting on whatever lies along a random ray
        uv = rng.uniform([0, 0], [w - 1, h - 1])
        ray = camera.bearings(uv[None])[0]
        k = int(round(uv[1])) * w + int(round(uv[0]))
        if not np.isfinite(d[k]):
            continue
        p = ray * d[k]
        n = -ray  # facing the camera
        radius = rng.uniform(5.0, 20.0)
        denom = rays @ n
        s = (p @ n) / np.where(np.abs(denom) > 1e-9, denom, np.nan)
        on = np.linalg.norm(rays * s[:, None] - p[None], axis=1) <= radius
        _keep(hits, np.where(on & (s > 0), s - 1.0, np.inf), rng.uniform(2.0, 20.0))
    if rng.random() < arm_probability:
        # 0.3-1 m in front of the target, and never nearer than half its range (a
        # target at 1 m gets its arm 0.5-0.7 m from the camera, not behind it)
        za = max(z_t - rng.uniform(300.0, 1000.0), z_t * rng.uniform(0.5, 0.7))
        reach = centre * za / z_t  # the target's line of sight at the arm's depth
        angle = rng.uniform(-0.6, 0.6)  # from horizontal, rad
        axis = np.array([np.cos(angle), np.sin(angle), 0.0])
        side = rng.choice([-1.0, 1.0])
        # the hand ends near the target's line of sight, the arm comes in from one side
        tip = reach + axis * side * rng.uniform(-150.0, 150.0)
        mid = tip + axis * side * 400.0
        _cylinder(
            rays,
            hits,
            mid + np.array([0.0, rng.uniform(-80.0, 80.0), 0.0]),
            axis,
            rng.uniform(40.0, 60.0),
            400.0,
            rng.uniform(0.3, 0.6),
        )
    return SceneBackground(d.reshape(h, w), rho.reshape(h, w), camera)
