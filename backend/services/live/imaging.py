"""Frame pairs to PNG images for the dashboard, optionally with detection overlays."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor

import cv2
import numpy as np

from tofpose.io.interop.previews import FULL_SCALE_COUNTS as PREVIEW_FULL_SCALE
from tofpose.io.interop.previews import distance_to_bgr, gray_to_u8
from tofpose.pipeline import PoseResult

MATCHED_BGR = (80, 220, 80)
UNMATCHED_BGR = (60, 60, 255)
LABEL_BGR = (255, 255, 255)


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
            out,
            str(m.catalog_id),
            org,
            cv2.FONT_HERSHEY_SIMPLEX,
            0.35 * scale,
            LABEL_BGR,
            1,
            cv2.LINE_AA,
        )
    for u, v, _d in result.unmatched:
        cv2.circle(out, px(u, v), int(3 * k), UNMATCHED_BGR, 1, cv2.LINE_AA, shift)
    return out


def gray_u8(gray: np.ndarray, full_scale_counts: float) -> np.ndarray:
    """(H, W) counts -> (H, W) uint8 as ``gray_to_u8`` draws it (gamma 0.5, full scale
    255), at the camera's own full scale (``CameraModel.full_scale_counts``: 4095 for
    the TOFcam-660, 65535 for an Azure Kinect's IR)."""
    return gray_to_u8(gray, full_scale_counts)


def render_png(
    kind: str,
    gray: np.ndarray,
    distance_mm: np.ndarray,
    result: PoseResult | None,
    *,
    overlay: bool,
    scale: int = 1,
    full_scale_counts: float = PREVIEW_FULL_SCALE,
) -> bytes:
    """PNG bytes of the ``gray`` or ``distance`` image, upscaled ``scale`` x (nearest);
    gray up to the camera's ``full_scale_counts``."""
    if kind == "gray":
        img = cv2.cvtColor(gray_u8(gray, full_scale_counts), cv2.COLOR_GRAY2BGR)
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


def downsample_png(
    kind: str,
    gray: np.ndarray,
    distance_mm: np.ndarray,
    step: int,
    *,
    full_scale_counts: float = PREVIEW_FULL_SCALE,
) -> bytes:
    """A small PNG for live streaming: every ``step``-th pixel (area-averaged)."""
    img = gray_u8(gray, full_scale_counts) if kind == "gray" else distance_to_bgr(distance_mm)
    if step > 1:
        h, w = img.shape[:2]
        img = cv2.resize(img, (w // step, h // step), interpolation=cv2.INTER_AREA)
    ok, buf = cv2.imencode(".png", img)
    if not ok:
        raise RuntimeError("PNG encoding failed")
    return buf.tobytes()


class ImageRenderer:
    """Renders PNGs off the event loop and off the acquisition thread, in bounded memory
    and bounded work.

    One worker thread renders (OpenCV releases the GIL while it resizes and encodes; one
    renderer cannot starve the acquisition loop however many clients ask). The cache
    holds one entry per *variant* (kind and options), not per frame: a request for the
    latest frame gets that variant's render if it is of the latest frame or still in
    progress, and starts a new render only when the cached one is done and older; the
    worker renders at most ``max_duty`` of the time. So at
    most one render per variant is ever queued (requests faster than the renderer get a
    frame or two older, named in the result), and memory is at most one PNG per variant:
    32 variants (16 REST, 16 WebSocket) of at most ~1 MB each.
    """

    def __init__(self, workers: int = 1, max_duty: float = 0.5) -> None:
        if not 0.0 < max_duty <= 1.0:
            raise ValueError(f"max_duty must be in (0, 1], got {max_duty}")
        self.max_duty = max_duty
        self._next_start = 0.0  # monotonic time before which the worker rests
        self._pool = ThreadPoolExecutor(workers, thread_name_prefix="render")
        self._cache: dict[tuple, tuple[int, Future]] = {}
        self._lock = threading.Lock()
        self.renders = 0  # how many PNGs were actually encoded (for tests and status)
        self.busy_s = 0.0  # time spent rendering

    def _get(self, variant: tuple, frame_index: int, make: Callable[[], bytes]) -> Future:
        """Future of (frame_index, png) for ``variant``; see the class docstring."""
        with self._lock:
            entry = self._cache.get(variant)
            if entry is not None:
                cached_index, fut = entry
                if cached_index >= frame_index or not fut.done():
                    return fut

            def run() -> tuple[int, bytes]:
                # Duty cycle: after a render of dt, rest dt (1/duty - 1), so that open
                # reads can never take more than max_duty of a core from the live loop.
                time.sleep(max(0.0, self._next_start - time.monotonic()))
                t0 = time.monotonic()
                png = make()
                t1 = time.monotonic()
                self._next_start = t1 + (t1 - t0) * (1.0 / self.max_duty - 1.0)
                self.renders += 1
                self.busy_s += t1 - t0
                return frame_index, png

            fut = self._pool.submit(run)
            self._cache[variant] = (frame_index, fut)
            return fut

    def png(
        self,
        frame_index: int,
        kind: str,
        gray: np.ndarray,
        distance_mm: np.ndarray,
        result: PoseResult | None,
        *,
        overlay: bool,
        scale: int,
        full_scale_counts: float = PREVIEW_FULL_SCALE,
    ) -> Future:
        """Future of (frame_index, PNG bytes) of ``render_png(...)``."""
        return self._get(
            ("png", kind, overlay, scale, full_scale_counts),
            frame_index,
            lambda: render_png(
                kind,
                gray,
                distance_mm,
                result,
                overlay=overlay,
                scale=scale,
                full_scale_counts=full_scale_counts,
            ),
        )

    def stream_png(
        self,
        frame_index: int,
        kind: str,
        gray: np.ndarray,
        distance_mm: np.ndarray,
        step: int,
        *,
        full_scale_counts: float = PREVIEW_FULL_SCALE,
    ) -> Future:
        """Future of (frame_index, PNG bytes) of ``downsample_png(...)`` (live images)."""
        return self._get(
            ("stream", kind, step, full_scale_counts),
            frame_index,
            lambda: downsample_png(
                kind, gray, distance_mm, step, full_scale_counts=full_scale_counts
            ),
        )

    def cached_entries(self) -> int:
        with self._lock:
            return len(self._cache)

    def close(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)
