"""The calibrated range correction applied to measured blobs, all blobs in one call: the
arithmetic of ``RangeCorrection.error_mm`` (the model's definition, in
``tofpose.calibration.range``) evaluated at each blob's pixels, and its median taken off
the blob's range."""

from __future__ import annotations

import numpy as np

from tofpose.core.compiled import jit
from tofpose.core.kernels.stats import median_inplace


@jit
def corrected_ranges(rho, flat, starts, gray, model, harmonics, pixel_offsets):
    """Each blob's range less the median of the modelled error over its pixels.

    rho : (n,) mm measured ranges (NaN stays NaN); blob j's pixels are
    ``flat[starts[j]:starts[j + 1]]`` (flat indices); gray : (H, W) float32, the
    amplitude proxy (I-bar); model : (4,) float64 (unambiguous range mm, constant
    offset mm, amplitude mm per decade, amplitude reference counts); harmonics : (k, 2)
    (sine, cosine) mm of the 4k-th phase harmonics; pixel_offsets : (H * W,) mm, or
    empty for none. Returns (n,) float64.
    """
    u, offset, k_amp, a_ref = model[0], model[1], model[2], model[3]
    gray_f = gray.reshape(-1)
    use_pixel = pixel_offsets.shape[0] > 0
    out = rho.copy()
    for j in range(rho.shape[0]):
        d = rho[j]
        if not np.isfinite(d):
            continue
        # the distance terms are the same at every pixel of the blob (error_mm evaluates
        # the model at the blob's range): summed once, in error_mm's order of additions,
        # so that each pixel's sum is the same float arithmetic
        phi = 2.0 * np.pi * d / u
        common = offset
        for k in range(harmonics.shape[0]):
            common += harmonics[k, 0] * np.sin(4 * (k + 1) * phi) + harmonics[k, 1] * np.cos(
                4 * (k + 1) * phi
            )
        err = np.empty(starts[j + 1] - starts[j])
        for i in range(starts[j], starts[j + 1]):
            a = max(np.float64(gray_f[flat[i]]), 1e-3)
            e = common + k_amp * np.log10(a / a_ref)
            if use_pixel:
                e += pixel_offsets[flat[i]]
            err[i - starts[j]] = e
        out[j] = d - median_inplace(err)
    return out
