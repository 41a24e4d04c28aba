"""A small marker's pixels mix its return with the surface around it; these kernels
measure the surround of each blob and remove it from the blob's range (ours, beyond the
paper's Eq. 20; docs/algorithm.md, "Small markers: local surround and mixed pixels").

A pixel p that a reflector covers by the fraction c_p (its area, after the lens) returns
the phasor ``c_p P_r + (1 - c_p) P_b``: the reflector's ``P_r`` and the surround's
``P_b`` (a raised marker's plate, 100-150 mm behind it on the paper's target). The phase
spread between the two (~0.04 rad at 6 MHz) is small, so amplitude and amplitude x
distance mix linearly: with a_p the pixel's amplitude (gray above the frame's no-return
level) and d_p its distance, summed over the blob's support (its pixels dilated by one),

    S_a  = sum (a_p - a_b)            = C (A_r - a_b)
    S_ad = sum (a_p d_p - a_b d_b)    = C (A_r d_r - a_b d_b)

where C = sum c_p is the reflector's image area in px^2. C cannot be told from A_r
by the pixels alone (a dimmer, larger disc gives the same image), but the catalog gives
it once the blob is matched: ``pi r_px^2 cos(incidence)``. Then

    A_r = a_b + S_a / C,   d_r = (a_b d_b + S_ad / C) / A_r

is the reflector's own distance. The median over the blob's pixels (Eq. 20 as we
measure it) is pulled towards the surround by the mixed pixels; ``bench/foreign.py``
and ``bench/physics.py`` measure both against truth by marker size (docs/results.md).

A saturated reflector (its core at the camera's full scale, no distance there) breaks
the sums: A_r is unknown (only A_r >= full scale), and a saturated pixel's coverage is
anything from FS / A_r to 1. Its range comes from the blob's own ranged pixels alone
(not the support's ring beyond it: at a plate's edge that ring can be a wall metres
behind, whose pixels would bound the reflector at the wall's distance with narrow
intervals and win the median), each with its own bounds: pixel p (amplitude a_p,
distance d_p) is ``c_p A_r + (1 - c_p) a_b``, so
``0 <= c_p <= c_max = (a_p - a_b) / (FS - a_b)``, and its reflector distance

    d_r(c) = (a_p d_p - (1 - c) a_b d_b) / (a_p - (1 - c) a_b)

lies between d_r(0) (all of the surround's return removed) and d_r(c_max). The blob's
range is the weighted median of those intervals' mid-points, weights 1 / half-width^2
(the brightest, least mixed pixels count most; a median, as Eq. 20's, so that a dim,
noisy rim pixel cannot pull it), and its sigma combines the weighted half-width /
sqrt(3) (a uniform over the interval; not divided by sqrt(n): one unknown A_r drives
every pixel's coverage) with the mid-points' scatter (1.4826 MAD, not divided by
sqrt(n) either: the pixels share one surround, a_b and d_b, whose error moves their
mid-points together; divided, the saturating family's markers read 1.5-1.8 sigmas RMS
at 4.5 m and one pose at 6 m was 2 deg and 4.6 sigma off, where undivided they read
0.5-1.5 and no pose beyond 3 sigma). ``bench/foreign.py`` on ``foreign-saturating.h5``
measures it.
"""

from __future__ import annotations

import numpy as np

from tofpose.core.compiled import jit
from tofpose.core.kernels.indexing import row_col
from tofpose.core.kernels.stats import median_inplace
from tofpose.stages.extraction.constants import (
    MAD_TO_SIGMA,
    MIX_FIELDS,
    OCCLUSION_MARGIN_MM,
    OCCLUSION_MIN_OUTER_PX,
    OCCLUSION_MIN_PATCH_PX,
    OCCLUSION_NOISE_SIGMAS,
    SATURATED_AREA_FRACTION,
    SATURATED_HALF_WIDTH_FLOOR_MM,
    SATURATED_MIN_CONTRAST,
    SURROUND_INNER_PX,
    SURROUND_OUTER_PX,
)
from tofpose.stages.extraction.records import Surrounds


