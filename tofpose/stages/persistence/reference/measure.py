"""§3.4 and Eqs. 7-8, 19-21 composed from the reference statements: a frame's blobs
combined with the consistent persistence history and measured (centroids, ranges, the
mixing sums, occlusion), then range-corrected, back-projected and weighted; the
measurement stage that acquisition and tracking share.

Same names, arguments and returns (the records of ``stages.persistence.records``) as
``tofpose.stages.persistence.kernels.measure``, so that one can stand in for the other.
The records are read by field name: ``frame`` (gray, distance, background, dark),
``blobs`` (pixel lists ``flat`` (P,) with blob j's at ``flat[starts[j]:starts[j + 1]]``,
boxes ``bbox`` (n, 4) (x, y, w, h), centroids, split), ``history`` (gray, distance, mask,
centroids: tuples newest first of which the first ``n_frames`` are real frames;
motion_tolerance_px, c_min), ``camera`` (fx, fy, cx, cy, dist, K, pixel_bearings),
``correction`` (apply, model, harmonics, offsets) and ``sigmas``
(``stages.extraction.reference.sigmas``'s constants).
"""

from __future__ import annotations

import warnings

import numpy as np

from tofpose.core.records import Candidates
from tofpose.core.reference.camera import back_project, bearings
from tofpose.stages.extraction.constants import MIX_FIELDS
from tofpose.stages.extraction.reference import mixed_pixels
from tofpose.stages.extraction.reference.centroids import blob_centroid, blob_range
from tofpose.stages.extraction.reference.sigmas import centroid_sigma_px, range_sigmas_mm, weights
from tofpose.stages.persistence.constants import RANGE_TEST_Z
from tofpose.stages.persistence.records import Measurement, PersistedBlobs
from tofpose.stages.persistence.reference.persistence import (
    centroids_consistent,
    ranges_consistent,
)


def _blobs(flat, starts) -> list[np.ndarray]:
    return [np.asarray(flat[starts[j] : starts[j + 1]], np.int64) for j in range(len(starts) - 1)]


def _pixel_lists(blobs) -> tuple[np.ndarray, np.ndarray]:
    """``flat``, ``starts`` of a list of pixel arrays."""
    starts = np.concatenate(([0], np.cumsum([len(b) for b in blobs], dtype=np.int64)))
    flat = np.concatenate(blobs).astype(np.int64) if blobs else np.zeros(0, np.int64)
    return flat, starts


def _owner_image(owners, shape):
    """``owner_map``'s map (an ``OwnerMap``) pasted into a (H, W) image of -1, or None
    when not used."""
    if not owners.used:
        return None
    full = np.full(shape, -1, np.int32)
    oy, ox = owners.y0, owners.x0
    full[oy : oy + owners.owner.shape[0], ox : ox + owners.owner.shape[1]] = owners.owner
    return full


def consistent_history(centroids_uv, distance, blobs, history) -> tuple[int, bool]:
    """How many of the history's frames, newest first, are consistent with this frame
    (``centroids_consistent`` at motion_tolerance_px and ``ranges_consistent`` at ``RANGE_TEST_Z``)
    before the first that is not, and whether one is not (motion)."""
    for f in range(history.n_frames):
        still = centroids_consistent(
            centroids_uv, history.centroids[f], history.motion_tolerance_px
        )
        if not (still and ranges_consistent(distance, history.distance[f], blobs, RANGE_TEST_Z)):
            return f, True
    return history.n_frames, False


def combined_frames(gray, distance, blobs, history, n_used):
    """§3.4's combination of the frame with the ``n_used`` newest history frames: keep
    (n,) (the median over a blob's pixels of the counter C, 1 + the history masks
    holding the pixel, at least c_min; every blob while fewer than c_min frames are
    combined), I-bar (the mean gray, summed newest first in float32) and D-bar (the
    median distance ignoring NaNs, float32), both (H, W) over the whole frame."""
    frames = 1 + n_used
    keep = np.ones(len(blobs), bool)
    if frames == 1 or not blobs:
        return keep, gray, distance
    if frames >= history.c_min:
        counter = 1 + sum(history.mask[f].astype(int) for f in range(n_used))
        keep = np.array([np.median(counter[p]) >= history.c_min for p in blobs])
    older = np.zeros_like(gray, np.float32)
    for f in range(n_used):
        older += history.gray[f]
    mean_gray = (gray + older) / np.float32(frames)
    stack = np.stack([distance] + [history.distance[f] for f in range(n_used)])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # pixels NaN in every frame
        median_distance = np.nanmedian(stack, axis=0).astype(np.float32)
    return keep, mean_gray, median_distance


