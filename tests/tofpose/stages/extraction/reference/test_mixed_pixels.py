"""The reference statement of the mixed-pixel rules
(``tofpose.stages.extraction.reference.mixed_pixels``):
each function against its compiled counterpart (``kernels.mixed_pixels``,
``kernels.centroids.owner_map``) on the blobs of rendered frames (a room with an arm in
front of the target, merged and split markers 7 and 8 at 5 and 8 m), and against known
truth on drawn frames."""

from __future__ import annotations

import numpy as np
import pytest

from tests.tofpose.stages.persistence.reference.test_measure import captured_stream
from tofpose.stages.extraction.kernels import centroids as compiled_centroids
from tofpose.stages.extraction.kernels import mixed_pixels as compiled
from tofpose.stages.extraction.records import OwnerMap, Surrounds
from tofpose.stages.extraction.reference import mixed_pixels as reference

#: the rendered frames' camera's saturation level (counts)
FULL_SCALE = 4095.0
#: (range mm, room seed, frame): frames of ``test_measure``'s streams
FRAMES = [
    (1500.0, 0, 0),
    (3000.0, 0, 2),
    (3000.0, 0, 5),
    (8000.0, 3, 1),
    (8000.0, 5, 4),
    (5000.0, 7, 3),
]


def _arrays(flat, starts, bbox):
    return (
        np.asarray(flat, np.int64),
        np.asarray(starts, np.int64),
        np.asarray(bbox, np.int64).reshape(-1, 4),
    )


def _blob_ranges(flat, starts, distance):
    """Each blob's median range (NaN with none), the range occlusion is tested against."""
    d = distance.reshape(-1)
    return np.array(
        [
            np.nanmedian(d[flat[a:b]]) if np.isfinite(d[flat[a:b]]).any() else np.nan
            for a, b in zip(starts[:-1], starts[1:], strict=True)
        ]
    )


def _both(flat, starts, bbox, gray, distance, dark):
    """Every function's result, compiled and reference, on one frame's blobs: a dict of
    name -> (compiled, reference)."""
    h, w = gray.shape
    out = {}
    own_c = compiled_centroids.owner_map(flat, starts, bbox, h, w)
    own_r = reference.owner_map(flat, starts, bbox, h, w)
    out["owner_map"] = own_c, own_r
    sur_c = compiled.blob_surrounds(bbox, gray, distance, own_c)
    sur_r = reference.blob_surrounds(bbox, gray, distance, own_r)
    out["blob_surrounds"] = sur_c, sur_r
    rho = _blob_ranges(flat, starts, distance)
    pairs = ((compiled, own_c), (reference, own_r))
    out["occluded_blobs"] = tuple(
        m.occluded_blobs(flat, starts, bbox, distance, rho, own) for m, own in pairs
    )
    mix = [
        m.blob_mixing(flat, starts, bbox, gray, distance, distance, sur_c, dark, own, FULL_SCALE)
        for m, own in pairs
    ]
    out["blob_mixing"] = tuple(mix)
    return out


def _assert_equal(name, got_compiled, got_reference):
    """Exactly for the owner map, surrounds (float32 medians) and flags; the mixing sums
    to 1e-12 relative or 1e-6 (float64 sums of products of ~1e3 counts and ~1e4 mm in
    another order)."""
    if name == "blob_mixing":
        np.testing.assert_allclose(got_reference, got_compiled, rtol=1e-12, atol=1e-6)
        return
    for a, b in (
        zip(got_compiled, got_reference, strict=True)
        if isinstance(got_compiled, tuple)
        else ((got_compiled, got_reference),)
    ):
        np.testing.assert_array_equal(np.asarray(b), np.asarray(a), err_msg=name)


