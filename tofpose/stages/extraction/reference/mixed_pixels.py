"""Small markers' mixed pixels as stated (ours, beyond the paper's Eq. 20;
docs/algorithm.md, "Small markers: local surround and mixed pixels"): which blob owns
each pixel, the surround of each blob (its level, its range, whether a neighbour crowds
it), whether something in front of a blob hides part of it, the sums of the mixing
model and the reflector's own range from them.

The mixing model: a pixel p covered by the fraction c_p of a reflector returns
``c_p P_r + (1 - c_p) P_b``; amplitude a_p (gray above the no-return level) and a_p d_p
mix linearly, so that over the blob's support (its pixels dilated by one)

    S_a  = sum (a_p - a_b)         = C (A_r - a_b)
    S_ad = sum (a_p d_p - a_b d_b) = C (A_r d_r - a_b d_b),   C = sum c_p,

and with C from the catalog (``pi r_px^2 cos(incidence)``) the reflector's own range is
``d_r = (a_b d_b + S_ad / C) / (a_b + S_a / C)``.

Same names, arguments and returns as ``tofpose.stages.extraction.kernels.mixed_pixels`` (and
``kernels.centroids.owner_map``), so that one can stand in for the other. Shapes: gray
(H, W) float32 counts; distance (H, W) float32 mm, NaN where invalid; blobs as pixel
lists ``flat`` (P,) int64 flat indices (row * W + col) with blob j's at
``flat[starts[j]:starts[j + 1]]``, and boxes ``bbox`` (n, 4) int64 (x, y, w, h); the
owner map and the surrounds as the records ``owner_map`` and ``blob_surrounds`` return
(``stages.extraction.records.OwnerMap``, ``Surrounds``).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

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
from tofpose.stages.extraction.records import OwnerMap, Surrounds

#: 8-connectivity
_EIGHT = np.ones((3, 3), bool)


def _blob(flat, starts, j) -> np.ndarray:
    return np.asarray(flat[starts[j] : starts[j + 1]], np.int64)


def _box(bbox, j, grow, shape):
    """Blob j's box grown by ``grow`` px and clipped to the image: (y0, y1, x0, x1)."""
    x, y, bw, bh = (int(v) for v in bbox[j])
    h, w = shape
    return max(y - grow, 0), min(y + bh + grow, h), max(x - grow, 0), min(x + bw + grow, w)


def _members(flat, starts, j, window, width) -> np.ndarray:
    """(h', w') bool: blob j's pixels in the window (y0, y1, x0, x1)."""
    y0, y1, x0, x1 = window
    rows, cols = np.divmod(_blob(flat, starts, j), width)
    member = np.zeros((y1 - y0, x1 - x0), bool)
    member[rows - y0, cols - x0] = True
    return member


def _others(owners, j, window) -> np.ndarray:
    """(h', w') bool: the window's pixels that belong to a blob other than j (owners:
    an ``OwnerMap``)."""
    y0, y1, x0, x1 = window
    out = np.zeros((y1 - y0, x1 - x0), bool)
    if not owners.used:
        return out
    owner, ox, oy = owners.owner, owners.x0, owners.y0
    oh, ow = owner.shape
    r0, r1, c0, c1 = max(y0, oy), min(y1, oy + oh), max(x0, ox), min(x1, ox + ow)
    if r0 < r1 and c0 < c1:
        o = owner[r0 - oy : r1 - oy, c0 - ox : c1 - ox]
        out[r0 - y0 : r1 - y0, c0 - x0 : c1 - x0] = (o != -1) & (o != j)
    return out


def owner_map(flat, starts, bbox, h, w):
    """Which blob owns each pixel, where a neighbour's pixels must be left out: only when
    some blob's box grown by ``SURROUND_OUTER_PX`` overlaps another's box. Then owner
    (h', w') int32 (blob index, -1 none) over the union of the boxes grown by 2 px
    (clipped to the (h, w) image), its top-left pixel x0, y0 and True; else a (1, 1)
    map of -1, 0, 0, False: an ``OwnerMap``."""
    b = np.asarray(bbox, np.int64).reshape(-1, 4)
    x, y, bw, bh = b[:, 0], b[:, 1], b[:, 2], b[:, 3]
    s = SURROUND_OUTER_PX
    overlap = (
        (x[:, None] - s < (x + bw)[None])
        & (x[None] - s < (x + bw)[:, None])
        & (y[:, None] - s < (y + bh)[None])
        & (y[None] - s < (y + bh)[:, None])
    )
    np.fill_diagonal(overlap, False)
    if not overlap.any():
        return OwnerMap(owner=np.full((1, 1), -1, np.int32), x0=0, y0=0, used=False)
    x0, y0 = int(np.maximum(x - 2, 0).min()), int(np.maximum(y - 2, 0).min())
    x1, y1 = int(np.minimum(x + bw + 2, w).max()), int(np.minimum(y + bh + 2, h).max())
    owner = np.full((y1 - y0, x1 - x0), -1, np.int32)
    for j in range(len(b)):
        rows, cols = np.divmod(_blob(flat, starts, j), w)
        owner[rows - y0, cols - x0] = j
    return OwnerMap(owner=owner, x0=x0, y0=y0, used=True)


