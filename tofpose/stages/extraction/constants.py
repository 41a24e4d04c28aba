"""The extraction stage's constants, shared by its kernels, its reference statement and
its orchestration (defined once: numba freezes a module global into the compiled code as
it reads here)."""

from __future__ import annotations

# -- frame levels (§3.1.1)
#: the camera's full scale (12 bit): a pixel at or above it is saturated
SATURATED_COUNTS = 4095
#: the background and its noise are read on every this-many-th row and column
LEVEL_STRIDE = 3
#: the no-return level is this percentile of the frame's gray (nearest rank): on a
#: target seen against a hall or space most pixels see nothing; with a wall behind it,
#: the darkest 2 %
DARK_PERCENTILE = 2.0
#: sigma of a normal distribution over its median absolute deviation
MAD_TO_SIGMA = 1.4826

# -- blob criteria (§3.2)
#: fewest pixels for which a blob's eccentricity means anything (shape gate and q_shape)
SHAPE_MIN_PIXELS = 6
#: how far (px) the window moments reach beyond a component's box: the active set cuts
#: a blurred blob at ~1-2 PSF sigmas, and 3 px more hold the tails of a PSF of up to
#: ~1.5 px (2 px read a 1.4 px PSF as ~1.1)
WINDOW_PAD_PX = 3
#: the widest lens PSF (1-sigma, px) the gates adapt to: a lens this far out of focus
#: smears a 35 mm marker at 3 m over ~5 px; a component that reads wider is taken for
#: a disc larger than the catalog's smallest, not for blur
MAX_PSF_SIGMA_PX = 2.0

# -- centroids (Eq. 19)
#: a member pixel at or above this fraction of the largest member value of its 3 x 3
#: neighbourhood is covered whole (the shot noise of a bright marker's pixel is ~3 %)
PLATEAU_RATIO = 0.9
#: coverage weights from this many whole-covered pixels (a 3 x 3 interior) on; below,
#: intensity weights
PLATEAU_MIN_PX = 9

# -- mixed pixels and occlusion (beyond Eq. 20)
#: the surround is read in the box of the blob grown by this many pixels ...
SURROUND_OUTER_PX = 3
#: ... outside the box grown by this many (the support reaches 1 px beyond the blob)
SURROUND_INNER_PX = 1
#: fields of a ``blob_mixing`` row: a_b, d_b, S_a, S_ad, covered area of the support
#: pixels without a range (px^2, their gray's coverage estimate), n_support, and for a
#: blob with a saturated pixel the bounded-coverage range and its sigma (mm; NaN else)
MIX_FIELDS = 8
#: a saturated blob's range is read from its ranged pixels at least this many times as
#: bright (above the no-return level) as its surround (dimmer ones are mostly surround:
#: unmixing them divides by a difference near 0)
SATURATED_MIN_CONTRAST = 2.0
#: ... and only when saturation took the range of more than this fraction of its disc's
#: area (then its ranged pixels are its rim; with most of the disc ranged, the median or
#: the mixing sums hold: a disc brighter on one side saturates there only)
SATURATED_AREA_FRACTION = 0.5
#: floor of a ranged pixel's half-interval in the saturated-blob range (mm): weights
#: stay finite where the interval closes
SATURATED_HALF_WIDTH_FLOOR_MM = 0.5
#: a pixel near a blob is something in front of it (an arm, a cable, the target's own
#: structure) when it reads nearer than the blob's range by more than this (a raised
#: marker's plate lies 100-150 mm behind it) ...
OCCLUSION_MARGIN_MM = 250.0
#: ... and by more than this many robust sigmas of the range scatter of the rest of the
#: blob's surround (a dark plate under strong ambient light scatters by 100s of mm) ...
OCCLUSION_NOISE_SIGMAS = 4.0
#: ... and such pixels touch the blob and make a connected patch of at least this many
#: pixels within its surround (isolated pixels that read near by chance do not chain up)
OCCLUSION_MIN_PATCH_PX = 4
#: ... reaching at least this many pixels of the surround's outermost ring (an occluder
#: is larger than the blob's rim; the rim's pixels alone read wrong while the target
#: moves, when the four phase sub-frames see the marker's edge at different places)
OCCLUSION_MIN_OUTER_PX = 2