@pytest.mark.parametrize(("distance_mm", "seed", "frame"), FRAMES)
def test_each_rule_equals_the_kernel_on_rendered_frames(distance_mm, seed, frame):
    args, _ = captured_stream(distance_mm, seed, False)[frame]
    gray, distance = args[0].gray, args[0].distance
    flat, starts, bbox = _arrays(args[1].flat, args[1].starts, args[1].bbox)
    results = _both(flat, starts, bbox, gray, distance, float(args[0].dark))
    for name, (got_c, got_r) in results.items():
        _assert_equal(name, got_c, got_r)
    mix = results["blob_mixing"][1]
    rho = _blob_ranges(flat, starts, distance)
    for j in range(len(bbox)):
        row_c, row_r = mix[j].copy(), mix[j].copy()
        compiled.shift_mixing(row_c, -17.25)
        reference.shift_mixing(row_r, -17.25)
        np.testing.assert_array_equal(row_r, row_c)
        for radius_px in (0.6, 1.3, 2.5, 5.0):
            want = compiled.unmixed_range(rho[j], mix[j], radius_px, 0.8, 4.0)
            got = reference.unmixed_range(rho[j], mix[j], radius_px, 0.8, 4.0)
            np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-12)


def test_the_rendered_frames_reach_every_branch():
    """The frames above hold crowded blobs (touching halves), occluded ones (the arm),
    blobs with mixing sums and without, and unmixed ranges that differ from the median."""
    seen = {"use_owner": 0, "crowded": 0, "occluded": 0, "mixed": 0, "unmixed": 0}
    for distance_mm, seed, frame in [f for f in FRAMES if not hasattr(f, "marks")]:
        args, _ = captured_stream(distance_mm, seed, False)[frame]
        frame_record, blobs = args[0], args[1]
        flat, starts, bbox = _arrays(blobs.flat, blobs.starts, blobs.bbox)
        gray, distance = frame_record.gray, frame_record.distance
        r = _both(flat, starts, bbox, gray, distance, float(frame_record.dark))
        seen["use_owner"] += r["owner_map"][1].used
        seen["crowded"] += r["blob_surrounds"][1].crowded.sum()
        seen["occluded"] += r["occluded_blobs"][1].sum()
        mix = r["blob_mixing"][1]
        seen["mixed"] += np.isfinite(mix[:, 0]).sum()
        rho = _blob_ranges(flat, starts, distance)
        seen["unmixed"] += sum(
            reference.unmixed_range(rho[j], mix[j], 1.0, 1.0, 4.0)[1] > 0 for j in range(len(rho))
        )
    assert all(v > 0 for v in seen.values()), seen


#: no blob owns a pixel (no neighbour to leave out)
NO_OWNERS = OwnerMap(owner=np.full((1, 1), -1, np.int32), x0=0, y0=0, used=False)


# -- known truth --------------------------------------------------------------------------
H, W = 60, 80


def _square(x, y, size):
    """Flat pixels and box of a size x size square at column x, row y."""
    r, c = np.mgrid[y : y + size, x : x + size]
    return (r * W + c).ravel(), (x, y, size, size)


def _lists(*blobs):
    flat = np.concatenate([b[0] for b in blobs]).astype(np.int64)
    starts = np.cumsum([0] + [len(b[0]) for b in blobs]).astype(np.int64)
    return flat, starts, np.array([b[1] for b in blobs], np.int64)


def test_a_tilted_plate_around_a_blob_has_the_level_at_its_centre():
    """A plate whose gray rises 3 counts a column and whose range rises 2 mm a row: the
    ring's medians are the plate's values at the blob's centre (the ring is symmetric);
    a neighbour in the ring crowds the blob and its pixels are left out."""
    cols, rows = np.meshgrid(np.arange(W), np.arange(H))
    gray = (100.0 + 3.0 * (cols - 21)).astype(np.float32)
    distance = (4000.0 + 2.0 * (rows - 21)).astype(np.float32)
    blob = _square(20, 20, 3)  # centre (21, 21)
    gray[20:23, 20:23] = 900.0
    flat, starts, bbox = _lists(blob)
    owner = reference.owner_map(flat, starts, bbox, H, W)
    level, depth, crowded = reference.blob_surrounds(bbox, gray, distance, owner)
    assert (level[0], depth[0], crowded[0]) == (100.0, 4000.0, False)
    distance[17, 17:26] = np.nan  # the top row of the ring without a range: median shifts
    assert reference.blob_surrounds(bbox, gray, distance, NO_OWNERS).distance_mm[0] == 4002.0
    # a bright neighbour two columns to the right: its pixels reach the ring
    neighbour = _square(25, 20, 3)
    gray[20:23, 25:28] = 3000.0
    flat, starts, bbox = _lists(blob, neighbour)
    owner = reference.owner_map(flat, starts, bbox, H, W)
    assert owner.used and owner.owner[20 - owner.y0, 25 - owner.x0] == 1
    level, _, crowded = reference.blob_surrounds(bbox, gray, distance, owner)
    assert crowded.tolist() == [True, True] and level[0] < 900.0


