"""Raw frames for the browser: one binary WebSocket message per frame pair, uint16.

Layout (little-endian), ``HEADER_BYTES`` = 24 then the pixels, rows first:

======  =====  =============================================================
offset  type   field
======  =====  =============================================================
0       4 B    magic ``b"TOFR"``
4       u16    format version (1)
6       u16    step: the frame was subsampled every ``step``-th row and column
8       u32    frame index (pairs the frame with its ``pose`` message)
12      u16    width (px, after subsampling)
14      u16    height (px)
16      u32    the camera's gray full scale (counts; ``CameraModel.full_scale_counts``,
               0 = not stated): the browser's gray scale tops out there
20      u32    reserved (0)
24      u16[]  gray counts, width x height
...     u16[]  distance in mm, width x height; 0 = invalid, 65535 = 65.535 m or more
======  =====  =============================================================

The browser colour-maps them itself (no PNG encoding on the server; ESPROS's own web
viewer streams its cameras the same way).
"""

from __future__ import annotations

import struct

import numpy as np

MAGIC = b"TOFR"
VERSION = 1
HEADER = struct.Struct("<4sHHIHHII")
HEADER_BYTES = HEADER.size  # 24: the pixel arrays start 2-byte aligned


def encode_raw_frame(
    frame_index: int,
    gray: np.ndarray,
    distance_mm: np.ndarray,
    step: int = 1,
    *,
    full_scale_counts: float = 0,
) -> bytes:
    """One binary message of a frame pair. gray : (H, W) uint16 counts; distance_mm :
    (H, W) float, NaN invalid; full_scale_counts : the camera's saturation level (0 = not
    stated)."""
    g = np.ascontiguousarray(gray[::step, ::step], dtype="<u2")
    d = distance_mm[::step, ::step]
    d16 = np.where(np.isfinite(d) & (d > 0), np.clip(np.rint(d), 1, 65535), 0).astype("<u2")
    h, w = g.shape
    full_scale = int(round(full_scale_counts))
    if not 0 <= full_scale <= 0xFFFFFFFF:
        raise ValueError(f"full_scale_counts must be in [0, 2**32), got {full_scale_counts}")
    head = HEADER.pack(MAGIC, VERSION, step, frame_index & 0xFFFFFFFF, w, h, full_scale, 0)
    return head + g.tobytes() + d16.tobytes()


def decode_raw_frame(message: bytes) -> tuple[int, int, np.ndarray, np.ndarray]:
    """(frame_index, step, gray (h, w) uint16, distance_mm (h, w) float32 NaN invalid): the
    inverse of ``encode_raw_frame`` (tests and Python clients)."""
    if len(message) < HEADER_BYTES:
        raise ValueError(f"raw frame of {len(message)} bytes is shorter than its header")
    magic, version, step, index, w, h, _, _ = HEADER.unpack_from(message)
    if magic != MAGIC or version != VERSION:
        raise ValueError(f"not a raw frame (magic {magic!r}, version {version})")
    n = w * h
    if len(message) != HEADER_BYTES + 4 * n:
        raise ValueError(
            f"raw frame of {w} x {h} px needs {HEADER_BYTES + 4 * n} bytes, got {len(message)}"
        )
    pix = np.frombuffer(message, "<u2", offset=HEADER_BYTES)
    gray = pix[:n].reshape(h, w).copy()
    d = pix[n:].reshape(h, w).astype(np.float32)
    d[d == 0] = np.nan
    return index, step, gray, d


def raw_frame_full_scale(message: bytes) -> int:
    """The gray full scale a raw frame states (counts, 0 = not stated)."""
    return int(HEADER.unpack_from(message)[6])
