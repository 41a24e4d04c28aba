"""Flat pixel indices (row * W + col) back to (row, col) without an integer division:
the kernels walk blobs given as flat index lists, and a 64-bit division per pixel cost
more than the rest of some of their loops; and the runs of such a list."""

from __future__ import annotations

from tofpose.core.compiled import jit


@jit
def row_col(p, width, inv_width):
    """(row, col) of flat index ``p`` >= 0 in an image ``width`` pixels wide;
    ``inv_width`` = 1.0 / width. floor((p + 0.5) / width) computed in float64 is exact:
    (p + 0.5) / width lies at least 0.5 / width from an integer, far more than the
    rounding error for any p below 2^50."""
    r = int((p + 0.5) * inv_width)
    return r, p - r * width


@jit
def run_end(flat, i, end, max_len):
    """The end (exclusive) of the run of consecutive flat indices that starts at
    ``flat[i]``, at most ``end`` and ``i + max_len`` (the pixels left in the row: pass
    W - col, so that a run never wraps into the next row). A blob's pixel list in
    raster order is its rows' runs one after another, and a run is contiguous in every
    image."""
    stop = min(end, i + max_len)
    e = i + 1
    while e < stop and flat[e] == flat[e - 1] + 1:
        e += 1
    return e
