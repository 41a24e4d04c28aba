"""Frame pairs to PNG images for the dashboard, optionally with detection overlays."""

from __future__ import annotations

import cv2
import numpy as np

from tofpose.pipeline import PoseResult

FULL_SCALE_COUNTS = 4095
MATCHED_BGR = (80, 220, 80)
UNMATCHED_BGR = (60, 60, 255)
LABEL_BGR = (255, 255, 255)


def gray_to_u8(gray: np.ndarray) -> np.ndarray:
    """(H, W) uint16 counts -> (H, W) uint8, gamma 0.5 so that the dark plate stays
    visible beside bright reflectors; full scale maps to 255."""
    g = np.clip(gray.astype(np.float32) / FULL_SCALE_COUNTS, 0.0, 1.0)
    return np.round(255.0 * np.sqrt(g)).astype(np.uint8)


def distance_to_bgr(
    distance_mm: np.ndarray, range_mm: tuple[float, float] | None = None
) -> np.ndarray:
    """(H, W) float mm -> (H, W, 3) uint8 turbo colour map; invalid (NaN) pixels black.

    range_mm : colour scale limits; default the 2nd-98th percentile of valid pixels.
    """
    d = np.asarray(distance_mm, np.float32)
    valid = np.isfinite(d)
    if range_mm is None:
        if valid.any():
            lo, hi = np.percentile(d[valid], [2.0, 98.0])
        else:
            lo, hi = 0.0, 1.0
    else:
        lo, hi = range_mm
    hi = max(hi, lo + 1.0)
    x = np.zeros(d.shape, np.uint8)
    x[valid] = np.round(255.0 * np.clip((d[valid] - lo) / (hi - lo), 0.0, 1.0)).astype(np.uint8)
    bgr = cv2.applyColorMap(x, cv2.COLORMAP_TURBO)
    bgr[~valid] = 0
    return bgr


def draw_overlay(bgr: np.ndarray, result: PoseResult, scale: int) -> np.ndarray:
    """Draw matched blobs (green circle, centroid cross, catalog id) and unmatched blobs
    (red circle) on an image already upscaled by ``scale``."""
    out = bgr.copy()
    shift = 4  # sub-pixel drawing: coordinates in 1/16 px
    k = scale * (1 << shift)

    def px(u: float, v: float) -> tuple[int, int]:
        # pixel centres are at integer (u, v); the upscaled image's centre is (u + 0.5) s - 0.5
        return int(round(((u + 0.5) * scale - 0.5) * (1 << shift))), int(
            round(((v + 0.5) * scale - 0.5) * (1 << shift))
        )

    for m in result.matched:
        u, v = float(m.centroid_uv[0]), float(m.centroid_uv[1])
        r = max(np.sqrt(m.area_px / np.pi), 1.0) + 1.0
        c = px(u, v)
        cv2.circle(out, c, int(r * k), MATCHED_BGR, 1, cv2.LINE_AA, shift)
        arm = int(2 * scale * (1 << shift))
        cv2.line(out, (c[0] - arm, c[1]), (c[0] + arm, c[1]), MATCHED_BGR, 1, cv2.LINE_AA, shift)
        cv2.line(out, (c[0], c[1] - arm), (c[0], c[1] + arm), MATCHED_BGR, 1, cv2.LINE_AA, shift)
        org = (int((u + r + 1) * scale), int((v - r) * scale))
        cv2.putText(
            out, str(m.catalog_id), org, cv2.FONT_HERSHEY_SIMPLEX, 0.35 * scale, LABEL_BGR, 1,
            cv2.LINE_AA,
        )  # fmt: skip
    for u, v, _d in result.unmatched:
        cv2.circle(out, px(u, v), int(3 * k), UNMATCHED_BGR, 1, cv2.LINE_AA, shift)
    return out


def render_png(
    kind: str, gray: np.ndarray, distance_mm: np.ndarray, result: PoseResult | None, *,
    overlay: bool, scale: int = 1,
) -> bytes:  # fmt: skip
    """PNG bytes of the ``gray`` or ``distance`` image, upscaled ``scale`` x (nearest)."""
    if kind == "gray":
        img = cv2.cvtColor(gray_to_u8(gray), cv2.COLOR_GRAY2BGR)
    elif kind == "distance":
        img = distance_to_bgr(distance_mm)
    else:
        raise ValueError(f"unknown image kind {kind!r}; use 'gray' or 'distance'")
    if scale != 1:
        img = cv2.resize(img, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)
    if overlay and result is not None:
        img = draw_overlay(img, result, scale)
    ok, buf = cv2.imencode(".png", img)
    if not ok:
        raise RuntimeError("PNG encoding failed")
    return buf.tobytes()


def downsample_png(kind: str, gray: np.ndarray, distance_mm: np.ndarray, step: int) -> bytes:
    """A small PNG for live streaming: every ``step``-th pixel (area-averaged)."""
    img = gray_to_u8(gray) if kind == "gray" else distance_to_bgr(distance_mm)
    if step > 1:
        h, w = img.shape[:2]
        img = cv2.resize(img, (w // step, h // step), interpolation=cv2.INTER_AREA)
    ok, buf = cv2.imencode(".png", img)
    if not ok:
        raise RuntimeError("PNG encoding failed")
    return buf.tobytes()
