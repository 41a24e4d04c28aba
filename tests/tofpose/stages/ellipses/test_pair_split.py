"""The two-centre split of a merged pair (``confirmation.split_in_two``, with
``pair_fit.fit_pair``) on images of two discs integrated over the pixel area and
blurred, with known centres."""

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from tofpose.stages.ellipses.confirmation import split_in_two
from tofpose.stages.extraction.extraction import Blob

BACKGROUND = 100.0
SUPER = 8  # sub-samples per pixel side


def _discs(centres_px, radius_px, gains, blur_px, shape=(24, 32)):
    """(H, W) float32 image: discs of ``radius_px`` at ``centres_px`` (k, 2) (u, v),
    each pixel the mean over its area, blurred by a Gaussian PSF, on a background."""
    h, w = shape
    v, u = np.mgrid[0 : h * SUPER, 0 : w * SUPER]
    u = (u + 0.5) / SUPER - 0.5
    v = (v + 0.5) / SUPER - 0.5
    fine = np.zeros(u.shape)
    for (cu, cv), g in zip(centres_px, gains, strict=True):
        fine += g * ((u - cu) ** 2 + (v - cv) ** 2 <= radius_px**2)
    img = fine.reshape(h, SUPER, w, SUPER).mean(axis=(1, 3))
    return (BACKGROUND + 2000.0 * gaussian_filter(img, blur_px)).astype(np.float32)


def _component(img, threshold):
    """The above-threshold pixels as one Blob."""
    rows, cols = np.nonzero(img >= threshold)
    w = img.shape[1]
    return Blob(
        pixels=rows * w + cols,
        area_px=len(rows),
        bbox=(int(cols.min()), int(rows.min()), int(np.ptp(cols) + 1), int(np.ptp(rows) + 1)),
        distance_mm=6000.0,
    )


def _centroid(img, blob):
    rows, cols = np.divmod(blob.pixels, img.shape[1])
    wt = img[rows, cols] - BACKGROUND
    return np.array([(wt * cols).sum(), (wt * rows).sum()]) / wt.sum()


@pytest.mark.parametrize("blur_px", [0.6, 1.0])
@pytest.mark.parametrize("gains", [(1.0, 1.0), (1.0, 1.4)])
def test_a_merged_pair_is_cut_at_its_two_centres(gains, blur_px):
    """Markers 7 and 8 at ~6 m: 4.3 px discs 4.9 px apart (a 0.6 px gap), integrated over
    the pixel area, blurred, reflectors up to 40 % apart in gain, pixel noise: the
    two-centre split cuts the component in two (each half's moment centroid within 0.2
    px of its disc's centre, leaning towards the other), and the pair fit's centres,
    which the measurement uses, are within 0.05 px."""
    centres = np.array([[13.2, 11.6], [18.1, 11.9]])
    img = _discs(centres, 2.15, gains, blur_px)
    img += np.random.default_rng(5).normal(0.0, 20.0, img.shape).astype(np.float32)
    threshold = BACKGROUND + 0.25 * (img.max() - BACKGROUND)
    comp = _component(img, threshold)
    parts = split_in_two(comp, img, BACKGROUND, 1.0, 7.4, 3)
    assert len(parts) == 2 and all(p.source == "split" for p in parts)
    found = sorted((_centroid(img, p) for p in parts), key=lambda c: c[0])
    np.testing.assert_allclose(found, centres, atol=0.2)
    fitted = sorted((p.fitted_uv for p in parts), key=lambda c: c[0])
    np.testing.assert_allclose(fitted, centres, atol=0.05)
    assert set(parts[0].pixels).isdisjoint(parts[1].pixels)
    assert parts[0].area_px + parts[1].area_px == comp.area_px


def test_one_disc_and_a_marker_with_a_glint_are_not_cut():
    """A round disc is not elongated as a pair; a disc with a faint speck beside it
    carries unlike light in its halves: neither is cut."""
    one = _discs(np.array([[15.0, 12.0]]), 3.0, (1.0,), 0.6)
    t = BACKGROUND + 0.25 * (one.max() - BACKGROUND)
    assert split_in_two(_component(one, t), one, BACKGROUND, 1.0, 7.4, 3) == []
    glint = _discs(np.array([[13.0, 12.0], [17.2, 12.0]]), 2.15, (1.0, 0.15), 0.6)
    t = BACKGROUND + 0.05 * (glint.max() - BACKGROUND)
    assert split_in_two(_component(glint, t), glint, BACKGROUND, 1.0, 7.4, 3) == []
