"""Specular glints: small bright spots that are not markers (a bolt head, a crease in a
blanket, a polished edge that mirrors the illuminator into the lens), each at a real
range, rendered into a frame by adding its light to the pixels' phasors.

A glint is a point that mirrors the illuminator; the lens (and the glint's own extent)
images it as a spot, modelled as a Gaussian of sigma ``sigma_px`` integrated over each
pixel's area. Its light adds to what the pixel already sees, as a phasor of the glint's
range (``tofpose.sim.render``'s mixing: amplitude and phase, so a pixel the spot only
partly lights reads a distance between the glint's and the surface behind it). The
glint itself is too small to hide the surface behind it.

The renderer (``render_frame``) takes no glints; ``render_glints`` adds them to a
rendered frame and measures the pixels they light again with ``render_frame``'s noise,
wrap, saturation and amplitude floor (for a sensor without systematic range errors).
``glint_phasors`` is the part a renderer would add to its phasor images before the PSF.

The spots' size and brightness are those of another renderer's glints
(``../shared/foreign/foreign-glints.h5``: a Gaussian fitted to each isolated glint gives
sigma 0.4-1.5 px and peaks of 500-2700 counts, 5th-95th percentile), which is what the
robustness study draws (``tofpose.sim.randomise``, family ``glints``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.special import erf

from tofpose.core.camera import CameraModel
from tofpose.core.catalog import Catalog
from tofpose.core.geometry import RigidTransform
from tofpose.sim.render import RenderedFrame, SensorModel
from tofpose.sim.scene import TargetScene

#: a spot is evaluated this many sigmas (plus a pixel) around its centre
SPOT_HALF_WIDTH_SIGMAS = 4.0
#: placement attempts per glint before ``draw_glints`` gives up
MAX_DRAWS_PER_GLINT = 200


@dataclass(frozen=True, eq=False)
class Glints:
    """The specular glints of one frame.

    Attributes
    ----------
    positions_mm : ndarray of shape (N, 3)
        Each glint in the camera frame (mm), in front of the camera: its range
        (``norm``) is what the pixels it lights read, its projection the spot's centre.
    sigma_px : ndarray of shape (N,)
        Each spot's Gaussian sigma in the image (px), > 0.
    peak_counts : ndarray of shape (N,)
        Each spot's peak, in reference (EPC660) counts per pixel area at the frame's
        exposure, >= 0: the spot's whole light is ``2 pi sigma^2 peak`` counts, and a
        pixel centred on it reads ``2 pi sigma^2 erf(1 / (2 sqrt(2) sigma))^2 peak``
        (0.73 of the peak at sigma 0.5 px, 0.97 at 1.6 px). A camera of another count
        scale reads them times its ``count_scale``.
    """

    positions_mm: np.ndarray
    sigma_px: np.ndarray
    peak_counts: np.ndarray

    def __post_init__(self) -> None:
        p = np.asarray(self.positions_mm, float).reshape(-1, 3)
        s = np.asarray(self.sigma_px, float).reshape(-1)
        a = np.asarray(self.peak_counts, float).reshape(-1)
        if not len(p) == len(s) == len(a):
            raise ValueError(
                f"glints: {len(p)} positions, {len(s)} sigmas and {len(a)} peaks differ in number"
            )
        if np.any(p[:, 2] <= 0):
            raise ValueError("glints must be in front of the camera (positions_mm z > 0)")
        if not np.all(s > 0):
            raise ValueError(f"glint sigma_px must be positive, got {s[~(s > 0)]}")
        if not np.all(a >= 0):
            raise ValueError(f"glint peak_counts must be >= 0, got {a[~(a >= 0)]}")
        for name, value in (("positions_mm", p), ("sigma_px", s), ("peak_counts", a)):
            object.__setattr__(self, name, value)

    def __len__(self) -> int:
        return len(self.sigma_px)

    @property
    def range_mm(self) -> np.ndarray:
        """Each glint's radial distance from the camera, shape (N,), mm."""
        return np.linalg.norm(self.positions_mm, axis=1)


def target_image_box(
    camera: CameraModel, catalog: Catalog, T_camera_target: RigidTransform
) -> tuple[np.ndarray, float]:
    """The target's image: the projection of its centre (2,) px and its half extent, px
    (half the larger side of the plate's projected bounding box)."""
    w, h = np.asarray(catalog.plate_size_mm, float) / 2
    corners = np.array([[sx * w, sy * h, 0.0] for sx in (-1, 1) for sy in (-1, 1)])
    uv = camera.project(T_camera_target.apply(corners))
    centre = camera.project(np.asarray(T_camera_target.t_mm, float)[None])[0]
    return centre, 0.5 * float(np.max(uv.max(axis=0) - uv.min(axis=0)))