def blob_surrounds(bbox, gray, distance, owners):
    """Each blob's surround: the ring between its box grown by ``SURROUND_INNER_PX`` and
    by ``SURROUND_OUTER_PX`` (clipped to the image), other blobs' pixels (``owners``, an
    ``OwnerMap``) left out. Returns ``Surrounds``: gray (n,) the ring's median gray (NaN:
    no ring pixel), distance_mm (n,) the median of its ranges (NaN with fewer than 3) and
    crowded (n,) bool: another blob's pixels lie in the ring. Medians in float32, as
    ``np.median`` of float32."""
    n = len(bbox)
    level, depth = np.full(n, np.nan), np.full(n, np.nan)
    crowded = np.zeros(n, bool)
    for j in range(n):
        window = _box(bbox, j, SURROUND_OUTER_PX, gray.shape)
        y0, y1, x0, x1 = window
        x, y, bw, bh = (int(v) for v in bbox[j])
        si = SURROUND_INNER_PX
        ring = np.ones((y1 - y0, x1 - x0), bool)
        ring[
            max(y - si - y0, 0) : max(y + bh + si - y0, 0),
            max(x - si - x0, 0) : max(x + bw + si - x0, 0),
        ] = False
        others = _others(owners, j, window)
        crowded[j] = (ring & others).any()
        ring &= ~others
        g = gray[y0:y1, x0:x1][ring]
        d = distance[y0:y1, x0:x1][ring]
        d = d[np.isfinite(d)]
        if len(g):
            level[j] = np.median(g)
        if len(d) >= 3:
            depth[j] = np.median(d)
    return Surrounds(gray=level, distance_mm=depth, crowded=crowded)


def _outer_ring(bbox, j, window) -> np.ndarray:
    """(h', w') bool: the window's pixels on the outermost ring of the blob's box grown
    by ``SURROUND_OUTER_PX`` (as if not clipped: a side cut by the image has none)."""
    y0, y1, x0, x1 = window
    x, y, bw, bh = (int(v) for v in bbox[j])
    so = SURROUND_OUTER_PX
    rows = np.arange(y0, y1)[:, None]
    cols = np.arange(x0, x1)[None, :]
    return (
        (rows < y - so + 1)
        | (rows >= y + bh + so - 1)
        | (cols < x - so + 1)
        | (cols >= x + bw + so - 1)
    )


def occluded_blobs(flat, starts, bbox, distance, rho, owners):
    """(n,) bool: blob j is partly hidden by something in front of it. In its box grown
    by ``SURROUND_OUTER_PX`` (its own and other blobs' pixels left out), the ranged
    pixels nearer than ``rho[j] - OCCLUSION_MARGIN_MM`` that are 8-connected to a near
    pixel touching the blob (8-neighbour of a member) form a patch; occluded when the
    patch has at least ``OCCLUSION_MIN_PATCH_PX`` pixels, at least
    ``OCCLUSION_MIN_OUTER_PX`` of them on the window's outermost ring, and its median
    range is nearer than rho[j] by more than the larger of ``OCCLUSION_MARGIN_MM`` and
    ``OCCLUSION_NOISE_SIGMAS`` x 1.4826 MAD of the window's other ranged pixels (0 with
    fewer than 3). rho (n,) mm; owners : an ``OwnerMap``; a NaN range is never occluded."""
    n = len(bbox)
    w = distance.shape[1]
    out = np.zeros(n, bool)
    for j in range(n):
        if not np.isfinite(rho[j]):
            continue
        window = _box(bbox, j, SURROUND_OUTER_PX, distance.shape)
        y0, y1, x0, x1 = window
        member = _members(flat, starts, j, window, w)
        d = distance[y0:y1, x0:x1]
        ranged = ~member & np.isfinite(d) & ~_others(owners, j, window)
        near = ranged & (d.astype(float) < rho[j] - OCCLUSION_MARGIN_MM)
        touching = near & ndimage.binary_dilation(member, _EIGHT)
        labels, _ = ndimage.label(near, _EIGHT)
        patch = np.isin(labels, np.unique(labels[touching])) & near
        if patch.sum() < OCCLUSION_MIN_PATCH_PX:
            continue
        if (patch & _outer_ring(bbox, j, window)).sum() < OCCLUSION_MIN_OUTER_PX:
            continue
        rest = d[ranged & ~patch]
        scatter = 0.0
        if len(rest) >= 3:
            scatter = MAD_TO_SIGMA * float(np.median(np.abs(rest - np.median(rest))))
        margin = max(OCCLUSION_MARGIN_MM, OCCLUSION_NOISE_SIGMAS * scatter)
        out[j] = float(np.median(d[patch])) < rho[j] - margin
    return out


