"""Forward model of the reflectors' pixel-integrated images (gray and distance).

Each disc k (catalog centre ``x_k`` and radius ``r_k``, on the target's plane, normal the
target's z axis) is, at a pose ``(R, t)``, the disc of centre ``c = R x_k + t`` and normal
``n = R e_z`` in the camera frame. A ray of unit bearing ``b`` meets its plane at range
``lam = (n . c) / (n . b)`` (the radial distance a ToF pixel measures) and at in-plane
radius ``rho = |lam b - c|``. The image-space signed distance to the rim is
``s = (r_k - rho) / |grad_uv rho|`` px (positive inside), with the outward normal
``grad_uv rho / |grad_uv rho|``; both come from the bearing's derivatives over the pixel
coordinates, so lens distortion enters only through ``CameraModel.bearings``.

A sub-cell (side ``1 / S`` px) cut by a straight rim of normal ``(g_u, g_v)`` at signed
distance ``s`` is covered by the area fraction ``box_coverage(s, a, b)`` with ``a = |g_u|
h``, ``b = |g_v| h``, ``h = 1 / (2 S)``: the exact integral of a half-plane over a square
(a piecewise quadratic, continuous with its first derivative). The pixel's coverage is
the mean over its S x S sub-cells; pixels further than ``BAND_PX`` from the rim are
wholly inside or outside and use their centre ray alone.

The pixel's phasor is the mean of its sub-cells' returns, as a CW-ToF pixel averages
them: the disc's part ``gain_k * mean(cov_s exp(j phi_s))`` with ``phi_s = lam_s /
mm_per_radian``, the surround's ``level * (1 - coverage) exp(j phi_plate)`` (the plate's
plane along the pixel's centre ray). The gray model is the sum of the parts' amplitudes
(the phase difference of disc and plate is hundredths of a radian); the distance model
is the mixed phasor's angle.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from tofpose.core.camera import CameraModel
from tofpose.core.catalog import Catalog
from tofpose.stages.pixelfit.constants import (
    BAND_PX,
    RIM_POINTS,
    SUBSAMPLES,
    UNMATCHED_MARGIN_PX,
    WINDOW_PAD_PX,
)
from tofpose.stages.pixelfit.kernels import derivatives as derivatives_kernel
from tofpose.stages.pixelfit.kernels import images as images_kernel
from tofpose.stages.pixelfit.records import DiscRecord, WindowRays
from tofpose.stages.pixelfit.reference import derivatives as derivatives_reference
from tofpose.stages.pixelfit.reference import images as images_reference

#: step of the bearing's derivative over the pixel coordinates, px
BEARING_STEP_PX = 1e-3


@dataclass(frozen=True)
class Discs:
    """The catalog discs the fit models.

    ids : ndarray of shape (K,), catalog ids; centres_mm : ndarray of shape (K, 3), target
    frame; radii_mm : ndarray of shape (K,).
    """

    ids: np.ndarray
    centres_mm: np.ndarray
    radii_mm: np.ndarray

    @staticmethod
    def from_catalog(catalog: Catalog, catalog_ids: Sequence[int]) -> Discs:
        """The discs of ``catalog_ids``, in that order. Raises ``ValueError`` for an id the
        catalog does not hold or one given twice."""
        ids = [int(i) for i in catalog_ids]
        if len(set(ids)) != len(ids):
            raise ValueError(f"catalog_ids holds an id twice: {ids}")
        where = {int(i): j for j, i in enumerate(catalog.ids)}
        missing = [i for i in ids if i not in where]
        if missing:
            raise ValueError(f"catalog_ids not in the catalog: {missing}")
        rows = [where[i] for i in ids]
        return Discs(
            ids=np.asarray(ids, int),
            centres_mm=catalog.positions_mm[rows].astype(float),
            radii_mm=catalog.diameters_mm[rows].astype(float) / 2,
        )


@dataclass(frozen=True)
class Windows:
    """The pixels the fit uses: the union of the windows around each disc's predicted
    ellipse, with the bearings of their centres and sub-cells.

    rows, cols : ndarray of shape (P,) int; gray : (P,) counts; distance_mm : (P,) float
    (NaN invalid); owner : (P,) int, the disc (0..K-1) whose surround level the pixel
    sees (the nearest predicted centre); bearings, dbdu, dbdv : (P, 3), the centre ray and
    its derivatives over u and v (per px); sample_bearings, sample_dbdu, sample_dbdv :
    (P, S * S, 3), the same for the sub-cell centres; near : K index arrays into the
    pixels, where each disc's coverage is evaluated; subsamples : S; plate_fraction :
    (P,) the part of each pixel the target's plate fills at the windows' pose
    (``plate_fraction``; all 1 when the plate's size is not given).
    """

    rows: np.ndarray
    cols: np.ndarray
    gray: np.ndarray
    distance_mm: np.ndarray
    owner: np.ndarray
    bearings: np.ndarray
    dbdu: np.ndarray
    dbdv: np.ndarray
    sample_bearings: np.ndarray
    sample_dbdu: np.ndarray
    sample_dbdv: np.ndarray
    near: tuple[np.ndarray, ...]
    subsamples: int
    plate_fraction: np.ndarray

    @property
    def near_flat(self) -> tuple[np.ndarray, np.ndarray]:
        """``near`` as one index array and the K + 1 offsets of each disc's part in it
        (the compiled kernel's form)."""
        index = np.concatenate([*self.near, np.zeros(0, np.int64)]).astype(np.int64)
        start = np.concatenate([[0], np.cumsum([len(x) for x in self.near])]).astype(np.int64)
        return index, start

    @property
    def n_pixels(self) -> int:
        return len(self.rows)


@dataclass(frozen=True)
class DiscImages:
    """The discs' images at one pose, over the window pixels.

    coverage : ndarray of shape (K, P), the part of each pixel each disc covers;
    phasor : (K, P) complex, the pixel mean of ``coverage_s exp(j (lam_s - ref) /
    mm_per_radian)`` (the disc's return per unit gain); plate_phasor : (P,) complex, the
    plate's unit phasor along the centre ray, same reference.
    """

    coverage: np.ndarray
    phasor: np.ndarray
    plate_phasor: np.ndarray


def predicted_rims(
    camera: CameraModel, discs_R: np.ndarray, discs_t_mm: np.ndarray, discs: Discs
) -> np.ndarray:
    """Each disc's projected rim (K, RIM_POINTS, 2) px at the pose ``(R, t)``."""
    theta = np.linspace(0.0, 2 * np.pi, RIM_POINTS, endpoint=False)
    ring = np.column_stack([np.cos(theta), np.sin(theta), np.zeros_like(theta)])
    pts = discs.centres_mm[:, None, :] + discs.radii_mm[:, None, None] * ring[None]
    cam_pts = pts.reshape(-1, 3) @ discs_R.T + discs_t_mm
    return camera.project(cam_pts).reshape(len(discs.ids), RIM_POINTS, 2)


def _bearings_with_derivatives(
    camera: CameraModel, uv: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit bearings (N, 3) of pixels ``uv`` (N, 2) and their central-difference
    derivatives over u and v (N, 3) each, per px."""
    h = BEARING_STEP_PX
    du = np.array([h, 0.0])
    dv = np.array([0.0, h])
    stack = np.concatenate([uv, uv + du, uv - du, uv + dv, uv - dv])
    e = camera.bearings(stack).reshape(5, len(uv), 3)
    return e[0], (e[1] - e[2]) / (2 * h), (e[3] - e[4]) / (2 * h)


def build_windows(
    gray: np.ndarray,
    distance_mm: np.ndarray,
    camera: CameraModel,
    discs: Discs,
    R: np.ndarray,
    t_mm: np.ndarray,
    *,
    others: Discs | None = None,
    pad_px: int = WINDOW_PAD_PX,
    subsamples: int = SUBSAMPLES,
    plate_size_mm: tuple[float, float] | None = None,
) -> Windows:
    """The windows around each disc's ellipse predicted at the pose ``(R, t_mm)``: its
    bounding box plus ``pad_px``, clipped to the image; pixels near the predicted image of
    a disc in ``others`` (catalog discs not fitted) are left out; ``plate_size_mm``
    (width, height) of the target's plate, centred on its origin in its z = 0 plane: the
    part of each pixel it fills (``plate_fraction``)."""
    h, w = camera.height, camera.width
    rims = predicted_rims(camera, R, t_mm, discs)
    centres = rims.mean(axis=1)  # (K, 2)
    taken = np.zeros((h, w), bool)
    boxes = []
    for rim in rims:
        u0 = max(int(np.floor(rim[:, 0].min())) - pad_px, 0)
        u1 = min(int(np.ceil(rim[:, 0].max())) + pad_px + 1, w)
        v0 = max(int(np.floor(rim[:, 1].min())) - pad_px, 0)
        v1 = min(int(np.ceil(rim[:, 1].max())) + pad_px + 1, h)
        boxes.append((u0, u1, v0, v1))
        if u0 < u1 and v0 < v1:
            taken[v0:v1, u0:u1] = True
    rows, cols = np.nonzero(taken)
    if others is not None and len(others.ids):
        keep = np.ones(len(rows), bool)
        for rim in predicted_rims(camera, R, t_mm, others):
            c = rim.mean(axis=0)
            reach = np.max(np.hypot(*(rim - c).T)) + UNMATCHED_MARGIN_PX
            keep &= np.hypot(cols - c[0], rows - c[1]) > reach
        rows, cols = rows[keep], cols[keep]
    uv = np.column_stack([cols, rows]).astype(float)
    # owner: the nearest predicted centre among the windows holding the pixel
    d2 = np.full((len(rows), len(boxes)), np.inf)
    near = []
    for k, (u0, u1, v0, v1) in enumerate(boxes):
        inside = (cols >= u0) & (cols < u1) & (rows >= v0) & (rows < v1)
        d2[inside, k] = np.sum((uv[inside] - centres[k]) ** 2, axis=1)
        near.append(np.flatnonzero(inside))
    owner = np.argmin(d2, axis=1) if len(rows) else np.zeros(0, int)
    b, bu, bv = _bearings_with_derivatives(camera, uv)
    s = subsamples
    offs = (np.arange(s) + 0.5) / s - 0.5
    ox, oy = np.meshgrid(offs, offs)
    grid = np.column_stack([ox.ravel(), oy.ravel()])
    suv = (uv[:, None, :] + grid[None]).reshape(-1, 2)
    sb = camera.bearings(suv).reshape(len(uv), s * s, 3)
    # a sub-cell's bearing derivatives are its pixel's: they scale the rim's signed
    # distance to px and set the sub-cell's box half-widths (``_rim_point``), and change
    # across a pixel by ~offset/f of themselves, to first order in the sub-cell's
    # offset: their mean over the sub-cells is the pixel's, and the coverage moves by
    # the second order, up to 8e-5 of a pixel at 1 m (test_model.py bounds it at 1e-4;
    # a rim pixel's shot noise there is ~2e-2 of its coverage); the bearings then cost
    # (S^2 + 5) P evaluations instead of 5 (S^2 + 1) P
    sbu = np.repeat(bu[:, None, :], s * s, axis=1)
    sbv = np.repeat(bv[:, None, :], s * s, axis=1)
    return Windows(
        rows=rows,
        cols=cols,
        gray=gray[rows, cols].astype(float),
        distance_mm=distance_mm[rows, cols].astype(float),
        owner=owner,
        bearings=b,
        dbdu=bu,
        dbdv=bv,
        sample_bearings=sb,
        sample_dbdu=sbu,
        sample_dbdv=sbv,
        near=tuple(near),
        subsamples=s,
        plate_fraction=np.ones(len(uv))
        if plate_size_mm is None
        else plate_fraction(sb, R, t_mm, plate_size_mm),
    )


def plate_fraction(
    sample_bearings: np.ndarray,
    R: np.ndarray,
    t_mm: np.ndarray,
    plate_size_mm: tuple[float, float],
) -> np.ndarray:
    """The part of each pixel (P,) that the target's plate fills at the pose ``(R,
    t_mm)``: the share of its sub-cells' rays (``sample_bearings`` (P, S * S, 3)) that meet
    the plate's plane (target z = 0) inside its ``plate_size_mm`` rectangle, centred on
    the target's origin. Where the plate's edge crosses a disc's window, the surround
    beyond it (a wall, the room, nothing) is not the plate's level. Point samples: the
    edge's contrast is the plate's level less the beyond's, tens to hundreds of counts,
    so the 1 / (S * S) steps are a few counts at S = 4, under the surround's noise."""
    n = R[:, 2]
    nb = sample_bearings @ n
    lam = np.where(np.abs(nb) > 1e-12, (n @ t_mm) / np.where(nb == 0, 1.0, nb), -1.0)
    points = lam[..., None] * sample_bearings - t_mm  # (P, S * S, 3) from the origin
    x, y = points @ R[:, 0], points @ R[:, 1]
    half_w, half_h = plate_size_mm[0] / 2, plate_size_mm[1] / 2
    inside = (lam > 0) & (np.abs(x) <= half_w) & (np.abs(y) <= half_h)
    return inside.mean(axis=1)


def disc_images(
    R: np.ndarray,
    t_mm: np.ndarray,
    discs: Discs,
    win: Windows,
    *,
    mm_per_radian: float,
    reference_mm: float,
    compiled: bool = True,
    near_flat: tuple[np.ndarray, np.ndarray] | None = None,
) -> DiscImages:
    """The discs' coverage and phasors over the window pixels at the pose ``(R, t_mm)``
    (module docstring). Phases are taken relative to ``reference_mm``. ``compiled``: the
    compiled kernel (``kernels.images.disc_images``), else the same arithmetic in NumPy
    (``reference.images.disc_images``); ``near_flat``: ``win.near_flat`` when the caller
    keeps it."""
    n = R[:, 2]
    plate_range = (n @ t_mm) / (win.bearings @ n)
    plate = np.exp(1j * (plate_range - reference_mm) / mm_per_radian)
    rays = _window_rays(win, near_flat)
    images = images_kernel.disc_images if compiled else images_reference.disc_images
    coverage, phasor = images(
        np.ascontiguousarray(R, dtype=float),
        np.ascontiguousarray(t_mm, dtype=float),
        DiscRecord(centres_mm=discs.centres_mm, radii_mm=discs.radii_mm),
        rays,
        BAND_PX,
        float(mm_per_radian),
        float(reference_mm),
    )
    return DiscImages(coverage=coverage, phasor=phasor, plate_phasor=plate)


@dataclass(frozen=True)
class DiscImageDerivatives:
    """The discs' images' derivatives over the pose (a small left-multiplied rotation
    ``w``, rad, then the translation, mm: the last axis, 6), at the pose of the
    ``DiscImages`` they come with.

    coverage : ndarray of shape (K, P, 6); phasor : (K, P, 6) complex; plate_phasor :
    (P, 6) complex.
    """

    coverage: np.ndarray
    phasor: np.ndarray
    plate_phasor: np.ndarray


def _window_rays(win: Windows, near_flat: tuple[np.ndarray, np.ndarray] | None) -> WindowRays:
    index, start = win.near_flat if near_flat is None else near_flat
    return WindowRays(
        bearings=win.bearings,
        dbdu=win.dbdu,
        dbdv=win.dbdv,
        sample_bearings=win.sample_bearings,
        sample_dbdu=win.sample_dbdu,
        sample_dbdv=win.sample_dbdv,
        near_index=index,
        near_start=start,
    )


def disc_images_with_derivatives(
    R: np.ndarray,
    t_mm: np.ndarray,
    discs: Discs,
    win: Windows,
    *,
    mm_per_radian: float,
    reference_mm: float,
    compiled: bool = True,
    near_flat: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[DiscImages, DiscImageDerivatives]:
    """``disc_images`` and the images' analytic derivatives over the pose
    (``kernels.derivatives``' docstring gives the chain rule), in one call: the compiled
    kernel (``kernels.derivatives.disc_images_with_derivatives``), else the same
    arithmetic in NumPy (``reference.derivatives``). Arguments as ``disc_images``; the
    images equal ``disc_images``' to rounding. Dearer than ``disc_images`` (the chain
    rule on every rim sub-cell a disc reaches, and (K, P, 6) arrays to fill), so it is a
    kernel of its own rather than a flag: the fit calls it once an iteration, for the
    Jacobian, and ``disc_images`` for its trial steps, which need no derivatives."""
    images = (
        derivatives_kernel.disc_images_with_derivatives
        if compiled
        else derivatives_reference.disc_images_with_derivatives
    )
    coverage, phasor, plate, d_coverage, d_phasor, d_plate = images(
        np.ascontiguousarray(R, dtype=float),
        np.ascontiguousarray(t_mm, dtype=float),
        DiscRecord(centres_mm=discs.centres_mm, radii_mm=discs.radii_mm),
        _window_rays(win, near_flat),
        BAND_PX,
        float(mm_per_radian),
        float(reference_mm),
    )
    return (
        DiscImages(coverage=coverage, phasor=phasor, plate_phasor=plate),
        DiscImageDerivatives(coverage=d_coverage, phasor=d_phasor, plate_phasor=d_plate),
    )


@dataclass(frozen=True)
class Prediction:
    """The model's gray (P,) counts and distance (P,) mm over the window pixels, with the
    mixed phasor (P,) complex and the surround's share (P,) that the derivatives use."""

    gray: np.ndarray
    distance_mm: np.ndarray
    phasor: np.ndarray
    surround: np.ndarray


#: terms of a disc's gain over its image: 1, x, y, x^2, x y, y^2 (x, y: the pixel's
#: offset from the disc's predicted centre over its radius in px)
GAIN_TERMS = 6


def gain_basis(offsets_px: np.ndarray, radius_px: np.ndarray) -> np.ndarray:
    """The gain's basis (K, P, GAIN_TERMS) at the window pixels: ``offsets_px`` (K, P, 2)
    from each disc's predicted centre, ``radius_px`` (K,) its radius."""
    xy = offsets_px / np.maximum(radius_px, 1.0)[:, None, None]
    x, y = xy[..., 0], xy[..., 1]
    return np.stack([np.ones_like(x), x, y, x * x, x * y, y * y], axis=-1)


def pixel_gains(gains: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """Each disc's gain at each window pixel (K, P): ``gains`` (K, GAIN_TERMS) its
    coefficients over ``basis`` (K, P, GAIN_TERMS) (``gain_basis``), counts."""
    return np.matmul(basis, gains[:, :, None])[..., 0]


def predict(
    images: DiscImages,
    level: np.ndarray,
    gains: np.ndarray,
    *,
    basis: np.ndarray,
    mm_per_radian: float,
    reference_mm: float,
    range_offset_mm: float = 0.0,
) -> Prediction:
    """Gray ``sum_k gain_k c_k + level (1 - sum_k c_k)`` and the mixed phasor's distance
    (plus ``range_offset_mm``) of every window pixel, ``level`` (P,) the surround's at
    each (the plate's level of the disc that owns it where the plate fills it, the
    beyond's where it does not: ``fit._Problem.pixel_levels``); ``gain_k`` varies linearly
    over the image (``pixel_gains``: the retro-reflector's return changes with the
    incidence angle and the range across a large disc by a few per cent, curved: a
    quadratic over the disc, ``gain_basis``)."""
    surround = np.clip(1.0 - images.coverage.sum(axis=0), 0.0, 1.0)
    g = pixel_gains(gains, basis)
    gray = np.sum(g * images.coverage, axis=0) + level * surround
    mixed = np.sum(g * images.phasor, axis=0) + level * surround * images.plate_phasor
    distance = reference_mm + mm_per_radian * np.angle(mixed) + range_offset_mm
    return Prediction(gray=gray, distance_mm=distance, phasor=mixed, surround=surround)