def draw_glints(
    rng: np.random.Generator,
    camera: CameraModel,
    scene: TargetScene,
    T_camera_target: RigidTransform,
    *,
    n: int = 15,
    sigma_px: tuple[float, float] = (0.5, 1.6),
    peak_counts: tuple[float, float] = (400.0, 2500.0),
    range_band_mm: float = 250.0,
    spread: float = 1.5,
) -> Glints:
    """``n`` glints in and around the target's image, each visible.

    Each glint's spot centre is uniform in the square of half side ``spread`` times the
    target's image half extent (``target_image_box``) around the target's image centre,
    within the frame; its range uniform within ``range_band_mm`` of the target centre's;
    its sigma and peak uniform in ``sigma_px`` (px) and ``peak_counts`` (reference
    counts). A glint that the target hides (its surface along the glint's ray is nearer:
    a glint behind the plate) is drawn again, so all ``n`` are seen.
    """
    if n < 0 or spread <= 0 or range_band_mm < 0:
        raise ValueError(
            f"need n >= 0, spread > 0 and range_band_mm >= 0, got {n}, {spread}, {range_band_mm}"
        )
    centre, half = target_image_box(camera, scene.catalog, T_camera_target)
    lo = np.maximum(centre - spread * half, -0.5)
    hi = np.minimum(centre + spread * half, [camera.width - 0.5, camera.height - 0.5])
    if np.any(lo >= hi):
        raise ValueError("the target's image is outside the frame: no place for glints")
    target_mm = float(np.linalg.norm(T_camera_target.t_mm))
    surfaces = scene.in_camera(T_camera_target)
    kept: list[np.ndarray] = []  # rows (x, y, z, sigma, peak)
    for _ in range(MAX_DRAWS_PER_GLINT):
        m = n - len(kept)
        if m == 0:
            break
        uv = rng.uniform(lo, hi, (m, 2))
        r = target_mm + rng.uniform(-range_band_mm, range_band_mm, m)
        s = rng.uniform(*sigma_px, m)
        a = rng.uniform(*peak_counts, m)
        e = camera.bearings(uv)
        d_hit, _, _ = surfaces.raycast(e)
        for k in np.flatnonzero(r <= d_hit):
            kept.append(np.concatenate((r[k] * e[k], [s[k], a[k]])))
    if len(kept) < n:
        raise RuntimeError(f"placed {len(kept)} of {n} visible glints: the target hides the rest")
    rows = np.array(kept).reshape(-1, 5)
    return Glints(rows[:, :3], rows[:, 3], rows[:, 4])


def _pixel_fractions(centre_px: float, sigma_px: float, edges: np.ndarray) -> np.ndarray:
    """The share of a 1-D Gaussian (centre, sigma) that falls in each pixel of the
    integer centres ``edges`` (K,) (the pixel spans centre +- 0.5)."""
    z = (edges[:, None] + np.array([-0.5, 0.5]) - centre_px) / (np.sqrt(2.0) * sigma_px)
    c = erf(z)
    return 0.5 * (c[:, 1] - c[:, 0])


