"""Distances beyond the camera's unambiguous range: the size criterion (§3.2) read the
other way round.

A continuous-wave camera measures the distance modulo its unambiguous range U = c / (2 f)
(7.49 m at 20 MHz): a target at 8 m reads 0.5 m. Its reflectors then look far too small
for the catalog at the range they read (a 35 mm disc at 0.5 m would be 23 px across on a
325 px lens; at 8 m it is 1.4 px), and the size window of §3.2 refuses every one of them.
The same window says where they are: the range, among the measured one plus a whole
number of unambiguous ranges, at which the catalog predicts the sizes they have.

``suggested_ranges_mm`` finds that range from the components the window refused
(``WrongSizeBlob``); ``unwrap_about`` then adds to each pixel's distance the whole number
of U that brings it nearest to it. The pipeline measures the frame again with the
unwrapped distances (``PosePipeline.process``), each reading that passes in turn (at most
``MAX_READINGS``): matching against the catalog's geometry and every later check decide
whether the reading was right, as they do for any frame. A wrong reading is refused as a
frame of clutter is, and when none holds the frame's first result stands.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from tofpose.config import ExtractionConfig
from tofpose.stages.extraction.extraction import WrongSizeBlob, predicted_diameter_window_px

#: whole unambiguous ranges tried either way (a 20 MHz camera: 3 x 7.49 m = 22.5 m, past
#: where the paper target's 35 mm discs shrink below a pixel on the EPC660's lens)
MAX_WRAPS = 3


#: a reading is not tried where the catalog's largest disc would be under this many
#: pixels across: no target is measured there anyway (the paper target's 80 mm discs on
#: the EPC660's 325 px lens: 17 m, inside its 25 m unambiguous range at 6 MHz, so no
#: reading is ever tried on it; at 650 px and 20 MHz: 35 m, four and a half ranges)
MIN_DISC_PX = 1.5
#: readings measured again at most, best first (every one ``MAX_WRAPS`` allows: the size
#: window's floor of a pixel lets a far target's sizes pass at each of them)
MAX_READINGS = 2 * MAX_WRAPS


@dataclass(frozen=True)
class WrapSuggestion:
    """A reading of the refused components' distances: ``wraps`` unambiguous ranges added
    (negative: taken off, where an earlier reading added too many), which gives
    ``fitting`` of them the catalog's size; ``about_mm`` their median range so read."""

    wraps: int
    about_mm: float
    fitting: int


def suggested_ranges_mm(
    wrong_size: Sequence[WrongSizeBlob],
    fx_px: float,
    diameters_mm: np.ndarray,
    config: ExtractionConfig,
    unambiguous_range_mm: float,
    min_fitting: int,
    max_range_mm: float,
) -> list[WrapSuggestion]:
    """The readings of ``wrong_size`` (their distances plus a whole number of unambiguous
    ranges, ``MAX_WRAPS`` either way, not 0, at most ``max_range_mm`` away: the window's
    floor of a pixel lets any small component pass far out, ``max_reading_mm``) at which
    most of them have a size the catalog's ``diameters_mm`` (M,) predict
    (``predicted_diameter_window_px``): at least ``min_fitting`` of them and at least
    half of those with a distance. Best first: the
    most fitting, then the fewest wraps, then adding before taking off. The size window
    is wide (a tilted disc, blur), so more than one reading may pass (at 20 MHz, a target
    at 16 m has sizes inside the window at 8.5 m too): the catalog's geometry tells them
    apart, in matching. Empty when U is not finite."""
    if not np.isfinite(unambiguous_range_mm) or unambiguous_range_mm <= 0:
        return []
    measured = [b for b in wrong_size if np.isfinite(b.distance_mm) and b.distance_mm > 0]
    out = []
    for wraps in (n for n in range(-MAX_WRAPS, MAX_WRAPS + 1) if n != 0):
        ranges = []
        for b in measured:
            r = b.distance_mm + wraps * unambiguous_range_mm
            if r <= 0 or r > max_range_mm:
                continue
            low, high = predicted_diameter_window_px(fx_px, r, diameters_mm, config)
            if low <= b.diameter_px <= high:
                ranges.append(r)
        fitting = len(ranges)
        if fitting >= max(min_fitting, 1) and 2 * fitting >= len(measured):
            out.append(WrapSuggestion(wraps, float(np.median(ranges)), fitting))
    return sorted(out, key=lambda s: (-s.fitting, abs(s.wraps), -s.wraps))


def readings_beyond(
    distances_mm: np.ndarray, unambiguous_range_mm: float, max_range_mm: float
) -> list[WrapSuggestion]:
    """Readings of candidates whose sizes do not tell (all inside the size window at the
    range they read: at 20 MHz a target at 10 m reads 2.5 m, where its discs' sizes are
    allowed too) but that match no catalog geometry there: their median distance
    (``distances_mm`` (N,), finite) plus 1 to ``MAX_WRAPS`` unambiguous ranges, then less
    (a frame read about a range may have read too far: the target came nearer), those
    above 0 and up to ``max_range_mm`` (``max_reading_mm``), fewest wraps first. Empty
    when U is not finite."""
    if not np.isfinite(unambiguous_range_mm) or unambiguous_range_mm <= 0 or len(distances_mm) == 0:
        return []
    median = float(np.median(distances_mm))
    out = []
    for n in range(1, MAX_WRAPS + 1):
        for wraps in (n, -n):
            r = median + wraps * unambiguous_range_mm
            if 0 < r <= max_range_mm:
                out.append(WrapSuggestion(wraps, r, len(distances_mm)))
    return out


def max_reading_mm(fx_px: float, diameters_mm: np.ndarray) -> float:
    """The farthest range a reading may put the target at: where the catalog's largest
    disc is ``MIN_DISC_PX`` across."""
    return float(fx_px * np.max(diameters_mm) / MIN_DISC_PX)


def unwrap_about(
    distance_mm: np.ndarray, about_mm: float, unambiguous_range_mm: float
) -> np.ndarray:
    """``distance_mm`` (H, W) with each finite distance plus the whole number (>= 0) of
    ``unambiguous_range_mm`` that brings it nearest to ``about_mm``; NaN stays NaN. Of
    the input's dtype (float32 as ``check_frame`` returns it)."""
    d = np.asarray(distance_mm)
    wraps = np.maximum(np.rint((about_mm - d) / unambiguous_range_mm), 0.0)
    out = d + wraps * unambiguous_range_mm
    return out.astype(d.dtype, copy=False)
