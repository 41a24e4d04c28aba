"""Rendering of a ToF frame pair (gray, radial distance) from a posed scene.

Physics (docs/architecture.md §6), per pixel:

1. Ray casting at the pixel centre finds the surface; pixels whose 3 x 3 neighbourhood
   holds more than one surface are supersampled on an S x S grid.
2. Each sample returns a phasor ``a * exp(j * 4 pi f d / c)``: Lambertian surfaces give
   ``a = K T rho cos(i) / d^2``, retro-reflectors ``a = K T G cos(beta)^4 / d^2`` (entrance
   angle fall-off). The pixel's phasor is the mean of its samples, so a pixel on an edge
   measures a distance between the two surfaces (a flying pixel), weighted by amplitude.
3. Optional optical blur mixes phasors of neighbouring pixels (Gaussian PSF).
4. Ambient light gives a background ``B = K_amb * lux * T * rho_diffuse`` (counts).
5. Noise: distance ``sigma_d = c / (4 pi f) * sqrt(A + B) / (demod_gain * A)`` (the
   standard CW-ToF model), gray shot noise ``sqrt(A + B)`` counts.
6. The measured distance wraps at the unambiguous range ``c / (2 f)`` (or at the
   unwrapped range of a multi-frequency sensor). Pixels with ``A + B`` at the camera's
   full scale are saturated (gray = full scale, 4095 on the EPC660; distance NaN);
   pixels with ``A < min_amplitude`` are invalid (distance NaN).

The gray image is the active amplitude plus the residual ambient offset left by the
sensor's background suppression (``ambient_gray_fraction * B``), quantised to counts.
The radiometry is in counts of the reference 12-bit EPC660; a camera of another count
scale (``CameraModel.count_scale``: a 16-bit sensor, say) gets its gray image scaled by
it, its saturation at its own full scale, and its auto exposure aims at the same
fraction of its full scale. ``sensor_for_camera`` gives a sensor the camera's modulation
frequency and range: with both, the simulator renders any camera profile
(``tofpose.core.camera_profiles``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import cv2
import numpy as np

from tofpose.core.camera import CameraModel
from tofpose.core.geometry import RigidTransform
from tofpose.core.tof import SPEED_OF_LIGHT_MM_S
from tofpose.sim.scene import FIRST_DISC, NO_HIT, PLATE, WALL, SceneInCamera, TargetScene
from tofpose.sim.systematic import SystematicErrors

#: the EPC660's 12-bit full scale: the auto exposure's reference level (a camera of
#: another count scale: ``reference_full_scale``)
FULL_SCALE_COUNTS = 4095

AMBIENT_NORMAL_LUX = 1000.0
AMBIENT_HIGH_LUX = 10000.0


@dataclass(frozen=True)
class SensorModel:
    """Radiometric and noise parameters of the simulated ToF sensor.

    Attributes
    ----------
    modulation_frequency_hz : float
        CW modulation frequency; unambiguous range is c / (2 f). 6 MHz -> 24.98 m.
    integration_time_us : float
        Exposure; ignored when ``auto_exposure`` is set and a target distance is known.
    auto_exposure : bool
        Choose the integration time so that a face-on reflector at the target's distance
        reaches ``auto_exposure_fill`` of full scale (like the camera's auto mode).
    integration_limits_us : (min, max)
    ambient_lux : float
        Ambient illuminance (1000 normal, 10000 high, §2.1).
    illumination_gain : float
        K, counts * mm^2 / us for a white Lambertian (rho = 1) surface face-on.
    retro_gain : float
        G, retro-reflector return relative to a white Lambertian surface.
    ambient_gain : float
        K_amb, counts / (lux * us) for rho = 1.
    ambient_gray_fraction : float
        Part of B that remains in the gray image after background suppression.
    demod_gain : float
        Scales distance noise (demodulation contrast and electrons per count).
    min_amplitude_counts : float
        Below this amplitude the distance is invalid.
    supersampling : int
        S: edge pixels are sampled on an S x S grid (1 = pixel centres only).
    blur_sigma_px : float
        PSF core sigma in pixels (0 = no blur). Real ToF lenses blur by 0.3-1.5 px
        (defocus over the working range, a wide aperture for the weak return).
    psf_halo_fraction, psf_halo_scale : a measured lens's PSF is not one Gaussian: a
        core of sigma ``blur_sigma_px`` and a halo (scattered light in the glass and on
        the sensor) carrying ``psf_halo_fraction`` of the energy with ``psf_halo_scale``
        times the core's sigma (0: a Gaussian PSF).
    noise : bool
        False renders the noiseless expectation.
    systematic : SystematicErrors or None
        The systematic range errors of a real, uncalibrated camera (None: the ideal
        sensor; ``tofpose.sim.systematic``).
    motion_artefacts : bool
        While the scene moves, render each of the four phase sub-frames at its own time
        (``combine_subframes``; the bench and the live simulator pass the poses).
    subframe_readout_us : float
        Readout between sub-frames; the sub-frame period is exposure + readout.
    unwrapped_range_mm : float or None
        Where the distance wraps on a sensor that unwraps several modulation
        frequencies (``CameraModel.unwrapped_range_mm``); None: ``c / (2 f)``.
    """

    modulation_frequency_hz: float = 6.0e6
    integration_time_us: float = 500.0
    auto_exposure: bool = True
    auto_exposure_fill: float = 0.6
    integration_limits_us: tuple[float, float] = (10.0, 4000.0)
    ambient_lux: float = AMBIENT_NORMAL_LUX
    illumination_gain: float = 5.0e5
    retro_gain: float = 40.0
    ambient_gain: float = 3.0e-5
    ambient_gray_fraction: float = 0.05
    demod_gain: float = 20.0
    min_amplitude_counts: float = 4.0
    supersampling: int = 4
    blur_sigma_px: float = 0.0
    psf_halo_fraction: float = 0.0
    psf_halo_scale: float = 4.0
    noise: bool = True
    systematic: SystematicErrors | None = None
    motion_artefacts: bool = True
    subframe_readout_us: float = 1500.0
    unwrapped_range_mm: float | None = None

    def __post_init__(self) -> None:
        if self.modulation_frequency_hz <= 0:
            raise ValueError("modulation_frequency_hz must be positive")
        if self.unwrapped_range_mm is not None and not self.unwrapped_range_mm > 0:
            raise ValueError(f"unwrapped_range_mm must be positive, got {self.unwrapped_range_mm}")
        if self.supersampling < 1:
            raise ValueError("supersampling must be >= 1")
        lo, hi = self.integration_limits_us
        if not 0 < lo <= hi:
            raise ValueError(f"integration_limits_us must satisfy 0 < min <= max, got {lo}, {hi}")

    @property
    def unambiguous_range_mm(self) -> float:
        """c / (2 f_mod) in mm."""
        return SPEED_OF_LIGHT_MM_S / (2.0 * self.modulation_frequency_hz)

    @property
    def reading_range_mm(self) -> float:
        """Where the distance the camera reads wraps, mm: ``unwrapped_range_mm`` when
        set, else the unambiguous range."""
        if self.unwrapped_range_mm is not None:
            return self.unwrapped_range_mm
        return self.unambiguous_range_mm

    @property
    def mm_per_radian(self) -> float:
        """c / (4 pi f_mod): distance per radian of phase, mm."""
        return SPEED_OF_LIGHT_MM_S / (4.0 * np.pi * self.modulation_frequency_hz)

    def distance_sigma_mm(self, amplitude: np.ndarray, background: np.ndarray) -> np.ndarray:
        """CW-ToF distance noise ``c/(4 pi f) sqrt(A + B) / (demod_gain A)``, mm."""
        a = np.maximum(np.asarray(amplitude, float), 1e-9)
        return self.mm_per_radian * np.sqrt(a + background) / (self.demod_gain * a)

    def exposure_for(
        self, distance_mm: float, *, full_scale_counts: float = FULL_SCALE_COUNTS
    ) -> float:
        """Integration time (us) used at a target distance under ``auto_exposure``:
        a face-on reflector there reaches ``auto_exposure_fill`` of ``full_scale_counts``
        (in reference counts: ``reference_full_scale(camera)``)."""
        if not self.auto_exposure:
            return self.integration_time_us
        peak_per_us = self.illumination_gain * self.retro_gain / distance_mm**2
        t = self.auto_exposure_fill * full_scale_counts / peak_per_us
        lo, hi = self.integration_limits_us
        return float(np.clip(t, lo, hi))

    def subframe_period_s(
        self, distance_mm: float, *, full_scale_counts: float = FULL_SCALE_COUNTS
    ) -> float:
        """Time from one phase sub-frame to the next: exposure plus readout, s."""
        t_int = self.exposure_for(distance_mm, full_scale_counts=full_scale_counts)
        return (t_int + self.subframe_readout_us) * 1e-6


def reference_full_scale(camera: CameraModel) -> float:
    """The camera's full scale in the simulator's reference (EPC660) counts:
    ``full_scale_counts / count_scale``."""
    return camera.full_scale_counts / camera.count_scale


def sensor_for_camera(sensor: SensorModel, camera: CameraModel) -> SensorModel:
    """``sensor`` with the camera's modulation frequency and unwrapped range: the
    simulated sensor of a camera profile (its distance noise, flying pixels and wrap
    follow the device's frequency)."""
    return replace(
        sensor,
        modulation_frequency_hz=camera.modulation_frequency_hz,
        unwrapped_range_mm=camera.unwrapped_range_mm,
    )


@dataclass(frozen=True)
class RenderedFrame:
    """A rendered frame pair and its noiseless truth.

    gray : ndarray (H, W) uint16; distance_mm : ndarray (H, W) float32 (NaN invalid);
    amplitude, background : ndarray (H, W) float64 noiseless A and B in counts;
    true_distance_mm : ndarray (H, W) float64, the noiseless phasor distance before wrap;
    surface_id : ndarray (H, W) uint8, surface at the pixel centre;
    integration_time_us : float.
    """

    gray: np.ndarray
    distance_mm: np.ndarray
    amplitude: np.ndarray
    background: np.ndarray
    true_distance_mm: np.ndarray
    surface_id: np.ndarray
    integration_time_us: float


def _sample_returns(
    sc: SceneInCamera, bearings: np.ndarray, sensor: SensorModel, t_int_us: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per-ray amplitude A, ambient B (counts), distance (mm) and surface id, shape (M,)."""
    d, sid, cos_inc = sc.raycast(bearings)
    scene = sc.scene
    behind = None
    if scene.background is not None:
        # the real scene where it is nearer than the target or the ray misses it
        bd, b_rho = scene.background.along(bearings)
        behind = bd < np.where(np.isfinite(d) & (sid != NO_HIT), d, np.inf)
        d, sid, cos_inc = d.copy(), sid.copy(), cos_inc.copy()
        d[behind], sid[behind], cos_inc[behind] = bd[behind], WALL, 1.0
    refl = np.zeros(len(d))
    diffuse = np.zeros(len(d))
    refl[sid == PLATE] = scene.plate_reflectance
    diffuse[sid == PLATE] = scene.plate_reflectance
    refl[sid == WALL] = scene.wall_reflectance
    diffuse[sid == WALL] = scene.wall_reflectance
    if behind is not None:
        refl[behind] = b_rho[behind]
        diffuse[behind] = np.minimum(b_rho[behind], 1.0)
    disc = sid >= FIRST_DISC
    if np.any(disc):
        k = sid[disc].astype(int) - FIRST_DISC
        refl[disc] = (
            sensor.retro_gain * sc.disc_gains[k] * cos_inc[disc] ** scene.retro_falloff_exponent
        )
        diffuse[disc] = scene.reflector_diffuse_reflectance
    hit = sid != NO_HIT
    a = np.zeros(len(d))
    a[hit] = sensor.illumination_gain * t_int_us * refl[hit] * cos_inc[hit] / d[hit] ** 2
    b = sensor.ambient_gain * sensor.ambient_lux * t_int_us * diffuse
    return a, b, d, sid


def _with_systematic_errors(
    dist: np.ndarray,
    re: np.ndarray,
    im: np.ndarray,
    amp: np.ndarray,
    sensor: SensorModel,
    e: SystematicErrors,
    time_s: float,
) -> np.ndarray:
    """Distances (H, W) as an uncalibrated camera reads them (``sensor.systematic`` =
    ``e``): lens scatter mixes the phasors, then cyclic, amplitude-related, per-pixel,
    drift and zero-offset errors add."""
    if e.scatter_fraction:
        re_s, im_s = e.scatter(re, im)
        phase = np.mod(np.arctan2(im_s, re_s), 2 * np.pi) * sensor.mm_per_radian
        # the scattered phasor's distance, unwrapped next to the true one
        u = sensor.unambiguous_range_mm
        dist = dist + (np.mod(phase - dist + u / 2, u) - u / 2)
    h, w = dist.shape
    return (
        dist
        + e.cyclic_mm(dist, sensor.unambiguous_range_mm)
        + e.amplitude_mm(amp)
        + e.pixel_offsets_mm(h, w)
        + e.drift_mm(time_s)
        + e.offset_mm
    )


def _subpixel_bearings(camera: CameraModel, uv: np.ndarray, s: int) -> np.ndarray:
    """Bearings of an S x S grid inside each pixel; uv (P, 2) -> (P * S * S, 3)."""
    offs = (np.arange(s) + 0.5) / s - 0.5
    ox, oy = np.meshgrid(offs, offs)
    grid = np.column_stack((ox.ravel(), oy.ravel()))
    pts = (uv[:, None, :] + grid[None]).reshape(-1, 2)
    return camera.bearings(pts)


def _phasor_images(
    camera: CameraModel,
    scene: TargetScene,
    T_camera_target: RigidTransform,
    sensor: SensorModel,
    t_int: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Noiseless phasor of one pose: (re, im, background, surface id, pixel-centre
    distance, mixed-surface mask), each (H, W)."""
    sc = scene.in_camera(T_camera_target)
    h, w = camera.height, camera.width

    bearings = camera.pixel_bearings().reshape(-1, 3)
    a, b, d, sid = _sample_returns(sc, bearings, sensor, t_int)
    sid_img = sid.reshape(h, w)
    phasor_re = np.zeros(h * w)
    phasor_im = np.zeros(h * w)
    hit = np.isfinite(d)
    phase = np.zeros(h * w)
    phase[hit] = d[hit] / sensor.mm_per_radian
    phasor_re[hit] = a[hit] * np.cos(phase[hit])
    phasor_im[hit] = a[hit] * np.sin(phase[hit])

    kernel = np.ones((3, 3), np.uint8)
    mixed = cv2.dilate(sid_img, kernel) != cv2.erode(sid_img, kernel)
    mixed |= _disc_rims(camera, sc)
    if sensor.supersampling > 1:
        idx = np.flatnonzero(mixed)
        if len(idx):
            s = sensor.supersampling
            uv = np.column_stack((idx % w, idx // w)).astype(np.float64)
            sb = _subpixel_bearings(camera, uv, s)
            sa, sbk, sd, _ = _sample_returns(sc, sb, sensor, t_int)
            sh = np.isfinite(sd)
            sph = np.where(sh, sd, 0.0) / sensor.mm_per_radian
            re = np.where(sh, sa * np.cos(sph), 0.0).reshape(-1, s * s).mean(axis=1)
            im = np.where(sh, sa * np.sin(sph), 0.0).reshape(-1, s * s).mean(axis=1)
            phasor_re[idx], phasor_im[idx] = re, im
            b[idx] = sbk.reshape(-1, s * s).mean(axis=1)

    re_img, im_img, b_img = (x.reshape(h, w) for x in (phasor_re, phasor_im, b))
    return re_img, im_img, b_img, sid_img, d.reshape(h, w), mixed


def _disc_rims(camera: CameraModel, sc: SceneInCamera) -> np.ndarray:
    """(H, W) bool: the pixels a disc can cover in part, found from its geometry (the
    annulus between the projected disc's minor and major radius, 1.5 px each way).
    Surface changes between pixel centres miss a disc of 1-2 px that covers no centre or
    one: without these pixels such a marker would be rendered by its centre samples
    alone, or not at all, instead of by the area it covers."""
    h, w = camera.height, camera.width
    rims = np.zeros((h, w), bool)
    front = sc.disc_centres[:, 2] > 0
    if not front.any():
        return rims
    centres = sc.disc_centres[front]
    uv = camera.project(centres)
    dist = np.linalg.norm(centres, axis=1)
    cos_view = np.abs(np.einsum("ij,ij->i", sc.disc_normals[front], centres)) / dist
    r_major = sc.disc_radii[front] * camera.fx / centres[:, 2]
    r_minor = r_major * cos_view
    vv, uu = np.mgrid[0:h, 0:w]
    for (u, v), lo, hi in zip(uv, r_minor - 1.5, r_major + 1.5, strict=True):
        u0, u1 = int(max(np.floor(u - hi), 0)), int(min(np.ceil(u + hi) + 1, w))
        v0, v1 = int(max(np.floor(v - hi), 0)), int(min(np.ceil(v + hi) + 1, h))
        if u0 >= u1 or v0 >= v1:
            continue
        d = np.hypot(uu[v0:v1, u0:u1] - u, vv[v0:v1, u0:u1] - v)
        rims[v0:v1, u0:u1] |= (d >= lo) & (d <= hi)
    return rims


def _psf(image: np.ndarray, sensor: SensorModel) -> np.ndarray:
    """The image (H, W) through the lens's PSF: a Gaussian core of ``blur_sigma_px`` plus
    a halo of ``psf_halo_fraction`` of the energy, ``psf_halo_scale`` times as wide
    (applied to the phasor's parts: blur mixes returns as a real lens does)."""

    def gaussian(x, sigma):
        ks = 2 * int(np.ceil(3 * sigma)) + 1
        return cv2.GaussianBlur(x, (ks, ks), sigma)

    core = gaussian(image, sensor.blur_sigma_px)
    if sensor.psf_halo_fraction <= 0:
        return core
    halo = gaussian(image, sensor.blur_sigma_px * sensor.psf_halo_scale)
    return (1.0 - sensor.psf_halo_fraction) * core + sensor.psf_halo_fraction * halo


def _same_pose(a: RigidTransform, b: RigidTransform) -> bool:
    return np.array_equal(a.R, b.R) and np.array_equal(a.t_mm, b.t_mm)


def combine_subframes(
    phasors: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]],
    background_fraction: float = 1.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The phasor a 4-phase CW-ToF pixel measures when its four correlation samples
    (0, 90, 180, 270 deg) see different scenes (motion artefacts).

    phasors : four (re, im, background) image triples, one per sub-frame, shape (H, W).
    Sample k is ``c_k = B_k + a_k cos(phi_k - k pi / 2)``; the camera forms
    ``((c0 - c2) + j (c1 - c3)) / 2``, so the real part comes from sub-frames 0 and 2 and
    the imaginary part from 1 and 3; background differences enter scaled by
    ``background_fraction`` (the part the sensor's background suppression leaves). Four
    equal sub-frames give back the static phasor exactly. Returns (re, im, mean
    background).
    """
    if len(phasors) != 4:
        raise ValueError(f"a 4-phase frame has 4 sub-frames, got {len(phasors)}")
    (re0, _, b0), (_, im1, b1), (re2, _, b2), (_, im3, b3) = phasors
    re = 0.5 * (re0 + re2) + 0.5 * background_fraction * (b0 - b2)
    im = 0.5 * (im1 + im3) + 0.5 * background_fraction * (b1 - b3)
    return re, im, 0.25 * (b0 + b1 + b2 + b3)


def render_frame(
    camera: CameraModel,
    scene: TargetScene,
    T_camera_target: RigidTransform,
    sensor: SensorModel,
    rng: np.random.Generator | None = None,
    time_s: float = 0.0,
    subframe_poses: Sequence[RigidTransform] | None = None,
) -> RenderedFrame:
    """Render one (gray, distance) frame pair.

    Parameters
    ----------
    camera : CameraModel
    scene : TargetScene
    T_camera_target : RigidTransform
        True pose of the target in the camera frame (mm).
    sensor : SensorModel
    rng : numpy Generator, required when ``sensor.noise`` is True.
    time_s : time since the camera was switched on (temperature drift), s.
    subframe_poses : optional four poses of the target at the times of the four phase
        sub-frames (``combine_subframes``): motion artefacts while the scene moves.
        ``T_camera_target`` then sets the exposure and the truth's surface map.

    Returns
    -------
    RenderedFrame
    """
    noise_rng = None  # rng when the sensor adds noise
    if sensor.noise:
        if rng is None:
            raise ValueError("a seeded numpy Generator is required when sensor.noise is True")
        noise_rng = rng
    h, w = camera.height, camera.width
    t_int = sensor.exposure_for(
        float(np.linalg.norm(T_camera_target.t_mm)),
        full_scale_counts=reference_full_scale(camera),
    )
    static = _phasor_images(camera, scene, T_camera_target, sensor, t_int)
    re_img, im_img, b_img, sid_img, d_img, mixed = static
    moved = np.zeros_like(mixed)  # pixels whose surface changes between sub-frames
    if subframe_poses is not None:
        # the four phase samples see the scene at their own times (a slewing table); a
        # sub-frame at the frame's own pose is not rendered again (with the stamp at the
        # acquisition's middle none is: a slewing frame is five ray casts)
        subs = [
            static
            if _same_pose(T, T_camera_target)
            else _phasor_images(camera, scene, T, sensor, t_int)
            for T in subframe_poses
        ]
        re_img, im_img, b_img = combine_subframes(
            [x[:3] for x in subs], sensor.ambient_gray_fraction
        )
        for x in subs:
            moved |= x[3] != sid_img
    if sensor.blur_sigma_px > 0:
        re_img, im_img, b_img = (_psf(x, sensor) for x in (re_img, im_img, b_img))
    amp = np.hypot(re_img, im_img)
    true_d = np.mod(np.arctan2(im_img, re_img), 2 * np.pi) * sensor.mm_per_radian
    # The phasor angle is already wrapped; keep the unwrapped truth for tests where we can.
    unwrapped = np.where(sid_img != NO_HIT, d_img, np.nan)
    if sensor.unwrapped_range_mm is not None:
        # a multi-frequency sensor unwraps its phase: a mixed pixel reads the period
        # next to its centre's surface (or the target's, where the centre sees nothing)
        u = sensor.unambiguous_range_mm
        ref = np.where(np.isfinite(unwrapped), unwrapped, np.linalg.norm(T_camera_target.t_mm))
        true_d = ref + (np.mod(true_d - ref + u / 2, u) - u / 2)
    from_mixture = mixed if sensor.supersampling > 1 else np.zeros_like(mixed)
    if sensor.blur_sigma_px > 0:
        from_mixture = np.ones_like(mixed)
    from_mixture = from_mixture | moved
    true_distance = np.where(from_mixture, true_d, unwrapped)

    dist = true_distance.copy()
    sys_err = sensor.systematic
    if sys_err is not None:
        dist = _with_systematic_errors(dist, re_img, im_img, amp, sensor, sys_err, time_s)
    gray = amp + sensor.ambient_gray_fraction * b_img
    if noise_rng is not None:
        sigma = sensor.distance_sigma_mm(amp, b_img)
        dist = dist + sigma * noise_rng.standard_normal((h, w))
        gray = gray + np.sqrt(amp + b_img) * noise_rng.standard_normal((h, w))
    dist = np.mod(dist, sensor.reading_range_mm)
    full_scale = camera.full_scale_counts  # the camera's clip level (4095: 12 bits)
    scale = camera.count_scale  # the camera's counts per reference count
    saturated = (amp + b_img) * scale >= full_scale
    invalid = saturated | (amp < sensor.min_amplitude_counts)
    dist[invalid] = np.nan
    gray = np.clip(np.rint(gray * scale), 0, full_scale)
    gray[saturated] = full_scale
    return RenderedFrame(
        gray=gray.astype(np.uint16),
        distance_mm=dist.astype(np.float32),
        amplitude=amp,
        background=b_img,
        true_distance_mm=true_distance,
        surface_id=sid_img,
        integration_time_us=t_int,
    )