def _occlusion_frame():
    """A 4 x 4 marker at 5000 mm on a plate at 5120 mm: (distance, flat, starts, bbox)."""
    distance = np.full((H, W), 5120.0, np.float32)
    distance[30:34, 40:44] = 5000.0
    return (distance, *_lists(_square(40, 30, 4)))


def _occluded(distance, flat, starts, bbox):
    rho = np.array([5000.0])
    args = (flat, starts, bbox, distance, rho, reference.owner_map(flat, starts, bbox, H, W))
    got = bool(reference.occluded_blobs(*args)[0])
    assert got == bool(compiled.occluded_blobs(*args)[0])
    return got


def test_an_arm_touching_a_marker_hides_it_and_a_lone_near_pixel_does_not():
    distance, flat, starts, bbox = _occlusion_frame()
    assert not _occluded(distance, flat, starts, bbox)
    arm = distance.copy()
    arm[27:30, 36:48] = 4400.0  # three rows across the window's top, touching the marker
    assert _occluded(arm, flat, starts, bbox)
    lone = distance.copy()
    lone[29, 41] = 4200.0  # one near pixel touching the marker
    assert not _occluded(lone, flat, starts, bbox)
    rim = distance.copy()
    rim[29, 39:45] = 4200.0  # the rim alone, not reaching the window's outer ring
    assert not _occluded(rim, flat, starts, bbox)
    apart = distance.copy()
    apart[27:29, 36:39] = 4400.0  # a near patch in the window's corner, not touching
    assert not _occluded(apart, flat, starts, bbox)
    shallow = distance.copy()
    shallow[27:30, 36:48] = 4800.0  # only 200 mm in front: within the margin
    assert not _occluded(shallow, flat, starts, bbox)


