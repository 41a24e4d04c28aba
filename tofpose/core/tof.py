"""Continuous-wave time-of-flight relations shared by the pipeline, the simulator and the
server: the speed of light and the unambiguous range of a modulation frequency."""

from __future__ import annotations

SPEED_OF_LIGHT_MM_S = 299_792_458_000.0


def unambiguous_range_mm(modulation_frequency_mhz: float) -> float:
    """c / (2 f): the radial distance at which the measured phase wraps (mm)."""
    if not modulation_frequency_mhz > 0:
        raise ValueError(f"modulation frequency must be > 0 MHz, got {modulation_frequency_mhz}")
    return SPEED_OF_LIGHT_MM_S / (2.0 * modulation_frequency_mhz * 1e6)