def persist_and_measure(frame, blobs, history, camera):
    """The frame's blobs combined with the history and measured: ``consistent_history``
    and ``combined_frames``; then of the kept blobs, on I-bar and D-bar: the surround
    (``mixed_pixels.blob_surrounds`` on this frame, neighbours left out by
    ``mixed_pixels.owner_map``), the coverage-weighted centroid above the surround's level
    (the frame's ``background`` where the ring is empty; Eq. 19,
    ``centroids.blob_centroid``), the range along its line of sight (Eq. 20,
    ``centroids.blob_range``), NaN when ``mixed_pixels.occluded_blobs`` (on this frame's
    distance) finds it partly hidden, and the mixing sums (``mixed_pixels.blob_mixing``:
    I-bar, D-bar at the blob's pixels, this frame's distance elsewhere, the frame's
    no-return level ``dark``). blobs : a ``BlobLists`` (its single-frame centroids (n, 2)
    are what the history is tested with); camera : fx, fy, cx, cy, dist and
    pixel_bearings (H * W, 3). The history's scratch frames are not used (the combined
    frames are computed whole).

    Returns ``PersistedBlobs``: n_used, motion, keep (n,), mean_gray and med_distance
    (H, W) float32, uv (n, 2) and rho (n,) (NaN for blobs not kept), mixing (n,
    ``MIX_FIELDS``)."""
    gray, distance, background, dark = frame.gray, frame.distance, frame.background, frame.dark
    flat, starts, bbox, centroids = blobs.flat, blobs.starts, blobs.bbox, blobs.centroids
    fx, fy, cx, cy, dist = camera.fx, camera.fy, camera.cx, camera.cy, camera.dist
    pixel_bearings = camera.pixel_bearings
    h, w = gray.shape
    pixels = _blobs(flat, starts)
    n = len(pixels)
    n_used, motion = consistent_history(centroids, distance, pixels, history)
    keep, mean_gray, med_dist = combined_frames(gray, distance, pixels, history, n_used)

    kept = np.flatnonzero(keep)
    k_flat, k_starts = _pixel_lists([pixels[j] for j in kept])
    k_bbox = np.asarray(bbox, np.int64).reshape(-1, 4)[kept]
    owners = mixed_pixels.owner_map(k_flat, k_starts, k_bbox, h, w)
    surrounds = mixed_pixels.blob_surrounds(k_bbox, gray, distance, owners)
    owner_full = _owner_image(owners, (h, w))
    K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    bearing_image = np.asarray(pixel_bearings).reshape(h, w, 3)
    k_uv = np.empty((len(kept), 2))
    k_rho = np.empty(len(kept))
    for a, j in enumerate(kept):
        level = surrounds.gray[a] if np.isfinite(surrounds.gray[a]) else background
        k_uv[a] = blob_centroid(
            mean_gray, pixels[j], tuple(k_bbox[a]), np.float32(level), owner_full, a, coverage=True
        )
        e_c = bearings(k_uv[a][None], K, dist)[0]
        k_rho[a] = blob_range(med_dist, pixels[j], bearing_image, e_c)
    hidden = mixed_pixels.occluded_blobs(k_flat, k_starts, k_bbox, distance, k_rho, owners)
    k_rho[hidden] = np.nan
    k_mix = mixed_pixels.blob_mixing(
        k_flat,
        k_starts,
        k_bbox,
        mean_gray,
        med_dist,
        distance,
        surrounds,
        dark,
        owners,
        camera.full_scale_counts,
    )
    uv = np.full((n, 2), np.nan)
    rho = np.full(n, np.nan)
    mix = np.full((n, MIX_FIELDS), np.nan)
    uv[kept], rho[kept], mix[kept] = k_uv, k_rho, k_mix
    return PersistedBlobs(
        n_used=n_used,
        motion=motion,
        keep=keep,
        mean_gray=mean_gray,
        med_distance=med_dist,
        uv=uv,
        rho=rho,
        mixing=mix,
    )


