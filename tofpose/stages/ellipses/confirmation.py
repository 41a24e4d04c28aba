"""§3.3 ellipse confirmation of candidate blobs and the split of components too large
for one reflector (by arcs of the predicted size, by thresholds, or as a merged pair by
two centres and a model fit): what ``PosePipeline`` runs between candidate extraction and
persistence."""

from __future__ import annotations

import cv2
import numpy as np

from tofpose.config import ExtractionConfig
from tofpose.stages.ellipses.arithmetic import COMPILED, EllipsesArithmetic
from tofpose.stages.ellipses.ellipse import (
    blob_contour,
    ellipses_from_arcs,
    outline_ellipse,
    split_arcs,
)
from tofpose.stages.ellipses.kernels.two_centres import SPLIT_OK
from tofpose.stages.ellipses.pair_fit import fit_pair
from tofpose.stages.extraction.extraction import Blob, FrameStats, predicted_diameter_window_px


def confirm_ellipses(
    blobs: list[Blob],
    oversize: list[Blob],
    gray: np.ndarray,
    stats: FrameStats,
    *,
    fx_px: float,
    catalog_diameters_mm: np.ndarray,
    config: ExtractionConfig,
    arithmetic: EllipsesArithmetic = COMPILED,
) -> list[Blob]:
    """§3.3: confirm candidate shapes; split oversize components into ellipses.

    ``blobs`` are the accepted candidates, ``oversize`` the components too large for
    one reflector (``extraction.find_candidate_blobs``), ``gray`` the (h, w) amplitude
    image, ``fx_px`` the focal length, ``catalog_diameters_mm`` (n,) the reflectors'
    diameters (their count is the catalog's size).

    A candidate of >= 20 px whose boundary is not an ellipse (RMS > limit) is dropped.
    When there are fewer candidates than catalog reflectors, components rejected as
    too large are searched for elliptical arcs of the predicted size (supplement).
    """
    cfg = config
    ar = arithmetic
    h, w = gray.shape
    out = []
    min_points, max_rms_px = cfg.ellipse_min_points, cfg.ellipse_max_residual_px
    for b in blobs:
        if b.area_px >= 20:
            x, y, bw, bh = b.bbox
            mask = ar.blob_mask(b.pixels, x, y, bw, bh, w)  # blob_mask's, inlined
            fitted = outline_ellipse(mask, (x - 1, y - 1), min_points, arithmetic=ar)
            if fitted is not None:
                e, rms_px = fitted
                if rms_px > max_rms_px:
                    continue
                b = b.with_values(ellipse=e, ellipse_residual_px=rms_px)
        out.append(b)
    if len(out) >= len(catalog_diameters_mm) or not oversize:
        return out
    for comp in oversize:
        mask, x0, y0 = blob_mask(comp, w, ar)
        pts = blob_contour(mask)
        d_lo, d_hi = predicted_diameter_window_px(
            fx_px, comp.distance_mm, catalog_diameters_mm, cfg
        )
        arcs = split_arcs(pts, min_points=cfg.ellipse_min_points, arithmetic=ar)
        found = ellipses_from_arcs(
            arcs,
            d_min_px=d_lo,
            d_max_px=d_hi,
            max_residual_px=cfg.ellipse_max_residual_px,
            arithmetic=ar,
        )
        if not found:
            found_parts = split_by_threshold(
                comp, gray, stats.raw_threshold, d_hi, cfg.min_area_px, ar
            )
            out += found_parts or split_in_two(
                comp, gray, stats.background, d_lo, d_hi, cfg.min_area_px, ar
            )
        elif len(found) == 1:
            # one ellipse for a component too large for one reflector: at a few px
            # the outline of a merged pair fits one ellipse of a reflector's size
            # over part of it; a pair's two centres explain all of it
            pair = split_in_two(comp, gray, stats.background, d_lo, d_hi, cfg.min_area_px, ar)
            if pair:
                out += pair
                continue
        for e, _ in found:
            fill = np.zeros_like(mask)
            (cx, cy), (a1, a2), ang = e
            cv2.ellipse(fill, ((cx, cy), (a1, a2), ang), 1, -1)
            inside = (fill > 0) & (mask > 0)
            rows, cols = np.nonzero(inside)
            if len(rows) < cfg.min_area_px:
                continue
            nb = Blob(
                pixels=(rows + y0) * w + (cols + x0),
                area_px=len(rows),
                bbox=(
                    int(cols.min() + x0),
                    int(rows.min() + y0),
                    int(np.ptp(cols) + 1),
                    int(np.ptp(rows) + 1),
                ),
                peak_counts=float(gray[rows + y0, cols + x0].max()),
                ellipse=((cx + x0, cy + y0), (a1, a2), ang),
                source="ellipse",
            )
            out.append(nb)
    return out


SPLIT_LEVELS = 12