def test_the_mixing_sums_of_a_partly_covering_disc_give_its_coverage_and_range():
    """A reflector covering the pixels of a 3 x 3 patch by known fractions (C = 3.8),
    amplitude and amplitude x distance mixed linearly over a plate: S_a = C (A_r - a_b),
    S_ad = C (A_r d_r - a_b d_b), and the model given C returns d_r. One support pixel
    without a range: its coverage is estimated from its gray and taken off C."""
    cover = np.array([[0.1, 0.5, 0.2], [0.6, 1.0, 0.7], [0.1, 0.4, 0.2]])
    dark, a_b, d_b, a_r, d_r = 90.0, 120.0, 5120.0, 1600.0, 5000.0
    c = np.zeros((H, W))
    c[30:33, 40:43] = cover
    amp = c * a_r + (1 - c) * a_b
    gray = (amp + dark).astype(np.float32)
    distance = ((c * a_r * d_r + (1 - c) * a_b * d_b) / amp).astype(np.float64)
    member = np.flatnonzero(c > 0.3)
    rows, cols = np.divmod(member, W)
    bbox = np.array([[cols.min(), rows.min(), np.ptp(cols) + 1, np.ptp(rows) + 1]], np.int64)
    flat, starts = member.astype(np.int64), np.array([0, len(member)], np.int64)
    owner = reference.owner_map(flat, starts, bbox, H, W)
    surround = Surrounds(
        gray=np.array([a_b + dark]), distance_mm=np.array([d_b]), crowded=np.array([False])
    )
    mix = reference.blob_mixing(
        flat,
        starts,
        bbox,
        gray,
        distance,
        distance,
        surround,
        dark,
        owner,
        FULL_SCALE,
    )[0]
    # the float32 gray holds the amplitudes to ~3e-5 counts
    area = cover.sum()
    assert mix[4] == 0.0 and mix[5] == 21  # the plus of members dilated: 5 x 5 less corners
    assert mix[2] == pytest.approx(area * (a_r - a_b), abs=1e-3)
    assert mix[3] == pytest.approx(area * (a_r * d_r - a_b * d_b), rel=1e-6)
    radius = np.sqrt(area / np.pi)
    assert reference.unmixed_range(5100.0, mix, radius, 1.0, 4.0)[0] == pytest.approx(d_r, abs=0.01)
    # the corner pixel (coverage 0.2) has no range: C_unranged is its gray's estimate
    distance[32, 42] = np.nan
    mix = reference.blob_mixing(
        flat,
        starts,
        bbox,
        gray,
        distance,
        distance,
        surround,
        dark,
        owner,
        FULL_SCALE,
    )[0]
    assert mix[4] == pytest.approx(0.2, abs=1e-6)
    assert reference.unmixed_range(5100.0, mix, radius, 1.0, 4.0)[0] == pytest.approx(d_r, abs=0.01)
    shifted = mix.copy()
    reference.shift_mixing(shifted, 30.0)
    assert reference.unmixed_range(5100.0, shifted, radius, 1.0, 4.0)[0] == pytest.approx(
        d_r + 30.0, abs=0.01
    )


#: the drawn saturated disc's image area (px^2): the sum of its coverages
SATURATED_DISC_AREA = 10.6


def _saturated_disc(a_r, full_scale=FULL_SCALE):
    """A reflector of amplitude ``a_r`` over a 5 x 5 patch of known coverages (its core
    clipped at ``full_scale`` and without distance, as a CW-ToF pixel that saturates
    gives none), 130 mm in front of a plate: (flat, starts, bbox, gray, distance,
    surround, owner, d_r, dark)."""
    cover = np.array(
        [
            [0.0, 0.15, 0.3, 0.15, 0.0],
            [0.15, 0.8, 1.0, 0.8, 0.15],
            [0.3, 1.0, 1.0, 1.0, 0.3],
            [0.15, 0.8, 1.0, 0.8, 0.15],
            [0.0, 0.15, 0.3, 0.15, 0.0],
        ]
    )
    dark, a_b, d_b, d_r = 90.0, 370.0, 6130.0, 6000.0
    c = np.zeros((H, W))
    c[30:35, 40:45] = cover
    amp = c * a_r + (1 - c) * a_b
    distance = (c * a_r * d_r + (1 - c) * a_b * d_b) / amp
    gray = amp + dark
    clipped = gray >= full_scale
    gray = np.minimum(gray, full_scale).astype(np.float32)
    distance[clipped] = np.nan
    member = np.flatnonzero(c > 0.1)
    rows, cols = np.divmod(member, W)
    bbox = np.array([[cols.min(), rows.min(), np.ptp(cols) + 1, np.ptp(rows) + 1]], np.int64)
    flat, starts = member.astype(np.int64), np.array([0, len(member)], np.int64)
    owner = reference.owner_map(flat, starts, bbox, H, W)
    surround = Surrounds(
        gray=np.array([a_b + dark]), distance_mm=np.array([d_b]), crowded=np.array([False])
    )
    return flat, starts, bbox, gray, distance, surround, owner, d_r, dark


def _mixing_row(flat, starts, bbox, gray, distance, surround, owner, dark):
    """The one blob's ``blob_mixing`` row (``MIX_FIELDS``,), after checking that the
    compiled kernel gives the reference's."""
    rows = [
        m.blob_mixing(
            flat, starts, bbox, gray, distance, distance, surround, dark, owner, FULL_SCALE
        )[0]
        for m in (compiled, reference)
    ]
    np.testing.assert_allclose(rows[0], rows[1], rtol=1e-12, atol=1e-6)
    return rows[1]


