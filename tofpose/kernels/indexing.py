"""Flat pixel indices (row * W + col) back to (row, col) without an integer division:
the kernels walk blobs given as flat index lists, and a 64-bit division per pixel cost
more than the rest of some of their loops."""

from __future__ import annotations

from tofpose.kernels import jit


@jit
def row_col(p, width, inv_width):
    """(row, col) of flat index ``p`` >= 0 in an image ``width`` pixels wide;
    ``inv_width`` = 1.0 / width. floor((p + 0.5) / width) computed in float64 is exact:
    (p + 0.5) / width lies at least 0.5 / width from an integer, far more than the
    rounding error for any p below 2^50."""
    r = int((p + 0.5) * inv_width)
    return r, p - r * width
