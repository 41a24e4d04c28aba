"""§3.4 in one call: combine the frame with the consistent persistence history and
measure the kept blobs' centroids (Eq. 19) and ranges (Eq. 20) on the combined frames
(``Persistence.measure``'s arithmetic);
and with the range correction, back-projection (Eqs. 7-8), sigmas and weights (Eq. 21)
of the measured blobs, the measurement stage that acquisition and tracking share."""

from __future__ import annotations

import numpy as np

from tofpose.core.compiled import jit
from tofpose.core.kernels.camera import bearings
from tofpose.core.records import Candidates
from tofpose.stages.extraction.constants import MIX_FIELDS
from tofpose.stages.extraction.kernels.centroids import blob_centroids, blob_ranges, owner_map
from tofpose.stages.extraction.kernels.mixed_pixels import (
    blob_mixing,
    blob_surrounds,
    occluded_blobs,
    shift_mixing,
)
from tofpose.stages.extraction.kernels.sigmas import blob_sigmas
from tofpose.stages.persistence.constants import RANGE_TEST_Z
from tofpose.stages.persistence.kernels.persistence import (
    blob_count_medians,
    consistent,
    mean_in_boxes,
    medians_and_counts_at,
    ranges_consistent,
)
from tofpose.stages.persistence.kernels.range_correction import corrected_ranges
from tofpose.stages.persistence.records import Measurement, PersistedBlobs


@jit
def pixel_list_subset(flat, starts, idx):
    """The pixel lists (``extraction.pixel_lists`` form: flat (P,), starts (n + 1,)) of
    the blobs ``idx`` (m,), in that order: flat (P',) and starts (m + 1,)."""
    sub_starts = np.zeros(idx.shape[0] + 1, np.int64)
    for a in range(idx.shape[0]):
        sub_starts[a + 1] = sub_starts[a] + starts[idx[a] + 1] - starts[idx[a]]
    sub_flat = np.empty(sub_starts[-1], np.int64)
    for a in range(idx.shape[0]):
        sub_flat[sub_starts[a] : sub_starts[a + 1]] = flat[starts[idx[a]] : starts[idx[a] + 1]]
    return sub_flat, sub_starts