def glint_phasors(
    glints: Glints, camera: CameraModel, sensor: SensorModel
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The glints' light per pixel as phasors, in reference counts.

    Each spot, through the lens's PSF core (``sensor.blur_sigma_px`` adds in quadrature
    to its sigma; the halo is not applied), is integrated over each pixel's area and
    carries the phase of its range (``sensor.mm_per_radian``).

    Returns
    -------
    re, im : ndarray of shape (H, W), the phasor's parts (0 where no glint lights).
    range_mm : ndarray of shape (H, W), the lit pixels' amplitude-weighted glint range
        (NaN elsewhere): the period a multi-frequency sensor unwraps them to.
    """
    h, w = camera.height, camera.width
    re, im = np.zeros((h, w)), np.zeros((h, w))
    amp, ranged = np.zeros((h, w)), np.zeros((h, w))
    if len(glints) == 0:
        return re, im, np.full((h, w), np.nan)
    uv = camera.project(glints.positions_mm)
    sigma = np.hypot(glints.sigma_px, sensor.blur_sigma_px)
    for (u, v), s, peak, r in zip(uv, sigma, glints.peak_counts, glints.range_mm, strict=True):
        half = SPOT_HALF_WIDTH_SIGMAS * s + 1.0
        u0, u1 = max(int(np.floor(u - half)), 0), min(int(np.ceil(u + half)) + 1, w)
        v0, v1 = max(int(np.floor(v - half)), 0), min(int(np.ceil(v + half)) + 1, h)
        if u0 >= u1 or v0 >= v1:
            continue
        fu = _pixel_fractions(u, s, np.arange(u0, u1, dtype=float))
        fv = _pixel_fractions(v, s, np.arange(v0, v1, dtype=float))
        a = 2.0 * np.pi * s**2 * peak * np.outer(fv, fu)  # counts in each pixel
        phase = r / sensor.mm_per_radian
        re[v0:v1, u0:u1] += a * np.cos(phase)
        im[v0:v1, u0:u1] += a * np.sin(phase)
        amp[v0:v1, u0:u1] += a
        ranged[v0:v1, u0:u1] += a * r
    lit = amp > 0
    range_mm = np.full((h, w), np.nan)
    range_mm[lit] = ranged[lit] / amp[lit]
    return re, im, range_mm


def render_glints(
    frame: RenderedFrame,
    glints: Glints,
    camera: CameraModel,
    sensor: SensorModel,
    rng: np.random.Generator | None = None,
) -> RenderedFrame:
    """``frame`` (``render_frame(camera, ..., sensor, ...)``, one static pose) with the
    glints' light added.

    The pixels the glints light are measured again: their noiseless phasor (the frame's
    amplitude at its true distance) plus ``glint_phasors``, then the camera's reading as
    ``render_frame`` forms it (gray ``A + ambient_gray_fraction B`` with shot noise,
    distance noise ``sensor.distance_sigma_mm``, the wrap at ``sensor.reading_range_mm``,
    saturation at the camera's full scale and the amplitude floor: NaN distance), with
    fresh noise from ``rng`` (required when ``sensor.noise``). Other pixels are kept.
    ``surface_id`` stays the scene's (a glint is not a surface). ``ValueError`` for a
    sensor with systematic range errors (not applied here).
    """
    if sensor.systematic is not None:
        raise ValueError("render_glints renders for a sensor without systematic range errors")
    if sensor.noise and rng is None:
        raise ValueError("a seeded numpy Generator is required when sensor.noise is True")
    g_re, g_im, g_range = glint_phasors(glints, camera, sensor)
    lit = np.isfinite(g_range)
    if not lit.any():
        return frame
    old_d = frame.true_distance_mm[lit]
    seen = np.isfinite(old_d) & (frame.amplitude[lit] > 0)
    phase = np.where(seen, old_d, 0.0) / sensor.mm_per_radian
    a0 = np.where(seen, frame.amplitude[lit], 0.0)
    re = a0 * np.cos(phase) + g_re[lit]
    im = a0 * np.sin(phase) + g_im[lit]
    amp = np.hypot(re, im)
    # the truth before the wrap: the period next to what the pixel saw (or the glint)
    ref = np.where(seen, old_d, g_range[lit])
    u = sensor.unambiguous_range_mm
    d = np.mod(np.arctan2(im, re), 2 * np.pi) * sensor.mm_per_radian
    true_d = ref + (np.mod(d - ref + u / 2, u) - u / 2)

    b = frame.background[lit]
    gray = amp + sensor.ambient_gray_fraction * b
    dist = true_d.copy()
    if sensor.noise:
        assert rng is not None
        dist = dist + sensor.distance_sigma_mm(amp, b) * rng.standard_normal(len(amp))
        gray = gray + np.sqrt(amp + b) * rng.standard_normal(len(amp))
    dist = np.mod(dist, sensor.reading_range_mm)
    full_scale, scale = camera.full_scale_counts, camera.count_scale
    saturated = (amp + b) * scale >= full_scale
    dist[saturated | (amp < sensor.min_amplitude_counts)] = np.nan
    gray = np.clip(np.rint(gray * scale), 0, full_scale)
    gray[saturated] = full_scale

    gray_img, dist_img = frame.gray.copy(), frame.distance_mm.copy()
    amp_img, true_img = frame.amplitude.copy(), frame.true_distance_mm.copy()
    gray_img[lit], dist_img[lit] = gray.astype(np.uint16), dist.astype(np.float32)
    amp_img[lit], true_img[lit] = amp, true_d
    return replace(
        frame,
        gray=gray_img,
        distance_mm=dist_img,
        amplitude=amp_img,
        true_distance_mm=true_img,
    )