def range_error_mm(distance_mm, amplitude, pixel_index, model, harmonics, offsets):
    """The calibrated range-error model (``RangeCorrection.error_mm``) at pixels (N,) of
    a blob measured at ``distance_mm``: offset + sum_k (s_k sin 4k phi + c_k cos 4k phi),
    phi = 2 pi d / U, + k_amp log10(max(amplitude, 1e-3) / a_ref) + the pixel's offset.
    model (4,) : (U mm, offset mm, k_amp mm per decade, a_ref counts); harmonics (k, 2);
    offsets (H * W,) mm, or (0,) for none."""
    u, offset, k_amp, a_ref = model
    phi = 2.0 * np.pi * distance_mm / u
    err = np.full(len(pixel_index), float(offset))
    for k, (s, c) in enumerate(np.asarray(harmonics).reshape(-1, 2), start=1):
        err += s * np.sin(4 * k * phi) + c * np.cos(4 * k * phi)
    err += k_amp * np.log10(np.maximum(np.asarray(amplitude, float), 1e-3) / a_ref)
    if len(offsets):
        err += np.asarray(offsets)[pixel_index]
    return err


def corrected_range(rho, pixels, gray, correction) -> float:
    """A blob's range less the median of ``range_error_mm`` over its pixels, with gray
    (I-bar) as the amplitude."""
    amplitude = np.asarray(gray).reshape(-1)[pixels]
    err = range_error_mm(
        rho, amplitude, pixels, correction.model, correction.harmonics, correction.offsets
    )
    return rho - float(np.median(err))


def measure_and_back_project(frame, blobs, history, camera, correction, sigmas):
    """``persist_and_measure``, then of the kept blobs with a range ("ranged"): the range
    correction when ``correction.apply`` (``corrected_range``; its shift applied to the
    mixing sums by ``mixed_pixels.shift_mixing``), the sigmas on I-bar and D-bar
    (``stages.extraction.reference.sigmas``; ``blobs.split``: blobs cut out of a merged
    component), the points y = rho e(uv) (Eq. 8) and Eq. 21's weights.

    Returns the ``Measurement``: n_used, motion, keep (n,), uv (n, 2), rho (n,)
    uncorrected, ranged (r,) int64, and the ranged blobs as ``Candidates``: uv (r, 2),
    ranges (r,) corrected, points (r, 3), weights (r,), sigma_px (r,), sigma_range (r,),
    mixing (r, ``MIX_FIELDS``)."""
    persisted = persist_and_measure(frame, blobs, history, camera)
    keep, uv, rho = persisted.keep, persisted.uv, persisted.rho
    mean_gray, med_dist, background = persisted.mean_gray, persisted.med_distance, frame.background
    pixels = _blobs(blobs.flat, blobs.starts)
    ranged = np.flatnonzero(keep & np.isfinite(rho))
    r_pixels = [pixels[j] for j in ranged]
    r_uv, r_rho, r_mix = uv[ranged], rho[ranged].copy(), persisted.mixing[ranged].copy()
    if correction.apply:
        for a, p in enumerate(r_pixels):
            raw = r_rho[a]
            r_rho[a] = corrected_range(raw, p, mean_gray, correction)
            mixed_pixels.shift_mixing(r_mix[a], r_rho[a] - raw)
    sp = np.array(
        [
            centroid_sigma_px(
                mean_gray,
                p,
                r_uv[a],
                background,
                bool(blobs.split[j]),
                sigmas,
                camera.full_scale_counts,
            )
            for a, (j, p) in enumerate(zip(ranged, r_pixels, strict=True))
        ]
    )
    sr = range_sigmas_mm(mean_gray, med_dist, r_pixels, background, sigmas)
    y = np.zeros((0, 3))
    if len(ranged):
        y = back_project(r_uv, r_rho, np.asarray(camera.K, float), camera.dist)  # Eq. 8
    wt = weights(r_rho, sr, sp, camera.fx)  # Eq. 21
    candidates = Candidates(
        uv_px=r_uv,
        range_mm=r_rho,
        y_mm=y.reshape(-1, 3),
        weights=wt,
        sigma_px=sp.reshape(-1),
        sigma_range_mm=np.asarray(sr, float).reshape(-1),
        mixing=r_mix,
    )
    return Measurement(
        n_used=persisted.n_used,
        motion=persisted.motion,
        keep=keep,
        uv=uv,
        rho=rho,
        ranged=ranged.astype(np.int64),
        candidates=candidates,
    )