def split_by_threshold(
    comp: Blob,
    gray: np.ndarray,
    raw_threshold: float,
    d_max_px: float,
    min_area_px: int,
    arithmetic: EllipsesArithmetic = COMPILED,
) -> list[Blob]:
    """Ours (after §3.3): a component too large for one reflector whose outline gives no
    elliptical arcs (small merged markers, e.g. 7 and 8 beyond ~4 m, a few px each) is
    thresholded again at rising levels between I_t and its peak; at the first level where
    it falls apart into two or more parts of at least a tenth of the component each, and
    each no larger than one reflector, those parts' cores are the candidates (their range
    and centroid are measured later as for any blob). Returns [] when no level splits it."""
    h, w = gray.shape
    mask, x0, y0 = blob_mask(comp, w, arithmetic)
    patch = np.zeros(mask.shape, np.float32)
    rows, cols = np.nonzero(mask)
    patch[rows, cols] = gray[rows + y0, cols + x0]
    peak = float(patch.max())
    for level in np.linspace(raw_threshold, peak, SPLIT_LEVELS + 2)[1:-1]:
        n, labels, st, _ = cv2.connectedComponentsWithStats(
            (patch >= level).astype(np.uint8), connectivity=8
        )
        # parts that are cores of markers, not noise specks on one big disc: each holds
        # at least a tenth of the component
        big = max(min_area_px, 0.1 * comp.area_px)
        parts = [k for k in range(1, n) if st[k, cv2.CC_STAT_AREA] >= big]
        if len(parts) < 2:
            continue
        sizes = [2.0 * np.sqrt(st[k, cv2.CC_STAT_AREA] / np.pi) for k in parts]
        if max(sizes) > d_max_px:
            continue  # still a merged pair in one of the parts: go higher
        out = []
        for k in parts:
            pr, pc = np.nonzero(labels == k)
            out.append(
                Blob(
                    pixels=(pr + y0) * w + (pc + x0),
                    area_px=len(pr),
                    bbox=(
                        int(pc.min() + x0),
                        int(pr.min() + y0),
                        int(np.ptp(pc) + 1),
                        int(np.ptp(pr) + 1),
                    ),
                    peak_counts=float(patch[pr, pc].max()),
                    distance_mm=comp.distance_mm,
                    source="split",
                )
            )
        return out
    return []


#: Lloyd iterations of the two-centre split (they converge in 2-4 on a merged pair)
TWO_CENTRE_ITERATIONS = 8
#: the halves of a merged pair of like reflectors carry light within this ratio (gains
#: of aged or dirty reflectors differ by up to ~30 %, so a pair by up to ~2x)
PAIR_LIGHT_RATIO = 3.0


def split_in_two(
    comp: Blob,
    gray: np.ndarray,
    background: float,
    d_lo_px: float,
    d_hi_px: float,
    min_area_px: int,
    arithmetic: EllipsesArithmetic = COMPILED,
) -> list[Blob]:
    """Ours (after ``split_by_threshold``): a component the size of two reflectors whose
    light shows no dip between them (two discs a fraction of a pixel apart, integrated
    over the pixel area and blurred by the lens: markers 7 and 8 beyond ~6 m) is cut in
    two by intensity-weighted 2-means (Lloyd's iteration from the ends of its major
    axis), each half's pixels those nearer its centre. Taken only when the component is
    elongated as a pair is (major axis over minor >= 1.5), each half's equivalent
    diameter lies in the window of one reflector (``d_lo_px``..``d_hi_px``) and their
    light is within ``PAIR_LIGHT_RATIO``; returns [] otherwise. Each half's moment
    centroid leans towards the other (it keeps the neighbour's light at the cut), so the
    centres come from a model fit of the pair's pixels (``pair_fit.fit_pair``; no split
    when it fails) and replace the halves' centroids in the measurement
    (``Blob.fitted_uv``); ranges are measured on the halves as any blob's, and the
    centroid sigma keeps the split's term (``uncertainty.SPLIT_CENTROID_PX``). The 2-means
    is compiled (``kernels.two_centres.two_centre_split``; ``arithmetic``'s)."""
    w = gray.shape[1]
    rows, cols = np.divmod(np.asarray(comp.pixels), w)
    weight = np.maximum(gray[rows, cols].astype(float) - background, 0.0)
    if len(rows) < 2 * min_area_px or weight.sum() <= 0:
        return []
    near, centres, status = arithmetic.two_centre_split(
        cols.astype(float), rows.astype(float), weight, TWO_CENTRE_ITERATIONS
    )
    if status != SPLIT_OK:
        return []  # not elongated as two discs side by side are, or one-sided
    light = np.bincount(near, weights=weight, minlength=2)
    if light.max() > PAIR_LIGHT_RATIO * light.min():
        return []  # not two like reflectors (a marker and a glint, or a speck)
    for n_k in np.bincount(near, minlength=2).tolist():  # each half one reflector's size
        if n_k < min_area_px or not d_lo_px <= 2.0 * np.sqrt(n_k / np.pi) <= d_hi_px:
            return []
    fit = fit_pair(gray, comp.pixels, centres, background, arithmetic=arithmetic)
    if fit is None:
        return []  # the halves' moment centroids lean towards each other: not used
    # the fitted disc nearest each half's centroid is that half's centre
    order = np.argmin(((centres[:, None, :] - fit.centres_px[None, :, :]) ** 2).sum(axis=2), axis=1)
    if order[0] == order[1]:
        return []
    out = []
    for k in range(2):
        pr, pc = rows[near == k], cols[near == k]
        out.append(
            Blob(
                pixels=pr * w + pc,
                area_px=len(pr),
                bbox=(int(pc.min()), int(pr.min()), int(np.ptp(pc) + 1), int(np.ptp(pr) + 1)),
                peak_counts=float(gray[pr, pc].max()),
                distance_mm=comp.distance_mm,
                source="split",
                fitted_uv=fit.centres_px[order[k]],
            )
        )
    return out


def blob_mask(
    b: Blob, width: int, arithmetic: EllipsesArithmetic = COMPILED
) -> tuple[np.ndarray, int, int]:
    """Binary mask of a blob in its bounding box padded by 1 px, and the box origin."""
    x, y, bw, bh = b.bbox
    return arithmetic.blob_mask(b.pixels, x, y, bw, bh, width), x - 1, y - 1
