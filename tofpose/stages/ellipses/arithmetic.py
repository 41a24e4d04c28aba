"""The ellipse stage's arithmetic (§3.3) per implementation: ``COMPILED`` (its kernels)
and ``REFERENCE`` (``reference``), each field with the kernel's calling convention."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from tofpose.stages.ellipses.kernels import ellipses, pair_fit, two_centres
from tofpose.stages.ellipses.reference import ellipses as ref_ellipses
from tofpose.stages.ellipses.reference import pair_fit as ref_pair_fit
from tofpose.stages.ellipses.reference import two_centres as ref_two_centres


@dataclass(frozen=True)
class EllipsesArithmetic:
    """§3.3: ellipse confirmation, and the split of a merged pair (the arguments and
    returns of ``kernels.ellipses``, ``kernels.two_centres`` and ``kernels.pair_fit``)."""

    name: str
    blob_mask: Callable
    ellipse_rms_px: Callable
    arc_points: Callable
    two_centre_split: Callable
    fit_pair_lm: Callable


def _reference_two_centre_split(cols, rows, weight, iterations):
    """``reference.two_centres.two_centre_split`` with the kernel's status: ``SPLIT_OK``,
    or a refusal (``SPLIT_ROUND``; the reference does not say which) with empty halves."""
    split = ref_two_centres.two_centre_split(cols, rows, weight, iterations)
    if split is None:
        return np.zeros(len(cols), np.int64), np.full((2, 2), np.nan), two_centres.SPLIT_ROUND
    near, centres = split
    return np.asarray(near, np.int64), centres, two_centres.SPLIT_OK


COMPILED = EllipsesArithmetic(
    "compiled",
    ellipses.blob_mask,
    ellipses.ellipse_rms_px,
    ellipses.arc_points,
    two_centres.two_centre_split,
    pair_fit.fit_pair_lm,
)
REFERENCE = EllipsesArithmetic(
    "reference",
    ref_ellipses.blob_mask,
    ref_ellipses.ellipse_rms_px,
    ref_ellipses.arc_points,
    _reference_two_centre_split,
    ref_pair_fit.fit_pair_lm,
)
