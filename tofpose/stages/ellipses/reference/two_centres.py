"""The split of a merged pair's pixels in two (ours: markers 7 and 8 beyond ~6 m):
intensity-weighted 2-means by Lloyd's iteration from the ends of the major axis."""

from __future__ import annotations

import numpy as np

from tofpose.stages.ellipses.constants import MIN_ELONGATION


def two_centre_split(cols, rows, weight, iterations):
    """(near (n,) 0/1, centres (2, 2) rows (u, v)) of pixels (cols, rows) weighted by
    ``weight`` (n,), or None when the pixels are not elongated as two discs side by side
    are or every pixel falls to one centre. The major axis by LAPACK; ties to the first
    centre (argmin)."""
    pts = np.column_stack((cols, rows)).astype(float)
    weight = np.asarray(weight, float)
    mean = (weight[:, None] * pts).sum(axis=0) / weight.sum()
    centred = pts - mean
    cov = (weight[:, None, None] * centred[:, :, None] * centred[:, None, :]).sum(axis=0)
    evals, evecs = np.linalg.eigh(cov / weight.sum())
    if evals[0] <= 0 or evals[1] < MIN_ELONGATION**2 * evals[0]:
        return None
    along = centred @ evecs[:, 1]
    centres = mean + np.array([along.min(), along.max()])[:, None] * evecs[:, 1][None] / 2
    near = np.zeros(len(pts), int)
    for _ in range(iterations):
        near = np.argmin(((pts[:, None, :] - centres[None]) ** 2).sum(axis=2), axis=1)
        if near.min() == near.max():
            return None
        centres = np.array(
            [
                (weight[near == k, None] * pts[near == k]).sum(axis=0) / weight[near == k].sum()
                for k in range(2)
            ]
        )
    return near, centres
