"""The persistence stage's constants, shared by its kernels and its reference statement
(defined once: numba freezes a module global into the compiled code as it reads here)."""

from __future__ import annotations

#: the standard normal quantile of ``ranges_consistent``'s test (0.999: a static scene
#: is cut one frame pair in a thousand)
RANGE_TEST_Z = 3.09
#: the most one blob adds to ``ranges_consistent``'s statistic (3 sigma squared)
RANGE_TEST_CLIP = 9.0
#: most pixels of a blob ``ranges_consistent`` reads (every k-th of a larger blob): 48
#: pixel pairs already see a millimetre a frame at 3 m, and a 0.7 m blob has thousands
RANGE_TEST_MAX_PIXELS = 48
#: fewest pixels with a range in both frames for a blob to take part in
#: ``ranges_consistent`` (a median and a MAD of fewer say little about the noise)
RANGE_TEST_MIN_PIXELS = 5
