"""Systematic range errors of a real, uncalibrated CW-ToF camera (docs/simulator.md).

The ideal simulated sensor measures the phasor distance plus shot noise. Real continuous-
wave ToF cameras add errors that do not average out; each is a term here, switchable
(set its magnitude to 0), with default magnitudes of the order reported by published
ToF calibration studies (references in docs/simulator.md):

- cyclic ("wiggling") error: the modulation is not a pure sinusoid, and with four phase
  taps its odd harmonics alias into a distance error periodic in the phase, mostly at 4x
  and 8x the fundamental: ``sum_k a_k sin(4 k phi + p_k)`` with ``phi = 2 pi d / U``
  (U the unambiguous range);
- amplitude-related error: bright pixels read a different distance from dim ones,
  ``k_A log10(A / A_ref)`` (retro-reflector pixels are 10-100x brighter than the plate);
- per-pixel fixed-pattern offsets (DRNU): a smooth radial term plus a per-pixel random
  offset, fixed for a camera (seeded);
- temperature drift: the camera warms after power-on, ``k_T dT (1 - exp(-t / tau))``;
- zero offset: a distance offset common to every pixel, the illumination driver's and
  the pixel's delays that no user calibration removed (a factory offset, its change with
  another LED board or cable, the drift of a camera already warm);
- lens scatter: a small fraction of each pixel's light spreads as a wide halo, so a bright
  reflector mixes its phase into its neighbours (added to the phasor, before the
  distance is taken).

Not modelled yet: motion artefacts (the four phase sub-frames seeing different scenes
while the turntable slews).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace

import cv2
import numpy as np


@dataclass(frozen=True)
class SystematicErrors:
    """Magnitudes of the systematic range errors (mm unless named otherwise).

    wiggle_amplitudes_mm, wiggle_phases_rad : a_k, p_k of the cyclic error, k = 1, 2 for
        the 4th and 8th harmonic of the modulation phase.
    amplitude_mm_per_decade, amplitude_reference_counts : k_A, A_ref.
    pixel_offset_sigma_mm : per-pixel random offset (1 sigma); pixel_offset_corner_mm :
        smooth radial offset reached at the image corner; pixel_offset_seed : the camera.
    drift_mm_per_kelvin, warmup_kelvin, warmup_tau_s : k_T, dT, tau.
    scatter_fraction, scatter_sigma_px : share of light spread into a Gaussian halo of
        that width.
    offset_mm : the zero offset, common to every pixel.
    """

    wiggle_amplitudes_mm: tuple[float, ...] = (7.0, 2.5)
    wiggle_phases_rad: tuple[float, ...] = (0.6, 1.9)
    amplitude_mm_per_decade: float = -6.0
    amplitude_reference_counts: float = 100.0
    pixel_offset_sigma_mm: float = 3.0
    pixel_offset_corner_mm: float = 8.0
    pixel_offset_seed: int = 660
    drift_mm_per_kelvin: float = 0.8
    warmup_kelvin: float = 12.0
    warmup_tau_s: float = 900.0
    scatter_fraction: float = 0.004
    scatter_sigma_px: float = 12.0
    offset_mm: float = 0.0

    @staticmethod
    def none() -> SystematicErrors:
        """Every term off (the ideal sensor)."""
        return SystematicErrors(
            wiggle_amplitudes_mm=(0.0, 0.0),
            wiggle_phases_rad=(0.0, 0.0),
            amplitude_mm_per_decade=0.0,
            pixel_offset_sigma_mm=0.0,
            pixel_offset_corner_mm=0.0,
            drift_mm_per_kelvin=0.0,
            warmup_kelvin=0.0,
            scatter_fraction=0.0,
            offset_mm=0.0,
        )

    def only(self, *terms: str) -> SystematicErrors:
        """These defaults with every term but ``terms`` switched off: ``"wiggle"``,
        ``"amplitude"``, ``"pixel"``, ``"drift"``, ``"scatter"``, ``"offset"``."""
        off = SystematicErrors.none()
        keep = {
            "wiggle": ("wiggle_amplitudes_mm", "wiggle_phases_rad"),
            "amplitude": ("amplitude_mm_per_decade",),
            "pixel": ("pixel_offset_sigma_mm", "pixel_offset_corner_mm"),
            "drift": ("drift_mm_per_kelvin",),
            "scatter": ("scatter_fraction",),
            "offset": ("offset_mm",),
        }
        unknown = set(terms) - keep.keys()
        if unknown:
            raise ValueError(f"unknown error terms {sorted(unknown)}; choose from {list(keep)}")
        changes = {f: getattr(self, f) for t in terms for f in keep[t]}
        return replace(off, **changes)

    # -- the terms ------------------------------------------------------------------------
    def cyclic_mm(self, distance_mm: np.ndarray, unambiguous_range_mm: float) -> np.ndarray:
        """Cyclic error at these distances, same shape."""
        phi = 2.0 * np.pi * np.asarray(distance_mm, float) / unambiguous_range_mm
        out = np.zeros_like(phi)
        for k, (a, p) in enumerate(
            zip(self.wiggle_amplitudes_mm, self.wiggle_phases_rad, strict=True), start=1
        ):
            if a:
                out += a * np.sin(4 * k * phi + p)
        return out

    def amplitude_mm(self, amplitude_counts: np.ndarray) -> np.ndarray:
        """Amplitude-related error, same shape (0 where the amplitude is 0)."""
        a = np.maximum(np.asarray(amplitude_counts, float), 1e-6)
        return self.amplitude_mm_per_decade * np.log10(a / self.amplitude_reference_counts)

    def pixel_offsets_mm(self, height: int, width: int) -> np.ndarray:
        """The camera's fixed per-pixel offsets, shape (height, width) (read-only: cached)."""
        return _pixel_offsets(
            self.pixel_offset_corner_mm,
            self.pixel_offset_sigma_mm,
            self.pixel_offset_seed,
            height,
            width,
        )

    def drift_mm(self, time_s: float) -> float:
        """Temperature drift after ``time_s`` seconds of operation."""
        warm = self.warmup_kelvin * (1.0 - np.exp(-max(time_s, 0.0) / self.warmup_tau_s))
        return float(self.drift_mm_per_kelvin * warm)

    def scatter(self, re: np.ndarray, im: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The phasor images (H, W) with the lens-scatter halo added."""
        if not self.scatter_fraction:
            return re, im
        ks = 2 * int(np.ceil(3 * self.scatter_sigma_px)) + 1
        halo = [cv2.GaussianBlur(x, (ks, ks), self.scatter_sigma_px) for x in (re, im)]
        f = self.scatter_fraction
        return (1 - f) * re + f * halo[0], (1 - f) * im + f * halo[1]


@functools.lru_cache(maxsize=4)
def _pixel_offsets(corner_mm: float, sigma_mm: float, seed: int, height: int, width: int):
    """Smooth radial offset (``corner_mm`` at the corners) plus a seeded per-pixel one."""
    v, u = np.mgrid[0:height, 0:width].astype(float)
    r2 = ((u - (width - 1) / 2) ** 2 + (v - (height - 1) / 2) ** 2) / (
        ((width - 1) / 2) ** 2 + ((height - 1) / 2) ** 2
    )
    rng = np.random.default_rng(seed)
    out = corner_mm * r2 + sigma_mm * rng.standard_normal((height, width))
    out.flags.writeable = False
    return out
