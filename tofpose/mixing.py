"""The mixing sums of blobs (``kernels.mixed_pixels``) as the solver takes them."""

from __future__ import annotations

import numpy as np

from tofpose.kernels.mixed_pixels import MIX_FIELDS, shift_mixing


def mixing_rows(blobs) -> np.ndarray:
    """(n, ``MIX_FIELDS``) float64: each blob's mixing sums, NaN rows for blobs that
    have none."""
    out = np.full((len(blobs), MIX_FIELDS), np.nan)
    for j, b in enumerate(blobs):
        if b.mixing is not None:
            out[j] = b.mixing
    return out


def shifted_mixing(mixing: np.ndarray | None, shift_mm: float) -> np.ndarray | None:
    """A copy of the sums with every distance in them shifted by ``shift_mm``
    (``kernels.mixed_pixels.shift_mixing``). (MIX_FIELDS,) or None."""
    if mixing is None:
        return None
    out = np.array(mixing, float)
    shift_mixing(out, float(shift_mm))
    return out