@jit
def persist_and_measure(frame, blobs, history, camera):
    """The frame's blobs (a ``persistence.records.BlobLists``: pixel lists, boxes,
    single-frame centroids, NaN allowed) combined with the history (a
    ``records.PersistenceHistory``: ``Persistence.history``) and measured.

    frame : a ``records.FrameRecord``: its gray and distance, its background level,
    counts (the centroids' level where a blob's own surround cannot be read) and its
    no-return level (``mixed_pixels``); camera : a ``records.CameraRecord``.

    Returns ``PersistedBlobs``: n_used (consistent history frames combined), motion (the
    history was cut), keep (n,) bool (counter C >= c_min, or every blob while fewer than
    c_min frames are combined), mean_gray (H, W) float32, med_distance (H, W) float32,
    uv (n, 2) and rho (n,) of the kept blobs (NaN for the others): coverage-weighted
    centroids on I-bar above each blob's surround level and ranges on D-bar along each
    centroid's line of sight; and mixing (n, ``MIX_FIELDS``) the mixing sums of the kept
    blobs
    (``mixed_pixels.blob_mixing`` on I-bar, D-bar at the blobs' pixels, and this frame's
    distance elsewhere; the surround from this frame: the combined frames hold I-bar
    and D-bar only inside the boxes and at the blobs' pixels). A blob partly hidden by
    something nearer (``mixed_pixels.occluded_blobs``) gets a NaN range.

    With one frame, mean_gray and med_distance are the frame's gray and distance. With
    more, they are the history's scratch frames (H, W) float32 (``Persistence`` owns them
    and lends them to every frame: copying two whole frames cost more than the rest of
    this call at far range), holding I-bar inside the boxes grown by 2 px and D-bar at
    the blobs' pixels, the only places anything reads; elsewhere they hold whatever an
    earlier frame left there."""
    gray, distance, background, dark = frame.gray, frame.distance, frame.background, frame.dark
    flat, starts, bbox, centroids = blobs.flat, blobs.starts, blobs.bbox, blobs.centroids
    mean_buf, med_buf = history.scratch_gray, history.scratch_distance
    h, w = gray.shape
    n = starts.shape[0] - 1
    n_used, motion = 0, False
    tol = history.motion_tolerance_px
    for f in range(history.n_frames):
        if consistent(centroids, history.centroids[f], tol) and ranges_consistent(
            distance, history.distance[f], flat, starts, RANGE_TEST_Z
        ):
            n_used += 1
        else:
            motion = True
            break
    frames = 1 + n_used
    keep = np.ones(n, np.bool_)
    mean_gray = gray
    med_dist = distance
    if frames > 1 and n > 0:
        # D-bar at every blob's pixels (only the kept ones' are read) and the counter
        counts = medians_and_counts_at(
            (distance,) + history.distance, history.mask, n_used, flat, med_buf
        )
        med_dist = med_buf
        if frames >= history.c_min:
            keep = blob_count_medians(counts, starts, frames + 1) >= history.c_min
        mean_gray = mean_in_boxes(gray, history.gray, n_used, bbox, mean_buf)
    # the kept blobs as their own pixel lists
    kept = np.flatnonzero(keep)
    k_flat, k_starts = pixel_list_subset(flat, starts, kept)

    # Eqs. 19-20 on the combined frames
    k_bbox = bbox[kept]
    owners = owner_map(k_flat, k_starts, k_bbox, h, w)
    surrounds = blob_surrounds(k_bbox, gray, distance, owners)
    level = np.empty(kept.shape[0])
    for a in range(kept.shape[0]):
        s_gray = surrounds.gray[a]
        level[a] = s_gray if np.isfinite(s_gray) else background
    k_uv = blob_centroids(k_flat, k_starts, k_bbox, mean_gray, level, True, owners)
    k_mix = blob_mixing(
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
    e_c = bearings(k_uv, camera.fx, camera.fy, camera.cx, camera.cy, camera.dist)
    k_rho = blob_ranges(k_flat, k_starts, med_dist.reshape(-1), camera.pixel_bearings, e_c)
    hidden = occluded_blobs(k_flat, k_starts, k_bbox, distance, k_rho, owners)
    for a in range(kept.shape[0]):
        if hidden[a]:  # partly hidden: no range, so no measurement
            k_rho[a] = np.nan
    uv = np.full((n, 2), np.nan)
    rho = np.full(n, np.nan)
    mix = np.full((n, MIX_FIELDS), np.nan)
    for a in range(kept.shape[0]):
        uv[kept[a]] = k_uv[a]
        rho[kept[a]] = k_rho[a]
        mix[kept[a]] = k_mix[a]
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


@jit
def measure_and_back_project(frame, blobs, history, camera, correction, sigmas):
    """§3.4 and Eqs. 7-8 in one call: ``persist_and_measure``, then of the kept blobs
    with a range (the "ranged" ones): the calibrated range correction (``correct_range``,
    ``range_correction.corrected_ranges``), the measurement sigmas
    (``sigmas.blob_sigmas``), the points y = rho e(uv) (Eq. 8) and the weights of Eq. 21,
    ``1 / (sigma_range^2 + (rho sigma_px / fx)^2)``: ``Persistence.measure``, then
    ``RangeCorrection.error_mm``'s median over the blob, ``stages.extraction.reference.sigmas``,
    Eq. 8 and Eq. 21 (as ``tests/tofpose/test_pipeline.py`` checks).

    The arguments are ``persist_and_measure``'s (the blobs' ``split`` flags read for the
    sigmas), the range correction (``records.RangeCorrectionRecord``) and the
    ``uncertainty`` constants and floors (``records.SigmaConstants``).

    Returns the ``persistence.records.Measurement``: n_used, motion, keep (n,), uv (n, 2)
    and rho (n,) as ``persist_and_measure`` gives them (rho uncorrected), ranged (r,)
    int64 the indices of the ranged blobs, and those as ``Candidates``: their centroids,
    ranges corrected, points, weights, sigmas and mixing sums, with the calibrated
    correction's shift of each blob's range applied to every distance in them
    (``solve.solve_pairs`` turns them into ranges once the blobs are matched).
    """
    fx = camera.fx
    persisted = persist_and_measure(frame, blobs, history, camera)
    keep, uv, rho = persisted.keep, persisted.uv, persisted.rho
    mean_gray, med_dist = persisted.mean_gray, persisted.med_distance
    ranged = np.flatnonzero(keep & np.isfinite(rho))
    n_ranged = ranged.shape[0]
    r_flat, r_starts = pixel_list_subset(blobs.flat, blobs.starts, ranged)
    r_uv, r_rho, r_split = uv[ranged], rho[ranged], blobs.split[ranged]
    r_mix = persisted.mixing[ranged]
    if correction.apply and n_ranged:
        raw = r_rho
        r_rho = corrected_ranges(
            r_rho,
            r_flat,
            r_starts,
            mean_gray,
            correction.model,
            correction.harmonics,
            correction.offsets,
        )
        for a in range(n_ranged):  # the same shift of every distance in the mixing sums
            shift_mixing(r_mix[a], r_rho[a] - raw[a])
    sp, sr = blob_sigmas(
        r_flat,
        r_starts,
        r_uv,
        mean_gray,
        med_dist,
        frame.background,
        r_split,
        camera.full_scale_counts,
        sigmas,
    )
    e = bearings(r_uv, fx, camera.fy, camera.cx, camera.cy, camera.dist)
    y = np.empty((n_ranged, 3))
    w = np.empty(n_ranged)
    for a in range(n_ranged):
        for b in range(3):
            y[a, b] = e[a, b] * r_rho[a]  # Eq. 8
        w[a] = 1.0 / (sr[a] ** 2 + (r_rho[a] * sp[a] / fx) ** 2)  # Eq. 21
    candidates = Candidates(
        uv_px=r_uv,
        range_mm=r_rho,
        y_mm=y,
        weights=w,
        sigma_px=sp,
        sigma_range_mm=sr,
        mixing=r_mix,
    )
    return Measurement(
        n_used=persisted.n_used,
        motion=persisted.motion,
        keep=keep,
        uv=uv,
        rho=rho,
        ranged=ranged,
        candidates=candidates,
    )