def blob_mixing(
    flat, starts, bbox, gray, member_distance, distance, surrounds, dark, owners, full_scale
):
    """The mixing model's sums of each blob over its support (its pixels dilated by one,
    other blobs' pixels left out): (n, ``MIX_FIELDS``) rows (a_b, d_b, S_a, S_ad,
    C_unranged, n_support, d_sat, sigma_sat), NaN rows for an unknown surround; a crowded
    blob has NaN sums (a neighbour's light would bias them), and only when saturated
    its d_sat, sigma_sat (its rims read towards the plate whatever its neighbours, so its
    bounded-coverage range is taken, with the surround ring's median level and distance
    as a_b and d_b);
    d_sat, sigma_sat as ``saturated_range`` of the blob's own ranged pixels (not the
    support's ring: beside a plate's edge it can be a wall metres behind), NaN unless a
    member reaches ``full_scale`` (counts).

    a_b = surrounds.gray - dark, d_b = surrounds.distance_mm; a support pixel with a range (from
    ``member_distance`` at the blob's pixels, ``distance`` elsewhere) adds
    a_p - a_b to S_a and a_p d_p - a_b d_b to S_ad (a_p = gray - dark); one without adds
    its covered fraction ``clip((g - g_b) / (g_max - g_b), 0, 1)`` to C_unranged, g_max
    the brightest member (nothing when no member is brighter than the surround).
    surrounds : ``blob_surrounds``' ``Surrounds``; dark : counts; owners : an ``OwnerMap``."""
    n = len(bbox)
    w = gray.shape[1]
    out = np.full((n, MIX_FIELDS), np.nan)
    for j in range(n):
        gb, db = surrounds.gray[j], surrounds.distance_mm[j]
        if not (np.isfinite(gb) and np.isfinite(db)):
            continue
        window = _box(bbox, j, 1, gray.shape)
        y0, y1, x0, x1 = window
        member = _members(flat, starts, j, window, w)
        g = gray[y0:y1, x0:x1].astype(float)
        g_max = max(gb, float(g[member].max()))
        if surrounds.crowded[j] and g_max < full_scale:
            continue
        support = ndimage.binary_dilation(member, _EIGHT)
        support &= ~_others(owners, j, window)
        d = np.where(member, member_distance[y0:y1, x0:x1], distance[y0:y1, x0:x1])
        d = d.astype(float)
        a_b = gb - dark
        ok = support & np.isfinite(d)
        a = g[ok] - dark
        s_a = float(np.sum(a - a_b))
        s_ad = float(np.sum(a * d[ok] - a_b * db))
        c_unranged = 0.0
        if g_max > gb:
            c_unranged = float(np.sum(np.clip((g[support & ~ok] - gb) / (g_max - gb), 0, 1)))
        if not surrounds.crowded[j]:  # a neighbour's light would bias the sums
            out[j, :6] = a_b, db, s_a, s_ad, c_unranged, support.sum()
        if g_max >= full_scale:  # from the blob's own ranged pixels (module docstring)
            own = member[ok]
            out[j, 6:] = saturated_range(a[own], d[ok][own], a_b, db, full_scale - dark)
    return out


