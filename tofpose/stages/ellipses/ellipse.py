"""Ellipse confirmation of reflector blobs (§3.3, Eqs. 21-24).

edge -> arcs -> ellipse: the blob's boundary (OpenCV contour following) is split into
elliptical arcs at corners (angle condition, AC) and inflections (curvature condition,
CC); arcs with fewer than Th_nc points are dropped (point condition, PC); each arc is fitted
with a direct least-squares ellipse (OpenCV ``fitEllipseDirect``, Fitzgibbon 1999 -- we use
it in place of ElliFit [24]); arcs whose ellipses agree are grouped. A single blob is
confirmed when one ellipse explains its whole boundary; a component too large for one
reflector (markers merged with each other or with a glint) is split into the ellipses its
arcs support (the "supplement" of §3.3).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from tofpose.stages.ellipses.arithmetic import COMPILED, EllipsesArithmetic

Ellipse = tuple[tuple[float, float], tuple[float, float], float]


def blob_contour(mask: np.ndarray, origin: tuple[int, int] = (0, 0)) -> np.ndarray:
    """Outer boundary of the largest region of a binary mask, shape (P, 2) float32 as
    (u, v), shifted by ``origin`` (the mask's top-left pixel in the image)."""
    contours, _ = cv2.findContours(
        np.asarray(mask, np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE, offset=origin
    )
    if not contours:
        return np.empty((0, 2), np.float32)
    c = contours[0] if len(contours) == 1 else max(contours, key=len)
    return c.reshape(-1, 2).astype(np.float32)


def fit_ellipse(points: np.ndarray) -> Ellipse | None:
    """Direct least-squares ellipse ((cx, cy), (axis1, axis2), angle_deg) of (P, 2)."""
    if len(points) < 5:
        return None
    try:
        e = cv2.fitEllipseDirect(np.asarray(points, np.float32).reshape(-1, 1, 2))
    except cv2.error:
        return None
    (cx, cy), (a1, a2), ang = e
    if not (math.isfinite(cx + cy + a1 + a2) and a1 > 0 and a2 > 0):
        return None
    return (float(cx), float(cy)), (float(a1), float(a2)), float(ang)


def ellipse_residual_px(
    ellipse: Ellipse, points: np.ndarray, *, arithmetic: EllipsesArithmetic = COMPILED
) -> float:
    """RMS approximate geometric distance of points (P, 2) from an ellipse, pixels.

    Uses the Sampson-like radial measure: |r_point - r_ellipse(theta)| along the ray from
    the centre, exact for circles and accurate for moderate eccentricity
    (``ellipse_rms_px`` of ``arithmetic``).
    """
    (cx, cy), (a1, a2), ang = ellipse
    pts = points if points.dtype == np.float32 else np.asarray(points, np.float64)
    pts = np.ascontiguousarray(pts).reshape(-1, 2)  # float32 exact in the float64 sums
    return float(
        arithmetic.ellipse_rms_px(float(cx), float(cy), float(a1), float(a2), float(ang), pts)
    )


def outline_ellipse(
    mask: np.ndarray,
    origin: tuple[int, int],
    min_points: int,
    *,
    arithmetic: EllipsesArithmetic = COMPILED,
) -> tuple[Ellipse, float] | None:
    """A candidate blob's confirmation step in one pass: its outer boundary
    (``blob_contour`` of the uint8 mask (h, w) whose top-left pixel is ``origin``), the
    direct least-squares ellipse of it (``fit_ellipse``) and the boundary's RMS distance
    from that ellipse, px (``ellipse_residual_px``), with the same arithmetic and no
    intermediate copies (``confirmation.confirm_ellipses`` runs it on every candidate).
    Returns (ellipse, rms_px), or None when the boundary has fewer than ``min_points``
    (or 5) points or no ellipse fits it."""
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE, offset=origin)
    if not contours:
        return None
    c = contours[0] if len(contours) == 1 else max(contours, key=len)
    n = c.shape[0]
    if n < min_points or n < 5:
        return None
    pts = c.astype(np.float32)  # (P, 1, 2), as fitEllipseDirect takes it
    try:
        (cx, cy), (a1, a2), ang = cv2.fitEllipseDirect(pts)
    except cv2.error:
        return None
    if not (math.isfinite(cx + cy + a1 + a2) and a1 > 0 and a2 > 0):
        return None
    e = (float(cx), float(cy)), (float(a1), float(a2)), float(ang)
    rms_px = arithmetic.ellipse_rms_px(e[0][0], e[0][1], e[1][0], e[1][1], e[2], pts.reshape(n, 2))
    return e, float(rms_px)


def split_arcs(
    contour: np.ndarray,
    *,
    angle_deg: float = 40.0,
    min_points: int = 6,
    smooth_sigma: float = 2.0,
    arithmetic: EllipsesArithmetic = COMPILED,
) -> list[np.ndarray]:
    """Split a closed contour (P, 2) into elliptical arcs (§3.3 AC, CC, PC).

    The contour is smoothed along its length (Gaussian, ``smooth_sigma`` points, so pixel
    staircases do not count as curvature); the turning angle xi between successive
    tangents (lag 2) is computed. The contour is broken where |xi| exceeds ``angle_deg``
    (a corner, AC) and where it turns against the contour's dominant direction (a concave
    point between two convex arcs, CC). Arcs with fewer than ``min_points`` contour
    points are dropped (PC). Returns the arcs as arrays of original contour points.
    """
    n = len(contour)
    if n < 2 * min_points:
        return [contour] if n >= min_points else []
    index, starts = arithmetic.arc_points(
        np.ascontiguousarray(contour, np.float64),
        float(angle_deg),
        int(min_points),
        float(smooth_sigma),
    )
    return [contour[index[starts[a] : starts[a + 1]]] for a in range(len(starts) - 1)]


def ellipses_from_arcs(
    arcs: list[np.ndarray],
    *,
    d_min_px: float,
    d_max_px: float,
    max_residual_px: float,
    arithmetic: EllipsesArithmetic = COMPILED,
) -> list[tuple[Ellipse, np.ndarray]]:
    """Fit each arc, keep ellipses of plausible size, merge arcs with agreeing ellipses.

    Returns a list of (ellipse, supporting points (P, 2)).
    """
    fits: list[tuple[Ellipse, np.ndarray]] = []
    for arc in arcs:
        e = fit_ellipse(arc)
        if e is None:
            continue
        major, minor = max(e[1]), min(e[1])
        if not (d_min_px <= minor and major <= d_max_px):
            continue
        if ellipse_residual_px(e, arc, arithmetic=arithmetic) > max_residual_px:
            continue
        fits.append((e, arc))
    groups: list[tuple[Ellipse, np.ndarray]] = []
    for e, pts in sorted(fits, key=lambda f: -len(f[1])):
        for g_i, (ge, gpts) in enumerate(groups):
            tol = 0.25 * max(ge[1])
            if np.hypot(e[0][0] - ge[0][0], e[0][1] - ge[0][1]) < tol:
                merged = np.vstack((gpts, pts))
                me = fit_ellipse(merged) or ge
                groups[g_i] = (me, merged)
                break
        else:
            groups.append((e, pts))
    return groups


def cone_distance_mm(ellipse: Ellipse, K: np.ndarray, radius_mm: float) -> float:
    """Distance to a circle of known radius from its image ellipse (Eqs. 22-24).

    Back-projects the ellipse to the cone Q_v = K^T C K (normalised coordinates), orders
    its eigenvalues (lambda1, lambda2 of one sign with |lambda1| >= |lambda2|, lambda3 of
    the other) and returns the distance to the circle centre along the cone's axis,
    ``z = R * sqrt(|lambda1| (|lambda2| + |lambda3|) / (|lambda3| (|lambda1| + |lambda3|)))``
    (Eq. 24 with R the circle radius). Returns NaN for a degenerate conic.
    """
    (cx, cy), (a1, a2), ang = ellipse
    t = np.radians(ang)
    c, s = np.cos(t), np.sin(t)
    Rm = np.array([[c, -s], [s, c]])
    Dm = np.diag([1.0 / (a1 / 2) ** 2, 1.0 / (a2 / 2) ** 2])
    A2 = Rm @ Dm @ Rm.T
    centre = np.array([cx, cy])
    C = np.zeros((3, 3))
    C[:2, :2] = A2
    C[:2, 2] = C[2, :2] = -A2 @ centre
    C[2, 2] = centre @ A2 @ centre - 1.0
    Q = K.T @ C @ K
    mu = np.linalg.eigvalsh(Q)
    pos, neg = mu[mu > 0], mu[mu < 0]
    if len(pos) == 2 and len(neg) == 1:
        l12, l3 = pos, neg[0]
    elif len(neg) == 2 and len(pos) == 1:
        l12, l3 = neg, pos[0]
    else:
        return float("nan")
    l1, l2 = sorted(np.abs(l12), reverse=True)
    l3 = abs(l3)
    return float(radius_mm * np.sqrt(l1 * (l2 + l3) / (l3 * (l1 + l3))))
