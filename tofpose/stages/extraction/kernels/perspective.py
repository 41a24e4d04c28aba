"""Perspective bias of projected discs (§3.3's projected-circle bias), compiled; the
method is documented at ``tofpose.stages.extraction.extraction.disc_image_centre_offsets_px``."""

from __future__ import annotations

import numpy as np

from tofpose.core.compiled import jit


@jit
def disc_centre_offsets(K, centres, normal, radii):
    """Image ellipse centre minus projected centre, (m, 2) px, of discs with centres
    (m, 3) mm in the camera frame, a shared unit-able normal (3,) and radii (m,) mm.

    The centre of a conic is the pole of the line at infinity: with the disc's
    homography H = K [a b c] the image conic is Q = H^-T D H^-1, D = diag(1, 1, -r^2),
    so the centre is Q^-1 (0, 0, 1)^T = H D^-1 H^T (0, 0, 1)^T = H D^-1 h3, h3 the
    third row of H: two small products, no inverse (the same point as
    ``-Q[:2, :2]^-1 Q[:2, 2]``, the form ``extraction.disc_image_centre_offsets_px``
    states)."""
    n = normal / np.sqrt((normal**2).sum())
    ref = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    a = np.cross(n, ref)
    a = a / np.sqrt((a**2).sum())
    b = np.cross(n, a)
    m = centres.shape[0]
    out = np.empty((m, 2))
    H = np.empty((3, 3))
    for i in range(m):
        c = centres[i]
        for r in range(3):  # H = K [a b c]
            H[r, 0] = K[r, 0] * a[0] + K[r, 1] * a[1] + K[r, 2] * a[2]
            H[r, 1] = K[r, 0] * b[0] + K[r, 1] * b[1] + K[r, 2] * b[2]
            H[r, 2] = K[r, 0] * c[0] + K[r, 1] * c[1] + K[r, 2] * c[2]
        # D^-1 h3, then H times it (homogeneous ellipse centre)
        g0, g1, g2 = H[2, 0], H[2, 1], -H[2, 2] / (radii[i] ** 2)
        e0 = H[0, 0] * g0 + H[0, 1] * g1 + H[0, 2] * g2
        e1 = H[1, 0] * g0 + H[1, 1] * g1 + H[1, 2] * g2
        e2 = H[2, 0] * g0 + H[2, 1] * g1 + H[2, 2] * g2
        # the projected centre K c is H's third column
        out[i, 0] = e0 / e2 - H[0, 2] / H[2, 2]
        out[i, 1] = e1 / e2 - H[1, 2] / H[2, 2]
    return out