def saturated_range(a, d, a_b, d_b, fs_a) -> tuple[float, float]:
    """A saturated reflector's distance and its sigma (mm) from its own ranged pixels
    (``blob_mixing`` passes the blob's members only), amplitudes ``a`` (k,) and
    distances ``d`` (k,) mm, the surround's amplitude ``a_b`` and distance ``d_b``
    and the full scale's amplitude ``fs_a`` (counts above the no-return level). Each
    pixel with ``a >= SATURATED_MIN_CONTRAST max(a_b, 0)`` bounds it between d_r(0)
    and d_r(c_max), ``d_r(c) = (a d - (1 - c) a_b d_b) / (a - (1 - c) a_b)``,
    ``c_max = clip((a - a_b) / (fs_a - a_b), 0, 1)`` (its coverage, A_r >= full
    scale); the weighted median of the mid-points, weights 1 / half-width^2 (floor
    ``SATURATED_HALF_WIDTH_FLOOR_MM``; the first mid-point in ascending order where the
    cumulative weight reaches half), and the sigma sqrt(hbar^2 / 3 + (1.4826 MAD)^2)
    (not over k: the pixels share one surround), hbar the weighted mean half-width,
    MAD the mid-points' median absolute deviation from that median. (NaN, NaN) when
    no pixel qualifies."""
    a_b = max(float(a_b), 0.0)
    use = (a > 0) & (a >= SATURATED_MIN_CONTRAST * a_b)
    if not (use.any() and fs_a > a_b):
        return np.nan, np.nan
    a, d = a[use], d[use]
    c_max = np.clip((a - a_b) / (fs_a - a_b), 0.0, 1.0)
    lo = np.where(a > a_b, (a * d - a_b * d_b) / np.where(a > a_b, a - a_b, 1.0), d)
    wb = (1.0 - c_max) * a_b
    hi = (a * d - wb * d_b) / (a - wb)
    half = np.maximum(0.5 * np.abs(hi - lo), SATURATED_HALF_WIDTH_FLOOR_MM)
    wt = 1.0 / half**2
    mid = 0.5 * (lo + hi)
    order = np.argsort(mid, kind="stable")
    at = int(np.searchsorted(np.cumsum(wt[order]), 0.5 * wt.sum()))
    med = float(mid[order[min(at, len(mid) - 1)]])
    spread = 1.4826 * float(np.median(np.abs(mid - med)))
    hbar = float(np.sum(wt * half) / wt.sum())
    return med, float(np.sqrt(hbar**2 / 3.0 + spread**2))


def shift_mixing(row, shift_mm):
    """A range correction ``shift_mm`` applied to a ``blob_mixing`` row (``MIX_FIELDS``,)
    in place: d_b + shift and S_ad + shift S_a (every distance in the sums moved)."""
    row[1] += shift_mm
    row[3] += shift_mm * row[2]
    row[6] += shift_mm


def unmixed_range(rho, mix, radius_px, cos_incidence, median_radius_px):
    """The reflector's own distance d_r from its mixing sums ``mix`` (``MIX_FIELDS``,),
    with C = pi radius_px^2 max(cos_incidence, 0.1) - C_unranged, and its sensitivity
    |d_r(1.15 C) - d_r(C)|: (d_r mm, sensitivity mm); a saturated blob's ``mix[6:8]``
    (``saturated_range``) whatever its size when C_unranged exceeds
    ``SATURATED_AREA_FRACTION`` of the disc's area or is NaN (a crowded blob: no sums).
    (rho, 0) where the model does not apply: radius_px not below ``median_radius_px``,
    no sums, C at most a quarter of the disc's area, A_r = a_b + S_a / C not above
    2 max(a_b, 0) or not positive, or a d_r that is not finite."""
    disc_area = np.pi * radius_px**2 * max(cos_incidence, 0.1)
    if np.isfinite(mix[6]) and not mix[4] <= SATURATED_AREA_FRACTION * disc_area:
        # saturation took most of the disc's range, or a crowded blob has no sums (NaN
        # C_unranged): the bounded-coverage range, any size
        return float(mix[6]), float(mix[7])
    a_b, d_b, s_a, s_ad, c_unranged = (float(v) for v in mix[:5])
    c = disc_area - c_unranged
    small = radius_px < median_radius_px and np.isfinite(a_b)
    if not (small and c > 0.25 * disc_area):
        return rho, 0.0
    a_r = a_b + s_a / c  # the reflector's amplitude
    if not (a_r > 2.0 * max(a_b, 0.0) and a_r > 0):
        return rho, 0.0
    d_r = (a_b * d_b + s_ad / c) / a_r
    if not np.isfinite(d_r):
        return rho, 0.0
    # the range with a 15 % larger image area
    d_r_wider = (a_b * d_b + s_ad / (1.15 * c)) / (a_b + s_a / (1.15 * c))
    return d_r, abs(d_r_wider - d_r)