@pytest.mark.parametrize("ratio", [1.5, 3.6, 6.0])
def test_a_saturated_reflector_reads_its_own_range_within_its_sigma(ratio):
    """A reflector ``ratio`` x full scale, its core clipped: the median of its ranged
    (rim) pixels reads long, pulled towards the plate; the bounded-coverage range
    (``blob_mixing``'s d_sat, what ``unmixed_range`` returns for it at any size) holds
    the truth within 2 of its sigmas, and that sigma is honest (below the median's
    bias); compiled and reference agree. Unsaturated, the fields stay NaN."""
    flat, starts, bbox, gray, distance, surround, owner, d_r, dark = _saturated_disc(
        ratio * (FULL_SCALE - 90.0)
    )
    mix = _mixing_row(flat, starts, bbox, gray, distance, surround, owner, dark)
    median_error = np.nanmedian(distance.reshape(-1)[flat]) - d_r
    radius = np.sqrt(SATURATED_DISC_AREA / np.pi)
    got, sigma = reference.unmixed_range(6010.0, mix, radius, 1.0, 4.0)
    assert (got, sigma) == compiled.unmixed_range(6010.0, mix, radius, 1.0, 4.0)
    assert median_error > 3.0  # the rim reads towards the plate
    assert 0 < sigma < median_error
    assert abs(got - d_r) < 2.0 * sigma
    assert abs(got - d_r) < 0.5 * median_error
    # a disc four times that area, of which saturation took less than half: not this
    # model (the median, or the mixing sums)
    assert reference.unmixed_range(6010.0, mix, 2 * radius, 1.0, 4.0)[0] != got
    # the same disc below full scale: no saturated estimate
    flat, starts, bbox, gray, distance, surround, owner, d_r, dark = _saturated_disc(
        0.5 * (FULL_SCALE - 90.0)
    )
    row = reference.blob_mixing(
        flat, starts, bbox, gray, distance, distance, surround, dark, owner, FULL_SCALE
    )[0]
    assert np.isnan(row[6:]).all()


@pytest.mark.parametrize(("ratio", "measured"), [(3.6, True), (0.5, False)])
def test_a_crowded_saturated_reflector_still_reads_its_own_range(ratio, measured):
    """Two raised reflectors side by side (the paper target's 7 and 8) put each other's
    pixels in their surround rings: crowded. The mixing sums are left out for such a
    blob (a neighbour's light would bias them); unsaturated, its centre and median range
    serve. Saturated, the median of its rims reads towards the plate (the other
    renderer's saturating frames: +10 to +24 mm), so its bounded-coverage range is
    taken, from the surround's median (the neighbour's own pixels are out of the ring),
    whatever part of the disc is clipped: within 2 of its sigmas here, and the same in
    the compiled kernel and its reference."""
    flat, starts, bbox, gray, distance, surround, owner, d_r, dark = _saturated_disc(
        ratio * (FULL_SCALE - 90.0)
    )
    crowded = Surrounds(
        gray=surround.gray, distance_mm=surround.distance_mm, crowded=np.array([True])
    )
    row = _mixing_row(flat, starts, bbox, gray, distance, crowded, owner, dark)
    # the sums stay out either way: the neighbour's light would bias them
    assert np.isnan(row[:6]).all()
    if not measured:
        assert np.isnan(row).all()
        return
    got, sigma = row[6], row[7]
    assert sigma > 0 and abs(got - d_r) < 2.0 * sigma
    # and the pose stage takes that bounded range at any apparent size (not the linear
    # model, not the rims' median), in the kernel and its reference alike
    for radius in (1.0, np.sqrt(SATURATED_DISC_AREA / np.pi), 6.0):
        for m in (compiled, reference):
            assert m.unmixed_range(6010.0, row, radius, 1.0, 4.0) == (got, sigma)
