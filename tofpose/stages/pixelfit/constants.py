"""The pixel-level fit's constants (defined once)."""

from __future__ import annotations

from tofpose.stages.extraction.constants import SATURATED_COUNTS

#: the camera's full scale: gray at or above it is a censored (saturated) measurement
FULL_SCALE_COUNTS = SATURATED_COUNTS
#: sub-cells per pixel side for the pixels a disc's rim crosses (S x S per pixel)
SUBSAMPLES = 4
#: window margin beyond the predicted ellipse's bounding box, px
WINDOW_PAD_PX = 3
#: rim samples used to predict each disc's ellipse (its bounding box)
RIM_POINTS = 64
#: a pixel whose centre is further than this from the rim (px) is fully inside or
#: outside its disc (a sub-cell reaches at most sqrt(2)/2 px from the centre)
BAND_PX = 1.0
#: a pixel's distance is fitted when the discs cover at least this part of it (its
#: phasor is mixed with the plate's by the model; below it the surround's return, which
#: the model knows less well, would dominate)
DISTANCE_MIN_COVERAGE = 0.5
#: pixels within this margin (px) of an unmatched catalog disc's predicted image are left
#: out of the fit (the model does not carry its gain)
UNMATCHED_MARGIN_PX = 2.0
#: Levenberg-Marquardt: iterations, initial damping and its factors
MAX_ITERATIONS = 30
INITIAL_DAMPING = 1e-3
DAMPING_DOWN, DAMPING_UP = 0.3, 10.0
#: converged when the step's squared length in its own sigmas (step' F step) is below
#: this: a step of 0.1 sigma changes the estimate's error variance by 1 %. (1e-4 until
#: 2026-12-07: the same RMS errors over the bound to three decimals at 1, 3 and 6 m,
#: 10-20 % more time a frame, one iteration more per solve)
STEP_TOLERANCE_SIGMA2 = 1e-2
#: the same for the solve that only finds where the frame's model errors are measured
#: (before the rim's model error and the discs' range errors are known, and the solve
#: with them follows from its state): a step under one sigma. Near the solution the
#: Gauss-Newton steps shrink quadratically, so the state is then a small part of a sigma
#: from that solve's optimum, and the residuals the model errors are measured on move by
#: less; the solve that follows converges to ``STEP_TOLERANCE_SIGMA2`` as before (when
#: none follows, the starting solve is finished to it). With the hold below, the
#: 300-frame range sweep's fits took 5.4 Jacobians each instead of 7.4.
START_STEP_TOLERANCE_SIGMA2 = 1.0
#: iterations over which the distance's noise constant, when the noise model leaves it
#: open (``PixelNoise.range_k_mm`` None), is measured again at each iteration on the
#: distance residuals (their median absolute deviation); then it is held at the last
#: value for the rest of the solve (and the fit's covariance, residuals and verdict are
#: with it), so the distance weights no longer jump with the median from step to step
#: (the gray's and the distance's shot-noise shapes still follow the model). Measured
#: again at every step,
#: the weights and the state can cycle: on a 300-frame range sweep, 14 of 576 solves
#: alternated between two states (their cost at each linearisation e.g. 347.7, 329.4,
#: 347.7, ...) until ``MAX_ITERATIONS`` and fell back; held after 6, every solve ended
#: (in at most 18 iterations), and a solve of up to 6 iterations is unchanged.
NOISE_FREEZE_ITERATIONS = 6
#: central-difference steps of the pose derivative: rotation, rad; translation, mm
ROTATION_STEP_RAD = 1e-5
TRANSLATION_STEP_MM = 1e-2
#: a disc whose residual RMS (whitened: sigmas) exceeds this is not what the model says
#: (a glint, an occluded or cut disc): fall back
MAX_MARKER_RMS_SIGMA = 3.0
#: a disc whose fitted gain is not this many surround sigmas above its surround is dark
#: (occluded, or not there): fall back
MIN_CONTRAST_SIGMA = 10.0
#: the surround beyond the target's plate (``fit._plate_surround``): its level is measured
#: on a window's pixels wholly beyond the plate and clear of the discs when it has at
#: least this many (else on all windows' together); a window with less than
#: ``MIN_PLATE_PIXELS`` of plate beside its disc fits no plate level
MIN_BEYOND_PIXELS = 8
MIN_PLATE_PIXELS = 1.0
#: a bright spot in the surround (``fit._glint_pixels``): its peak's gray this many
#: sigmas above the model (no pixel the model explains is: a 10 sigma residual has odds
#: of 1e-23; the glints of the robustness study and of the other renderer are 25-800),
#: its pixels those connected to the peak more than ``GLINT_TAIL_SIGMA`` above it
GLINT_PEAK_SIGMA = 10.0
GLINT_TAIL_SIGMA = 3.0
#: nor is a spot larger than this share of the windows' surround pixels left out (a
#: glint of 1.6 px sigma and 2500 counts is ~100 px over a surround of 3 counts' noise,
#: against ~2000 surround pixels at 3 m; a larger one is more likely the model's error)
GLINT_MAX_SHARE = 0.1
#: fewest discs the fit needs (three points fix a pose)
MIN_MARKERS = 3
#: robust scale of normal samples: sigma = MAD_TO_SIGMA * median absolute deviation
MAD_TO_SIGMA = 1.4826
#: variance of the 12-bit quantisation of the gray image, counts^2
QUANTISATION_VAR = 1.0 / 12.0
#: a disc covers a pixel partly (a rim pixel) when its coverage is inside (eps, 1 - eps)
RIM_COVERAGE_EPS = 1e-3
#: fewest unsaturated rim pixels on which the rim's model error is measured
MIN_RIM_PIXELS = 12
#: fewest distance pixels a disc needs for its mean range residual to count
MIN_DISC_DISTANCE_PIXELS = 3
#: fewest rim pixels a disc needs for its own rim model error to count (the median over
#: the discs is the frame's)
MIN_DISC_RIM_PIXELS = 4
#: a disc whose residual RMS exceeds this many times the matched discs' median (and
#: RELATIVE_RMS_MIN_SIGMA) is unlike the others: a glint on or beside it, fall back
RELATIVE_RMS_FACTOR = 2.0
RELATIVE_RMS_MIN_SIGMA = 2.0
#: discs whose rims come within this gap of each other on the target (mm) are crowded:
#: exempt from the relative residual test (raised to different heights, one may hide
#: the other's rim at an angle: 50 mm of height at 20 deg shifts a rim by 18 mm)
CROWDED_GAP_MM = 30.0
#: a disc with more than this share of its wholly covered pixels saturated has a clipped
#: core: its gain is then seen only on the rim's outer pixels (coverage below full scale
#: over the gain, 0.2-0.5 at 2-5x full scale), where it trades against the rim's position
#: and the rim's model error (a pixel's response over its area; the simulator samples
#: 4 x 4 points) biases the pose far beyond its covariance. Measured on the physics
#: study's ``saturating`` family (48 frames, every disc with a core clipped wholly): NEES/6
#: 17.8, 46 % beyond 3 sigma; the same frames rendered without noise and fitted from the
#: true pose land up to 13 sigma off (NEES/6 up to 180) with residual RMS near 1, and 16 x
#: 16 point sampling shrinks some of those (180 -> 2, 83 -> 6, 55 -> 0.6) but not all
#: (18 -> 30): the bias is the rim model's, not the noise's, and not the censoring's (the
#: true per-pixel clip level, full scale less the ambient's hidden share, changes NEES/6
#: 19.9 -> 14.5; no censored rows at all: 24.9). The fit then falls back (the centroid
#: pose, NEES/6 0.4 on that family). Not tuned: every clipped disc measured had share 1.
MAX_CLIPPED_CORE_SHARE = 0.5