@jit
def _owned_by_other(owners, r, c, j):
    """Whether pixel (r, c) belongs to a blob other than j (owners: a
    ``records.OwnerMap``, ``centroids.owner_map``)."""
    if not owners.used:
        return False
    rr, cc = r - owners.y0, c - owners.x0
    if rr < 0 or cc < 0 or rr >= owners.owner.shape[0] or cc >= owners.owner.shape[1]:
        return False
    o = owners.owner[rr, cc]
    return o != -1 and o != j


@jit
def _next_to(mask, r, c):
    """Whether (r, c) or one of its 8 neighbours is set in the (h, w) bool ``mask``."""
    for dr in range(-1, 2):
        for dc in range(-1, 2):
            rr, cc = r + dr, c + dc
            if 0 <= rr < mask.shape[0] and 0 <= cc < mask.shape[1] and mask[rr, cc]:
                return True
    return False


@jit
def blob_surrounds(bbox, gray, distance, owners):
    """The gray level (counts) and distance (mm) of the surface around each blob: the
    medians over the ring between its box grown by ``SURROUND_INNER_PX`` and by
    ``SURROUND_OUTER_PX`` (clipped to the image; other blobs' pixels left out). A tilted
    plate's gradient cancels in the median of a ring centred on the blob.

    bbox : (n, 4) int64 (x, y, w, h); gray : (H, W) float32; distance : (H, W) float32
    (NaN invalid); owners : ``centroids.owner_map``'s ``records.OwnerMap``. Returns a
    ``records.Surrounds``: gray (n,) (NaN with no ring pixel), distance_mm (n,) (NaN with
    fewer than 3 ranged ring pixels) and crowded (n,) bool: another blob's pixels lie in
    the ring (its light then spills into this blob's support, and the mixing sums are not
    used)."""
    h, w = gray.shape
    n = bbox.shape[0]
    level = np.full(n, np.nan)
    depth = np.full(n, np.nan)
    crowded = np.zeros(n, np.bool_)
    so, si = SURROUND_OUTER_PX, SURROUND_INNER_PX
    for j in range(n):
        x, y, bw, bh = bbox[j, 0], bbox[j, 1], bbox[j, 2], bbox[j, 3]
        y0, y1 = max(y - so, 0), min(y + bh + so, h)
        x0, x1 = max(x - so, 0), min(x + bw + so, w)
        g_ring = np.empty((y1 - y0) * (x1 - x0), np.float32)
        d_ring = np.empty((y1 - y0) * (x1 - x0), np.float32)
        ng, nd = 0, 0
        for r in range(y0, y1):
            inner_row = y - si <= r < y + bh + si
            for c in range(x0, x1):
                if inner_row and x - si <= c < x + bw + si:
                    continue
                if _owned_by_other(owners, r, c, j):
                    crowded[j] = True
                    continue
                g_ring[ng] = gray[r, c]
                ng += 1
                d = distance[r, c]
                if np.isfinite(d):
                    d_ring[nd] = d
                    nd += 1
        if ng:
            level[j] = median_inplace(g_ring[:ng])
        if nd >= 3:
            depth[j] = median_inplace(d_ring[:nd])
    return Surrounds(gray=level, distance_mm=depth, crowded=crowded)


