"""A lit surface around the markers (a bright plate, a wall): its gray level, so that the
active pixel set and the peak criterion (§3.1.1, Eq. 16) sit above it, not inside its
noise.

The paper's thresholds are fractions of the frame's contrast over its background
(``ExtractionConfig.raw_threshold_rel``, ``peak_rel``). The background is the frame's
median, which on a target seen against a hall or space is the no-return level. A
plate or wall that returns light above the noise then lies between that background and
the markers. When it is bright (a white-painted plate, or weak reflectors that make
the exposure long), ``I_t`` falls inside its noise. The active set becomes a speckle
of plate pixels, the blob criteria find dozens of noise blobs, the markers merge with
them, and the matcher can fit the pattern to the speckle. The thresholds there must
be relative to the surface's own level.

A surface is told from the markers by its extent, its level and its evenness. The
pixels lit above the background's noise floor (``noise_floor_sigma`` sigmas), of median
``L``, are a surface when

(a) they outnumber what the catalog's discs can cover at the lit pixels' median range,
    ``SURFACE_AREA_FACTOR`` times over (each disc counted with a pixel of blur and
    mixing around its rim);
(b) ``L`` is at most ``SURFACE_MAX_LEVEL_SHARE`` of the brightest pixel: the markers
    are what is brightest, and a lit set that is mostly markers has its median near
    their cores (0.74-0.93 of I_max on the simulator's frames where markers alone
    outnumbered the discs: a catalog smaller than the markers in view, or 8 m frames
    whose markers fill their pixels), where a plate or wall under markers bright
    enough to be found sits at 0.01-0.3;
(c) their spread (MAD as a sigma) is within ``SURFACE_MAX_SPREAD`` shot-noise sigmas,
    sqrt(count_scale * L), or ``SURFACE_MAX_RELATIVE_SPREAD`` of ``L``: an evenly lit
    surface, not the rims-to-cores spread of markers, glints and a lit room (3.5-47
    noise sigmas and 0.3-1.3 of their median on the simulator's families). The
    relative term is for a plate near the camera, whose shading across it (incidence,
    1 / d^2) outgrows its shot noise: 3.3-4.2 noise sigmas at 1.5-2 m, against 1.2-2.3
    at 3-8 m.

Markers are a minority of the lit pixels then, so they do not move ``L``. The
thresholds become

    I_t    = max(I_t,    L + raw_threshold_rel * (I_max - L),
                         L + noise_floor_sigma * sqrt(count_scale * L))
    I_peak = max(I_peak, L + peak_rel * (I_max - L), I_t)

the paper's rule with ``L`` as the background, and at least ``noise_floor_sigma``
shot-noise sigmas above it. A level whose I_t would reach the frame's brightest pixel
is not a surface behind the markers and is ignored. The frame's ``background``
itself is unchanged: centroids and mixed pixels keep the no-return level.
Where no surface is lit, the paper preset's absolute thresholds are set, or
``ExtractionConfig.surface_threshold`` is off, nothing changes.

Both implementations of the stage (``arithmetic``) use this module: it runs once per
frame on a subsample and is not a hot loop.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from tofpose.config import ExtractionConfig
from tofpose.stages.extraction.constants import LEVEL_STRIDE, MAD_TO_SIGMA
from tofpose.stages.extraction.extraction import FrameStats

#: lit pixels are a surface when they outnumber the catalog's discs' pixels this many times
SURFACE_AREA_FACTOR = 4.0
#: pixels of blur and mixing counted around each disc's rim (its lit area is
#: pi (r + this)^2)
DISC_RIM_PX = 1.0
#: a surface's lit pixels spread at most this many shot-noise sigmas (MAD as a sigma)
SURFACE_MAX_SPREAD = 3.0
#: ... or at most this share of their median (a plate's shading at near range)
SURFACE_MAX_RELATIVE_SPREAD = 0.25
#: a surface's level is at most this share of the frame's brightest pixel
SURFACE_MAX_LEVEL_SHARE = 0.5


def discs_area_px(fx_px: float, range_mm: float, diameters_mm: np.ndarray) -> float:
    """Pixels the catalog's discs (diameters (n,) mm) can light at ``range_mm``, face-on
    (the largest their images get), with ``DISC_RIM_PX`` around each rim."""
    r_px = 0.5 * fx_px * np.asarray(diameters_mm, float) / max(range_mm, 1.0)
    return float(np.sum(np.pi * (r_px + DISC_RIM_PX) ** 2))


def lit_surface_level(
    gray: np.ndarray,
    distance_mm: np.ndarray,
    stats: FrameStats,
    fx_px: float,
    diameters_mm: np.ndarray,
    config: ExtractionConfig,
    count_scale: float = 1.0,
    stride: int = LEVEL_STRIDE,
) -> float:
    """The gray level (counts) of a surface lit above the background's noise floor, or
    NaN when the lit pixels are few enough to be the markers (module docstring).

    gray, distance_mm : (H, W) the frame; stats : its ``frame_levels``; fx_px : the
    camera's focal length; diameters_mm : (n,) the catalog's discs; count_scale : the
    camera's counts per reference count (``CameraModel.count_scale``: its shot noise is
    sqrt(count_scale * gray)). Read on every ``stride``-th row and column, as the
    background is.
    """
    g = np.asarray(gray, np.float32)[::stride, ::stride]
    floor = stats.background + config.noise_floor_sigma * stats.noise_sigma
    lit = g >= np.float32(floor)
    n_lit = int(np.count_nonzero(lit))
    if n_lit == 0:
        return math.nan
    d = np.asarray(distance_mm, np.float32)[::stride, ::stride][lit]
    d = d[np.isfinite(d)]
    if d.size == 0:
        return math.nan
    covered = discs_area_px(fx_px, float(np.median(d)), diameters_mm)
    if n_lit * stride * stride <= SURFACE_AREA_FACTOR * covered:
        return math.nan
    values = g[lit].astype(np.float64)
    level = float(np.median(values))
    if level > SURFACE_MAX_LEVEL_SHARE * stats.i_max:
        return math.nan
    spread = MAD_TO_SIGMA * float(np.median(np.abs(values - level)))
    shot = math.sqrt(count_scale * max(level, 1.0))
    if spread > max(SURFACE_MAX_SPREAD * shot, SURFACE_MAX_RELATIVE_SPREAD * level):
        return math.nan
    return level


def applies(config: ExtractionConfig) -> bool:
    """The rule is on: ``surface_threshold`` set and the thresholds relative (not the
    paper preset's absolute ones)."""
    return config.surface_threshold and config.raw_threshold_abs is None


def thresholds_above_surface(
    stats: FrameStats,
    gray: np.ndarray,
    distance_mm: np.ndarray,
    fx_px: float,
    diameters_mm: np.ndarray,
    config: ExtractionConfig,
    count_scale: float = 1.0,
) -> FrameStats:
    """The frame's levels ``stats`` with I_t and I_peak above its lit surface, if one is
    lit (``lit_surface_level`` then ``above_surface``; arguments as theirs); the frame is
    not read when the rule is off (``applies``)."""
    if not applies(config):
        return stats
    level = lit_surface_level(gray, distance_mm, stats, fx_px, diameters_mm, config, count_scale)
    return above_surface(stats, level, config, count_scale)


def above_surface(
    stats: FrameStats, level: float, config: ExtractionConfig, count_scale: float = 1.0
) -> FrameStats:
    """``stats`` with I_t and I_peak raised above a lit surface of gray ``level``
    (module docstring); unchanged when ``level`` is NaN or the thresholds are the paper
    preset's absolute ones or ``config.surface_threshold`` is off."""
    if not (math.isfinite(level) and applies(config)):
        return stats
    contrast = stats.i_max - level
    i_t = max(
        stats.raw_threshold,
        level + config.raw_threshold_rel * contrast,
        level + config.noise_floor_sigma * math.sqrt(count_scale * max(level, 1.0)),
    )
    if i_t >= stats.i_max:  # the brightest pixels themselves: not a surface behind them
        return stats
    i_peak = stats.peak_threshold
    if config.peak_abs is None:
        i_peak = max(i_peak, level + config.peak_rel * contrast)
    return replace(stats, raw_threshold=i_t, peak_threshold=max(i_peak, i_t), surface_level=level)
