"""The reference statement of §3.1-§3.2 (``tofpose.stages.extraction.reference.extraction``):
against the
compiled path (``tofpose.stages.extraction.extraction.frame_levels`` and ``find_candidate_blobs``,
that is
``kernels.levels`` and ``kernels.gates``) on rendered frames over the operating range,
and against known truth on drawn frames."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from tests.conftest import facing_pose, render
from tofpose.config import ExtractionConfig
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.sim.background import synthetic_room
from tofpose.sim.render import SensorModel
from tofpose.sim.scene import Clutter, TargetScene
from tofpose.stages.extraction import extraction
from tofpose.stages.extraction.reference import extraction as reference

CAM = CameraModel()
#: spurious reflections: discs of other sizes, one tilted (an elongated image), one small
#: and bright
CLUTTER = (
    Clutter((250.0, 180.0, 20.0), 60.0, 1.2),
    Clutter((-420.0, -230.0, 10.0), 40.0, 0.8),
    Clutter((650.0, 0.0, -100.0), 70.0, 1.5),
    Clutter((-300.0, 200.0, 30.0), 150.0, 0.3, (0.9, 0.0, 0.44)),
    Clutter((100.0, -230.0, 10.0), 12.0, 3.0),
)
#: the drawn frame's range and catalog: a 100 mm disc at 2 m is 16.25 px across
DRAWN_RANGE_MM = 2000.0
DRAWN_DIAMETERS_MM = np.array([100.0, 80.0])


@cache
def _rendered(distance_mm, seed, blur_px):
    """(gray, distance, diameters) of the paper target at ``distance_mm`` (the paper's
    697 mm aim point on the plate, tilted a few degrees) with ``CLUTTER`` in a random
    room, through a lens PSF of ``blur_px``, as ``check_frame`` hands them on."""
    rng = np.random.default_rng(seed)
    scene = TargetScene(clutter=CLUTTER, background=synthetic_room(CAM, rng, distance_mm))
    frame = render(
        facing_pose(distance_mm, 4, -6, 12, offset_mm=(-110.0, -55.0)),
        seed=seed,
        scene=scene,
        sensor=SensorModel(blur_sigma_px=blur_px),
    )
    g, d = extraction.check_frame(CAM, frame.gray, frame.distance_mm)
    return g, d, paper_target().diameters_mm


def _disc(centre_uv, radius_px):
    """(H, W) bool: the pixels whose centres are within ``radius_px`` of ``centre_uv``."""
    v, u = np.mgrid[0 : CAM.height, 0 : CAM.width]
    return np.hypot(u - centre_uv[0], v - centre_uv[1]) <= radius_px


#: the drawn frame's shapes: (mask, counts), and the gate each meets (default settings)
DRAWN = {
    "accepted": (_disc((60, 60), 8), 2000.0),  # 197 px, 17 px across: a 100 mm disc
    "oversize": (_disc((250, 60), 30), 4095.0),  # saturated, 61 px across
    "nlog": (~_disc((160, 60), 7.5) & _disc((160, 60), 8.5), 2000.0),  # a 1 px thin ring
    "border": (_disc((0, 120), 8), 2000.0),
    "shape": (np.pad(np.ones((2, 20), bool), ((120, 118), (40, 260))), 2000.0),  # a bar
    "dim": (_disc((100, 180), 8), 900.0),  # between I_t and I_peak
    "size": (np.pad(np.ones((2, 2), bool), ((200, 38), (200, 118))), 2000.0),  # 2 x 2 px
}


@cache
def _drawn():
    """(gray, distance, diameters): the ``DRAWN`` shapes on a level of 10 counts, every
    pixel at ``DRAWN_RANGE_MM``."""
    g = np.full(CAM.shape, 10.0, np.float32)
    for mask, counts in DRAWN.values():
        g[mask] = counts
    return g, np.full(CAM.shape, DRAWN_RANGE_MM, np.float32), DRAWN_DIAMETERS_MM


def _found(frame, cfg):
    """(compiled levels, compiled candidates, reference levels, reference candidates)."""
    g, d, diameters = frame
    levels = extraction.frame_levels(g, cfg)
    found = extraction.find_candidate_blobs(g, d, CAM, diameters, cfg, levels)
    ref_levels = reference.frame_levels(g, cfg)
    got = reference.find_candidates(g, d, ref_levels, fx=CAM.fx, diameters_mm=diameters, config=cfg)
    return levels, found, ref_levels, got


#: (frame, settings): 0.7-12 m with clutter in a room, sharp and through a lens PSF; the
#: paper preset at 0.7 m (there its N_max cap applies); a cap and L that cut; the drawn
#: frame, whose shapes meet every gate
CASES = {
    "0.7 m": (lambda: _rendered(700.0, 0, 0.0), ExtractionConfig()),
    "0.7 m paper": (lambda: _rendered(700.0, 1, 0.0), ExtractionConfig.paper()),
    "1.5 m psf 0.5": (lambda: _rendered(1500.0, 1, 0.5), ExtractionConfig()),
    "3 m psf 1": (lambda: _rendered(3000.0, 2, 1.0), ExtractionConfig()),
    "3 m N_max 300 L 4": (
        lambda: _rendered(3000.0, 0, 0.0),
        ExtractionConfig(n_max=300, max_candidates=4),
    ),
    "5.7 m psf 1": (lambda: _rendered(5700.0, 2, 1.0), ExtractionConfig()),
    "8 m": (lambda: _rendered(8000.0, 0, 0.0), ExtractionConfig()),
    "12 m psf 0.5": (lambda: _rendered(12000.0, 1, 0.5), ExtractionConfig()),
    "drawn": (_drawn, ExtractionConfig()),
    "drawn paper": (_drawn, ExtractionConfig.paper()),
    "drawn L 0": (_drawn, ExtractionConfig(max_candidates=0)),
}


@pytest.mark.parametrize("case", list(CASES))
def test_the_reference_finds_what_the_compiled_path_finds(case):
    """Levels (before and after the N_max cap), A, every accepted blob, every oversize
    component, every refused component with its reason and place, in the same order,
    and the wrong-size list. Exact, except: the moment centroids, eccentricities and
    penalties to 1e-9 (the kernels sum in a loop, NumPy pairwise; the eccentricity by
    the closed form against LAPACK's eigenvalues: measured <= 1e-12), and the PSF sigma
    to 1e-9 (the kernel's second moment from raw sums, ours centred; measured ~1e-12).
    The nLoG responses themselves differ at float32 rounding (a band-matrix product
    against OpenCV's filters, ~1e-5 of the peak; ``tests/tofpose/kernels/
    test_components.py``), so a pixel that close to J_t could be kept by one and not the
    other; on these frames none is, and the kept pixel sets are compared exactly."""
    make, cfg = CASES[case]
    levels, found, ref_levels, got = _found(make(), cfg)
    for name in reference.FrameLevels._fields[:-1]:  # n_active: 0 before the cap
        assert getattr(ref_levels, name) == getattr(levels, name), name
    for name in reference.FrameLevels._fields:
        assert getattr(got.levels, name) == getattr(found.stats, name), name
    assert got.psf_sigma_px == pytest.approx(found.stats.psf_sigma_px, rel=0, abs=1e-9)
    np.testing.assert_array_equal(got.active_mask, found.active_mask.astype(bool))
    assert len(got.accepted) == len(found.accepted)
    for b, c in zip(got.accepted, found.accepted, strict=True):
        np.testing.assert_array_equal(b.pixels, c.pixels)
        np.testing.assert_equal(
            (b.area_px, b.bbox, b.distance_mm, b.peak_counts),
            (c.area_px, c.bbox, c.distance_mm, c.peak_counts),
        )
        np.testing.assert_allclose(b.centroid_uv, c.centroid_uv, rtol=0, atol=1e-9)
        assert b.eccentricity == pytest.approx(c.eccentricity, rel=0, abs=1e-9)
        assert b.penalty == pytest.approx(c.penalty, rel=0, abs=1e-9)
    assert len(got.oversize) == len(found.oversize)
    for b, c in zip(got.oversize, found.oversize, strict=True):
        np.testing.assert_array_equal(b.pixels, c.pixels)
        np.testing.assert_equal(
            (b.area_px, b.bbox, b.peak_counts, b.distance_mm),
            (c.area_px, c.bbox, c.peak_counts, c.distance_mm),
        )
    assert [r.reason for r in got.rejected] == [r.reason for r in found.rejected]
    places = [(r.u_px, r.v_px, r.diameter_px) for r in found.rejected]
    np.testing.assert_allclose(
        np.reshape([r[:3] for r in got.rejected], (-1, 3)),
        np.reshape(places, (-1, 3)),
        rtol=0,
        atol=1e-9,
    )
    np.testing.assert_allclose(
        np.reshape(got.wrong_size, (-1, 4)),
        np.reshape(
            [
                (w.diameter_px, w.expected_min_px, w.expected_max_px, w.distance_mm)
                for w in found.wrong_size
            ],
            (-1, 4),
        ),
        rtol=0,
        atol=1e-12,
    )


def test_the_cases_exercise_every_rule():
    """The comparison above means something only if its frames reach every gate, the
    N_max cap and the PSF estimate: every reason of
    ``tofpose.stages.extraction.extraction.REJECT_REASONS``
    (the reference's are the same names) is given on some case."""
    assert tuple(extraction.REJECT_REASONS) == reference.REJECT_REASONS
    reasons, capped, blurred, accepted = set(), 0, 0, 0
    for make, cfg in CASES.values():
        g, d, diameters = make()
        levels = reference.frame_levels(g, cfg)
        got = reference.find_candidates(g, d, levels, fx=CAM.fx, diameters_mm=diameters, config=cfg)
        reasons |= {r.reason for r in got.rejected}
        capped += got.levels.raw_threshold > levels.raw_threshold
        blurred += got.psf_sigma_px > 0.5
        accepted += len(got.accepted)
    assert reasons == set(reference.REJECT_REASONS)
    assert capped >= 2 and blurred >= 2 and accepted >= 50


# -- against known truth ------------------------------------------------------------------


def test_frame_levels_of_a_frame_of_known_levels():
    """A checkerboard of 5 and 15 counts (every 3rd row and column: half each): the
    background 10, its MAD 5 (sigma 1.4826 x 5, above sqrt(10)), the dark level 5 (the
    2nd percentile, under the background); lines off the subsample's rows: 50 saturated
    pixels (I_max 4095) and 30 at 1000. The thresholds: ours from the contrast 4085 (the
    relative I_t above the noise floor), the paper's absolute."""
    v, u = np.mgrid[0 : CAM.height, 0 : CAM.width]
    g = np.where((u + v) % 2 == 0, 5.0, 15.0).astype(np.float32)
    g[31, 100:150] = 4095.0
    g[34, 100:130] = 1000.0
    lv = reference.frame_levels(g, ExtractionConfig())
    assert (lv.background, lv.dark_level, lv.i_max) == (10.0, 5.0, 4095.0)
    assert lv.noise_sigma == pytest.approx(1.4826 * 5.0, rel=1e-15)
    assert lv.raw_threshold == pytest.approx(10.0 + 0.15 * 4085.0, rel=1e-15)
    assert lv.peak_threshold == pytest.approx(10.0 + 0.25 * 4085.0, rel=1e-15)
    assert lv.saturated_fraction == 50 / g.size and lv.n_active == 0
    floor = reference.frame_levels(g, ExtractionConfig(raw_threshold_rel=0.001))
    assert floor.raw_threshold == pytest.approx(10.0 + 6.0 * 1.4826 * 5.0, rel=1e-15)
    paper = reference.frame_levels(g, ExtractionConfig.paper())
    assert (paper.raw_threshold, paper.peak_threshold) == (114.66, 155.0)
    # distinct counts, the pixel's index: the subsample (80 rows of 107) is 960 i + 3 j;
    # its 2nd percentile is its value of rank int(8560 0.02) = 171 (row 1, column 64)
    # and its median that of ranks 4279 and 4280 (row 39, column 106 and row 40, column 0)
    ramp = reference.frame_levels(
        np.arange(g.size, dtype=np.float32).reshape(g.shape), ExtractionConfig()
    )
    assert (ramp.dark_level, ramp.background) == (960 + 3 * 64, (960 * 39 + 318 + 960 * 40) / 2)


def test_a_drawn_frame_gives_its_one_disc_and_each_shape_its_gate():
    """The ``DRAWN`` shapes at 2 m on a level of 10, no noise: one candidate, the 8 px
    disc, whole (197 px: its pixels are a plateau, no nLoG cut), at its centre (60, 60)
    with eccentricity 0, its range and peak, and the penalty of its size alone: d_eq =
    2 sqrt(197 / pi) against the catalog's nearest face-on diameter, 16.25 px (shape,
    intensity: 0). Every other shape refused by its gate at its box's centre; the
    saturated disc kept whole as oversize; the levels from the contrast 4095 - 10; no
    PSF (the sharp 2 x 2 square reads a negative one). With L = 0 the disc is "rank"."""
    g, d, diameters = _drawn()
    cfg = ExtractionConfig()
    got = reference.find_candidates(
        g, d, reference.frame_levels(g, cfg), fx=CAM.fx, diameters_mm=diameters, config=cfg
    )
    lv = got.levels
    assert (lv.background, lv.noise_sigma, lv.i_max, lv.dark_level) == (10, np.sqrt(10.0), 4095, 10)
    assert (lv.raw_threshold, lv.peak_threshold) == (10 + 0.15 * 4085, 10 + 0.25 * 4085)
    assert lv.saturated_fraction == DRAWN["oversize"][0].sum() / g.size
    assert lv.n_active == sum(m.sum() for m, c in DRAWN.values() if c >= lv.raw_threshold)
    assert got.psf_sigma_px == 0.0
    (blob,) = got.accepted
    disc = DRAWN["accepted"][0]
    np.testing.assert_array_equal(blob.pixels, np.flatnonzero(disc))
    assert blob.area_px == 197 and blob.bbox == (52, 52, 17, 17)
    assert (blob.distance_mm, blob.peak_counts, blob.eccentricity) == (2000.0, 2000.0, 0.0)
    np.testing.assert_allclose(blob.centroid_uv, [60.0, 60.0], rtol=0, atol=1e-12)
    d_eq = 2.0 * np.sqrt(197 / np.pi)
    assert blob.penalty == pytest.approx(np.log(16.25 / d_eq) / np.log(3.0), rel=1e-12)
    (big,) = got.oversize
    np.testing.assert_array_equal(big.pixels, np.flatnonzero(DRAWN["oversize"][0]))
    assert (big.area_px, big.bbox, big.peak_counts, big.distance_mm) == (
        2821,
        (220, 30, 61, 61),
        4095.0,
        2000.0,
    )
    where = {}
    for name, (mask, _) in DRAWN.items():
        rows, cols = np.nonzero(mask)
        where[name] = ((cols.min() + cols.max()) / 2, (rows.min() + rows.max()) / 2)
    assert sorted((r.reason, (r.u_px, r.v_px)) for r in got.rejected) == sorted(
        (name, uv) for name, uv in where.items() if name != "accepted"
    )
    none = reference.find_candidates(
        g,
        d,
        reference.frame_levels(g, cfg),
        fx=CAM.fx,
        diameters_mm=diameters,
        config=ExtractionConfig(max_candidates=0),
    )
    assert none.accepted == () and none.rejected[-1][:2] == (60.0, 60.0)
    assert none.rejected[-1].reason == "rank"


def test_the_cap_keeps_the_n_max_brightest_and_every_pixel_of_the_cut_value():
    """Distinct counts 0 .. H W - 1: N_max = 1000 keep the 1000 brightest, I_t rises to
    the 1000th brightest value. Each value twice: N_max = 1001 cuts inside a pair, and
    both of the pair stay (1002: the cut is a value, not a count). The compiled cap
    gives the same sets."""
    order = np.random.default_rng(7).permutation(CAM.height * CAM.width).reshape(CAM.shape)
    distinct, pairs = order.astype(np.float32), (order // 2).astype(np.float32)
    # the 1001st brightest of the pairs is the first of the pair 37899 (38399 the brightest)
    for g, n_max, cut, n in (
        (distinct, 1000, order.size - 1000, 1000),
        (pairs, 1001, (order.size - 1001) // 2, 1002),
    ):
        levels = reference.frame_levels(g, ExtractionConfig(raw_threshold_abs=0.0))
        mask, applied = reference.active_pixel_set(g, levels, n_max=n_max)
        assert (applied.raw_threshold, applied.n_active, int(mask.sum())) == (cut, n, n)
        np.testing.assert_array_equal(mask, g >= cut)
        assert levels.n_active == 0 and levels.raw_threshold == 0.0
        stats = extraction.frame_levels(g, ExtractionConfig(raw_threshold_abs=0.0))
        compiled, compiled_applied = extraction.active_pixel_mask(g, stats, n_max)
        np.testing.assert_array_equal(mask, compiled.astype(bool))
        assert compiled_applied.raw_threshold == cut


def test_a_marker_cut_by_the_border_is_refused_as_such():
    """The target slid right until marker 8 (x = 420 mm) straddles the image's right
    edge: one "border" component there, the other seven markers accepted."""
    pose = facing_pose(1500.0)
    pose.t_mm[0] = (CAM.width - 1 - CAM.cx) * (1500.0 - 150.0) / CAM.fx - 420.0
    frame = render(pose, noise=False)
    g, d = extraction.check_frame(CAM, frame.gray, frame.distance_mm)
    cfg = ExtractionConfig()
    got = reference.find_candidates(
        g,
        d,
        reference.frame_levels(g, cfg),
        fx=CAM.fx,
        diameters_mm=paper_target().diameters_mm,
        config=cfg,
    )
    (border,) = got.rejected
    assert border.reason == "border" and border.u_px > CAM.width - 20
    assert len(got.accepted) == 7
    assert reference.touches_border((0, 5, 3, 3), CAM.shape)
    assert reference.touches_border((CAM.width - 3, 5, 3, 3), CAM.shape)
    assert not reference.touches_border((1, 1, CAM.width - 2, CAM.height - 2), CAM.shape)


# -- single rules --------------------------------------------------------------------------


def test_nlog_scale_normalised_disc_response_is_2_over_e():
    v, u = np.mgrid[0:101, 0:101]
    r = 12.0
    img = ((u - 50) ** 2 + (v - 50) ** 2 <= r * r).astype(np.float32) * 100.0
    j = reference.nlog_response(img, r / np.sqrt(2))
    assert j[50, 50] == pytest.approx(100 * 2 / np.e, rel=0.06)


def test_size_gate_window_from_the_catalog_at_the_range():
    """A 100 mm marker at 2 m is ~16 px across (f = 325 px): ~200 px of area; the
    paper's window is on the area alone."""
    cfg, diam = ExtractionConfig(), paper_target().diameters_mm
    opts = {"fx": 325.0, "diameters_mm": diam}
    d_eq, lo, hi, ok, big = reference.size_gate(200, 16, 2000.0, config=cfg, **opts)
    assert ok and not big and lo < d_eq < hi
    assert reference.size_gate(2000, 50, 2000.0, config=cfg, **opts).too_big  # merged markers
    assert not reference.size_gate(200, 60, 2000.0, config=cfg, **opts).inside  # no disc
    widened = reference.size_gate(200, 16, 2000.0, config=cfg, widening_px=3.0, **opts)
    assert widened.window_hi_px == hi - cfg.size_margin_px + 3.0
    assert reference.size_gate(200, 16, float("nan"), config=cfg, **opts)[1:3] == (0.0, np.inf)
    paper = ExtractionConfig(h_min_px=10, h_max_px=300)
    assert reference.size_gate(200, 16, np.nan, config=paper, **opts)[3:] == (True, False)
    assert reference.size_gate(400, 16, np.nan, config=paper, **opts)[3:] == (False, True)


@pytest.mark.parametrize(("n", "ecc", "ok"), [(4, 0.99, True), (30, 0.3, True), (30, 0.9, False)])
def test_shape_gate(n, ecc, ok):
    assert reference.shape_gate(n, ecc, 0.5) is ok


def test_two_pixel_blob_of_a_distant_small_marker_has_no_penalty():
    """A 35 mm marker at 10 m covers ~1 px and often lights a 1 x 2 pixel pair. Two pixels
    side by side have eccentricity 1, which must not count as a bad shape: the blob is too
    small for its shape to mean anything; eight in a line are all shape."""
    opts = {
        "fx": 325.0,
        "diameters_mm": paper_target().diameters_mm,
        "i_peak": 220.0,
        "i_t": 150.0,
        "max_eccentricity": 0.95,
    }
    assert reference.penalty_score(2, 1.0, 10000.0, 580.0, **opts) == 0.0
    assert reference.penalty_score(8, 1.0, 10000.0, 580.0, **opts) == 1.0
    assert reference.penalty_score(2, 0.0, 10000.0, 185.0, **opts) == pytest.approx(0.5)


def test_blur_widening_is_what_the_psf_adds_at_the_threshold():
    """A disc of 8 px through a PSF of variance 1 px^2, peak 4 x the threshold: a Gaussian
    of variance 4 + 1/12 (+ 1) cut at a quarter of its peak, 2 sqrt(2 v ln 4) across."""
    sharp, blurred = 4.0 + 1.0 / 12.0, 5.0 + 1.0 / 12.0
    want = 2.0 * (np.sqrt(2 * blurred * np.log(4.0)) - np.sqrt(2 * sharp * np.log(4.0)))
    assert reference.blur_widening_px(8.0, 1.0, 400.0, 100.0) == pytest.approx(want, rel=1e-12)
    assert reference.blur_widening_px(8.0, 0.0, 400.0, 100.0) == 0.0
    assert reference.blur_widening_px(8.0, 1.0, 90.0, 100.0) == 0.0