@jit
def occluded_blobs(flat, starts, bbox, distance, rho, owners):
    """(n,) bool: blobs partly hidden by something in front of them. Within the blob's
    box grown by ``SURROUND_OUTER_PX`` (other blobs' pixels left out), the pixels that
    read nearer than its range ``rho`` (n,) by more than ``OCCLUSION_MARGIN_MM`` and
    touch the blob, with the near pixels connected to them, make a patch of at least
    ``OCCLUSION_MIN_PATCH_PX`` that reaches ``OCCLUSION_MIN_OUTER_PX`` pixels of the
    window's outermost ring and whose median lies nearer than ``rho`` by more than
    ``OCCLUSION_NOISE_SIGMAS`` robust sigmas (1.4826 MAD) of the other ranged pixels
    there (the plate around a marker; none ranged: no scatter). Such a blob is the image
    of the part of a marker left visible: its centroid lies off the marker's centre by
    up to its radius and its range mixes in the occluder's, so it carries no
    measurement (ours, not the paper's). flat, starts : the pixel lists; bbox (n, 4);
    distance (H, W) float32 (NaN invalid); owners : ``centroids.owner_map``'s
    ``records.OwnerMap``. NaN ranges are never occluded."""
    h, w = distance.shape
    n = bbox.shape[0]
    out = np.zeros(n, np.bool_)
    inv_w = 1.0 / w
    so = SURROUND_OUTER_PX
    for j in range(n):
        if not np.isfinite(rho[j]):
            continue
        x, y, bw, bh = bbox[j, 0], bbox[j, 1], bbox[j, 2], bbox[j, 3]
        y0, y1 = max(y - so, 0), min(y + bh + so, h)
        x0, x1 = max(x - so, 0), min(x + bw + so, w)
        ph, pw = y1 - y0, x1 - x0
        member = np.zeros((ph, pw), np.bool_)
        for i in range(starts[j], starts[j + 1]):
            r, c = row_col(flat[i], w, inv_w)
            member[r - y0, c - x0] = True
        limit = rho[j] - OCCLUSION_MARGIN_MM
        ranged = np.zeros((ph, pw), np.bool_)
        near = np.zeros((ph, pw), np.bool_)
        for r in range(ph):
            for c in range(pw):
                d = distance[r + y0, c + x0]
                ranged[r, c] = (
                    not member[r, c]
                    and np.isfinite(d)
                    and not _owned_by_other(owners, r + y0, c + x0, j)
                )
                near[r, c] = ranged[r, c] and d < limit
        if not near.any():  # the usual case: nothing in front, no flood to run
            continue
        # flood the near patches from the near pixels that touch the blob
        patch = np.zeros((ph, pw), np.bool_)
        stack = np.empty(ph * pw, np.int64)
        size = 0
        for r in range(ph):
            for c in range(pw):
                if not near[r, c] or patch[r, c]:
                    continue
                if not _next_to(member, r, c):
                    continue
                patch[r, c] = True
                stack[0] = r * pw + c
                top = 1
                while top:
                    top -= 1
                    k = stack[top]
                    size += 1
                    kr, kc = k // pw, k % pw
                    for dr in range(-1, 2):
                        for dc in range(-1, 2):
                            rr, cc = kr + dr, kc + dc
                            if 0 <= rr < ph and 0 <= cc < pw and near[rr, cc] and not patch[rr, cc]:
                                patch[rr, cc] = True
                                stack[top] = rr * pw + cc
                                top += 1
        if size < OCCLUSION_MIN_PATCH_PX:
            continue
        outer = 0
        for r in range(ph):
            row_out = r + y0 < y - so + 1 or r + y0 >= y + bh + so - 1
            for c in range(pw):
                if patch[r, c] and (row_out or c + x0 < x - so + 1 or c + x0 >= x + bw + so - 1):
                    outer += 1
        if outer < OCCLUSION_MIN_OUTER_PX:
            continue
        inside = np.empty(size, np.float32)
        rest = np.empty(ph * pw, np.float32)
        n_in, n_rest = 0, 0
        for r in range(ph):
            for c in range(pw):
                if patch[r, c]:
                    inside[n_in] = distance[r + y0, c + x0]
                    n_in += 1
                elif ranged[r, c]:
                    rest[n_rest] = distance[r + y0, c + x0]
                    n_rest += 1
        scatter = 0.0
        if n_rest >= 3:
            med = median_inplace(rest[:n_rest].copy())  # it scrambles its input
            for i in range(n_rest):
                rest[i] = abs(rest[i] - med)
            scatter = MAD_TO_SIGMA * median_inplace(rest[:n_rest])
        margin = max(OCCLUSION_MARGIN_MM, OCCLUSION_NOISE_SIGMAS * scatter)
        out[j] = median_inplace(inside[:n_in]) < rho[j] - margin
    return out


