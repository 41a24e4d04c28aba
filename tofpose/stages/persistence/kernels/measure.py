"""§3.4 in one call: combine the frame with the consistent persistence history and
measure the kept blobs' centroids (Eq. 19) and ranges (Eq. 20) on the combined frames
(``Persistence.measure``'s arithmetic);
and with the range correction, back-projection (Eqs. 7-8), sigmas and weights (Eq. 21)
of the measured blobs, the measurement stage that acquisition and tracking share."""

from __future__ import annotations

import numpy as np

from tofpose.core.compiled import jit
from tofpose.core.kernels.camera import bearings
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
def persist_and_measure(
    gray,
    distance,
    flat,
    starts,
    bbox,
    centroids,
    history,
    background,
    dark,
    fx,
    fy,
    cx,
    cy,
    dist,
    pixel_bearings,
    mean_buf,
    med_buf,
):
    """The frame's blobs (pixels ``flat[starts[j]:starts[j + 1]]``, boxes (n, 4) (x, y,
    w, h), single-frame centroids (n, 2), NaN allowed) combined with the history (a
    ``records.PersistenceHistory``: ``Persistence.history``) and measured.

    background : the frame's level, counts (the centroids' level where a blob's own
    surround cannot be read); dark : its no-return level (``mixed_pixels``).

    Returns n_used (consistent history frames combined), motion (the history was cut),
    keep (n,) bool (counter C >= c_min, or every blob while fewer than c_min frames are
    combined), mean_gray (H, W) float32, med_distance (H, W) float32, uv (n, 2) and rho
    (n,) of the kept blobs (NaN for the others): coverage-weighted centroids on I-bar
    above each blob's surround level and ranges on D-bar along each centroid's line of
    sight; and mix (n, ``MIX_FIELDS``) the mixing sums of the kept blobs
    (``mixed_pixels.blob_mixing`` on I-bar, D-bar at the blobs' pixels, and this frame's
    distance elsewhere; the surround from this frame: the combined frames hold I-bar
    and D-bar only inside the boxes and at the blobs' pixels). A blob partly hidden by
    something nearer (``mixed_pixels.occluded_blobs``) gets a NaN range.

    With one frame, mean_gray and med_distance are the frame's gray and distance. With
    more, they are the scratch frames ``mean_buf`` and ``med_buf`` (H, W) float32
    (``Persistence`` owns them and lends them to every frame: copying two whole frames
    cost more than the rest of this call at far range), holding I-bar inside the boxes
    grown by 2 px and D-bar at the blobs' pixels, the only places anything reads;
    elsewhere they hold whatever an earlier frame left there."""
    h, w = gray.shape
    n = starts.shape[0] - 1
    n_used, motion = 0, False
    for f in range(history.count):
        if consistent(centroids, history.centroids[f], history.tol_px) and ranges_consistent(
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
        k_flat, k_starts, k_bbox, mean_gray, med_dist, distance, surrounds, dark, owners
    )
    k_rho = blob_ranges(
        k_flat, k_starts, med_dist.reshape(-1), pixel_bearings, bearings(k_uv, fx, fy, cx, cy, dist)
    )
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
    return n_used, motion, keep, mean_gray, med_dist, uv, rho, mix


@jit
def measure_and_back_project(
    gray,
    distance,
    flat,
    starts,
    bbox,
    centroids,
    split,
    history,
    background,
    dark,
    camera,
    mean_buf,
    med_buf,
    correction,
    sigmas,
):
    """§3.4 and Eqs. 7-8 in one call: ``persist_and_measure``, then of the kept blobs
    with a range (the "ranged" ones): the calibrated range correction (``correct_range``,
    ``range_correction.corrected_ranges``), the measurement sigmas
    (``sigmas.blob_sigmas``), the points y = rho e(uv) (Eq. 8) and the weights of Eq. 21,
    ``1 / (sigma_range^2 + (rho sigma_px / fx)^2)``: ``Persistence.measure``, then
    ``RangeCorrection.error_mm``'s median over the blob, ``stages.extraction.reference.sigmas``,
    Eq. 8 and
    Eq. 21 (as ``tests/tofpose/test_pipeline.py`` checks).

    The arguments are ``persist_and_measure``'s (the camera as a
    ``records.CameraRecord``), ``split`` (n,) bool (blobs cut out of a merged
    component), the range correction (``records.RangeCorrectionRecord``) and the
    ``uncertainty`` constants and floors (``records.SigmaConstants``).

    Returns n_used, motion, keep (n,), uv (n, 2) and rho (n,) as ``persist_and_measure``
    gives them (rho uncorrected), ranged (r,) int64 the indices of the ranged blobs, and
    for those: rho (r,) corrected, sigma_px (r,), sigma_range (r,), y (r, 3), weights (r,),
    mix (r, ``MIX_FIELDS``) their mixing sums, with the calibrated correction's shift of
    each blob's range applied to every distance in them (``solve.solve_pairs`` turns
    them into ranges once the blobs are matched).
    """
    fx, fy, cx, cy, dist = camera.fx, camera.fy, camera.cx, camera.cy, camera.dist
    n_used, motion, keep, mean_gray, med_dist, uv, rho, mix = persist_and_measure(
        gray,
        distance,
        flat,
        starts,
        bbox,
        centroids,
        history,
        background,
        dark,
        fx,
        fy,
        cx,
        cy,
        dist,
        camera.pixel_bearings,
        mean_buf,
        med_buf,
    )
    ranged = np.flatnonzero(keep & np.isfinite(rho))
    n_ranged = ranged.shape[0]
    r_flat, r_starts = pixel_list_subset(flat, starts, ranged)
    r_uv, r_rho, r_split = uv[ranged], rho[ranged], split[ranged]
    r_mix = mix[ranged]
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
        background,
        r_split,
        sigmas,
    )
    e = bearings(r_uv, fx, fy, cx, cy, dist)
    y = np.empty((n_ranged, 3))
    w = np.empty(n_ranged)
    for a in range(n_ranged):
        for b in range(3):
            y[a, b] = e[a, b] * r_rho[a]  # Eq. 8
        w[a] = 1.0 / (sr[a] ** 2 + (r_rho[a] * sp[a] / fx) ** 2)  # Eq. 21
    return n_used, motion, keep, uv, rho, ranged, r_rho, sp, sr, y, w, r_mix