@jit
def blob_mixing(
    flat, starts, bbox, gray, member_distance, distance, surrounds, dark, owners, full_scale
):
    """The sums of the mixing model (module docstring) of each blob over its support
    (its pixels dilated by one, other blobs' pixels left out): (n, ``MIX_FIELDS``) rows
    (a_b, d_b, S_a, S_ad, C_unranged, n_support), NaN rows where the surround is unknown;
    a crowded blob's sums stay NaN and only a saturated one gets d_sat, sigma_sat
    (``reference.mixed_pixels.blob_mixing``).

    flat, starts : the pixel lists; bbox (n, 4); gray (H, W) float32 (I-bar where
    persistence combined frames: it holds them inside the boxes grown by 2 px);
    member_distance (H, W) float32, read at the blobs' own pixels (D-bar, the
    combination's median, as the blob's median range reads it), and distance, the
    frame's own, read at the support's other pixels; surrounds : ``blob_surrounds``'
    ``records.Surrounds``; dark : the frame's no-return gray level (counts); owners :
    ``centroids.owner_map``'s ``records.OwnerMap``. Support pixels
    without a range (saturated, or too dark) are left out of the sums; their covered
    area, estimated from their gray as ``(g - g_b) / (g_max - g_b)`` clipped to [0, 1]
    (1 for a saturated centre), is returned so that the caller takes it off C."""
    h, w = gray.shape
    fs_a = full_scale - dark
    n = bbox.shape[0]
    out = np.full((n, MIX_FIELDS), np.nan)
    inv_w = 1.0 / w
    for j in range(n):
        gb, db = surrounds.gray[j], surrounds.distance_mm[j]
        if not (np.isfinite(gb) and np.isfinite(db)):
            continue
        x, y, bw, bh = bbox[j, 0], bbox[j, 1], bbox[j, 2], bbox[j, 3]
        y0, y1 = max(y - 1, 0), min(y + bh + 1, h)
        x0, x1 = max(x - 1, 0), min(x + bw + 1, w)
        ph, pw = y1 - y0, x1 - x0
        member = np.zeros((ph, pw), np.bool_)
        g_max = gb
        for i in range(starts[j], starts[j + 1]):
            r, c = row_col(flat[i], w, inv_w)
            member[r - y0, c - x0] = True
            g_max = max(g_max, float(gray[r, c]))
        saturated = g_max >= full_scale
        if surrounds.crowded[j] and not saturated:
            continue
        a_b = gb - dark
        a_bp = max(a_b, 0.0)
        mids = np.empty(ph * pw)
        halves = np.empty(ph * pw)
        n_mid = 0
        s_a, s_ad, c_unranged, n_sup = 0.0, 0.0, 0.0, 0
        for r in range(ph):
            for c in range(pw):
                if not _next_to(member, r, c) or _owned_by_other(owners, r + y0, c + x0, j):
                    continue
                n_sup += 1
                g = float(gray[r + y0, c + x0])
                src = member_distance if member[r, c] else distance
                d = src[r + y0, c + x0]
                if np.isfinite(d):
                    a = g - dark
                    s_a += a - a_b
                    s_ad += a * d - a_b * db
                    if (
                        saturated
                        and member[r, c]
                        and a > 0
                        and a >= SATURATED_MIN_CONTRAST * a_bp
                        and fs_a > a_bp
                    ):
                        c_max = min(max((a - a_bp) / (fs_a - a_bp), 0.0), 1.0)
                        lo = (a * d - a_bp * db) / (a - a_bp) if a > a_bp else d
                        wb = (1.0 - c_max) * a_bp
                        hi = (a * d - wb * db) / (a - wb)
                        mids[n_mid] = 0.5 * (lo + hi)
                        halves[n_mid] = max(0.5 * abs(hi - lo), SATURATED_HALF_WIDTH_FLOOR_MM)
                        n_mid += 1
                elif g_max > gb:
                    c_unranged += min(max((g - gb) / (g_max - gb), 0.0), 1.0)
        if not surrounds.crowded[j]:  # a neighbour's light would bias the sums
            out[j, 0], out[j, 1], out[j, 2], out[j, 3] = a_b, db, s_a, s_ad
            out[j, 4], out[j, 5] = c_unranged, n_sup
        if n_mid > 0:
            out[j, 6], out[j, 7] = _saturated_estimate(mids[:n_mid], halves[:n_mid])
    return out


@jit
def _saturated_estimate(mids, halves):
    """(range mm, sigma mm) of a saturated blob from its pixels' interval mid-points
    ``mids`` (k,) and half-widths ``halves`` (k,) (module docstring): the weighted
    median of the mid-points, weights 1 / half^2 (the first mid-point, in ascending
    order, where the cumulative weight reaches half), and sqrt(hbar^2 / 3 + (1.4826
    MAD)^2), hbar the weighted mean half-width."""
    k = mids.shape[0]
    order = np.argsort(mids)
    total, w_half = 0.0, 0.0
    for i in range(k):
        wt = 1.0 / (halves[i] * halves[i])
        total += wt
        w_half += wt * halves[i]
    acc = 0.0
    med = mids[order[k - 1]]
    for i in range(k):
        h = halves[order[i]]
        acc += 1.0 / (h * h)
        if acc >= 0.5 * total:
            med = mids[order[i]]
            break
    dev = np.abs(mids - med)
    mad = median_inplace(dev)
    spread = 1.4826 * mad
    hbar = w_half / total
    return med, np.sqrt(hbar * hbar / 3.0 + spread * spread)


@jit
def shift_mixing(row, shift_mm):
    """Shift every distance in a ``blob_mixing`` row (``MIX_FIELDS``,) by ``shift_mm`` in
    place (a range correction applied to the blob): d_b + shift, S_ad + shift S_a, so
    that the model's range moves by the same shift."""
    row[1] += shift_mm
    row[3] += shift_mm * row[2]
    row[6] += shift_mm


@jit
def unmixed_range(rho, mix, radius_px, cos_incidence, median_radius_px):
    """The reflector's own distance (mm) from its mixing sums (module docstring), or
    ``rho`` (the blob's median range) when the model does not apply: a disc of at least
    ``median_radius_px`` (most of its pixels are covered whole and the median is
    unbiased), no surround, a surround as bright as the reflector, or too little of the
    disc ranged.

    rho : mm; mix : (``MIX_FIELDS``,) ``blob_mixing`` row; radius_px : the catalog disc's
    apparent radius at rho; cos_incidence : of the disc's normal to the line of sight.
    Returns (range mm, C-sensitivity mm): the change of the range when C is 15 %
    larger, the model's own uncertainty (edges, the lens's spill beyond the support).
    A saturated blob (``mix[6]`` finite) whose unranged area C_unranged exceeds
    ``SATURATED_AREA_FRACTION`` of the disc's, or that has no sums (crowded: NaN
    C_unranged), gets its bounded-coverage range and sigma instead, at any size (its
    core has no distance: the median reads the rim)."""
    disc_area = np.pi * radius_px * radius_px * max(cos_incidence, 0.1)
    if np.isfinite(mix[6]) and not mix[4] <= SATURATED_AREA_FRACTION * disc_area:
        return mix[6], mix[7]
    if not radius_px < median_radius_px or not np.isfinite(mix[0]):
        return rho, 0.0
    area = disc_area
    c = area - mix[4]
    if not c > 0.25 * area:
        return rho, 0.0
    a_b, d_b, s_a, s_ad = mix[0], mix[1], mix[2], mix[3]
    a_r = a_b + s_a / c
    if not a_r > 2.0 * max(a_b, 0.0) or not a_r > 0:
        return rho, 0.0
    d_r = (a_b * d_b + s_ad / c) / a_r
    c2 = 1.15 * c
    a_r2 = a_b + s_a / c2
    d_r2 = (a_b * d_b + s_ad / c2) / a_r2
    if not np.isfinite(d_r):
        return rho, 0.0
    return d_r, abs(d_r2 - d_r)
