"""Per-camera range correction, as ToF users calibrate their cameras (docs/algorithm.md).

An uncalibrated CW-ToF camera's distance carries systematic errors that do not average
out: a cyclic error in the modulation phase, an amplitude-related error and per-pixel
offsets. The correction model, linear in its parameters:

    e(d, A, pixel) = c0 + sum_k [s_k sin(4 k phi) + c_k cos(4 k phi)]
                     + k_A log10(A / A_ref) + o[pixel],        phi = 2 pi d / U

(d the measured radial distance, U the unambiguous range, A the pixel's amplitude with
the gray level as its proxy, o a zero-mean per-pixel offset map). It is fitted from a
calibration recording against known geometry: every frame's reference pose (truth) and
the target's known shape give each pixel's true radial distance by ray casting; pixels on
a surface edge are left out (their range mixes two surfaces), and so is the plate (see
``tofpose.sim.pixel_truth.true_pixel_distances``). Varying the integration time during
the calibration run spreads the reflectors' amplitudes over a decade at each distance, which is what
separates the amplitude-related term from the others. The pipeline subtracts
``e`` from each reflector's range before back-projection (Eq. 8).
"""

from __future__ import annotations

import base64
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from tofpose.core.records import RangeCorrectionRecord

AMPLITUDE_REFERENCE_COUNTS = 100.0
OFFSET_QUANTUM_MM = 0.01  # per-pixel offsets are stored as int16 multiples of this


@dataclass(frozen=True)
class RangeCorrection:
    """A fitted range-error model; ``error_mm`` is what the camera adds to the truth.

    harmonics_mm : ((s_1, c_1), (s_2, c_2), ...) for the 4k-th phase harmonics.
    pixel_offsets_mm : (H, W) zero-mean offsets, or None (not fitted).
    calibrated_span_mm : (near, far) measured distances of the samples the fit used, or
        None (a file written before spans were recorded: taken to cover every range).
        Outside it the model is an extrapolation (the amplitude term above all): the
        pipeline still applies it but reports the uncalibrated range-bias uncertainty.
    """

    unambiguous_range_mm: float
    offset_mm: float = 0.0
    harmonics_mm: tuple[tuple[float, float], ...] = ()
    amplitude_mm_per_decade: float = 0.0
    amplitude_reference_counts: float = AMPLITUDE_REFERENCE_COUNTS
    pixel_offsets_mm: np.ndarray | None = field(default=None, compare=False)
    calibrated_span_mm: tuple[float, float] | None = None

    def covers(self, distance_mm: float) -> bool:
        """Whether ``distance_mm`` lies in the span the calibration data covered."""
        if self.calibrated_span_mm is None:
            return True
        near, far = self.calibrated_span_mm
        return bool(near <= distance_mm <= far)

    def error_mm(
        self, distance_mm: np.ndarray, amplitude: np.ndarray, pixel_index: np.ndarray | None
    ) -> np.ndarray:
        """Modelled error for measured distances (N,), amplitudes (N,) and flat pixel
        indices (N,) (None: no per-pixel term)."""
        d = np.asarray(distance_mm, float)
        out = np.full(d.shape, self.offset_mm)
        phi = 2.0 * np.pi * d / self.unambiguous_range_mm
        for k, (s, c) in enumerate(self.harmonics_mm, start=1):
            out += s * np.sin(4 * k * phi) + c * np.cos(4 * k * phi)
        a = np.maximum(np.asarray(amplitude, float), 1e-3)
        out += self.amplitude_mm_per_decade * np.log10(a / self.amplitude_reference_counts)
        if self.pixel_offsets_mm is not None and pixel_index is not None:
            out += self.pixel_offsets_mm.ravel()[np.asarray(pixel_index, int)]
        return out

    def kernel_arguments(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The model as ``stages.persistence.kernels.range_correction.corrected_ranges`` takes it:
        (4,)
        (unambiguous range, offset, amplitude mm per decade, amplitude reference), (k, 2)
        harmonics, (H * W,) pixel offsets (empty when not fitted), all float64."""
        model = np.array(
            [
                self.unambiguous_range_mm,
                self.offset_mm,
                self.amplitude_mm_per_decade,
                self.amplitude_reference_counts,
            ]
        )
        harmonics = np.array(self.harmonics_mm, float).reshape(-1, 2)
        offsets = (
            np.zeros(0)
            if self.pixel_offsets_mm is None
            else np.ascontiguousarray(self.pixel_offsets_mm, float).ravel()
        )
        return model, harmonics, offsets

    def to_dict(self) -> dict:
        d = {
            "model": "cyclic+amplitude+pixel",
            "unambiguous_range_mm": self.unambiguous_range_mm,
            "offset_mm": self.offset_mm,
            "harmonics_mm": [list(h) for h in self.harmonics_mm],
            "amplitude_mm_per_decade": self.amplitude_mm_per_decade,
            "amplitude_reference_counts": self.amplitude_reference_counts,
        }
        if self.calibrated_span_mm is not None:
            d["calibrated_span_mm"] = [float(v) for v in self.calibrated_span_mm]
        if self.pixel_offsets_mm is not None:
            q = np.clip(np.rint(self.pixel_offsets_mm / OFFSET_QUANTUM_MM), -32767, 32767)
            d["pixel_offsets"] = {
                "shape": list(self.pixel_offsets_mm.shape),
                "quantum_mm": OFFSET_QUANTUM_MM,
                "int16_le_base64": base64.b64encode(q.astype("<i2").tobytes()).decode(),
            }
        return d

    @staticmethod
    def from_dict(d: dict) -> RangeCorrection:
        """Parse ``to_dict``'s form; ``ValueError`` naming what is missing or wrong."""
        try:
            offsets = None
            if (p := d.get("pixel_offsets")) is not None:
                h, w = (int(v) for v in p["shape"])
                raw = np.frombuffer(base64.b64decode(p["int16_le_base64"]), "<i2")
                if raw.size != h * w:
                    raise ValueError(f"pixel_offsets hold {raw.size} values for {h} x {w} px")
                offsets = raw.reshape(h, w).astype(float) * float(p["quantum_mm"])
            span = d.get("calibrated_span_mm")
            if span is not None:
                if not isinstance(span, list | tuple) or len(span) != 2:
                    raise ValueError(f"calibrated_span_mm must be [near, far] in mm, got {span!r}")
                near, far = (float(v) for v in span)
                if not 0 <= near <= far:
                    raise ValueError(f"calibrated_span_mm must be 0 <= near <= far, got {span}")
                span = (near, far)
            return RangeCorrection(
                unambiguous_range_mm=float(d["unambiguous_range_mm"]),
                offset_mm=float(d["offset_mm"]),
                harmonics_mm=tuple((float(s), float(c)) for s, c in d["harmonics_mm"]),
                amplitude_mm_per_decade=float(d["amplitude_mm_per_decade"]),
                amplitude_reference_counts=float(
                    d.get("amplitude_reference_counts", AMPLITUDE_REFERENCE_COUNTS)
                ),
                pixel_offsets_mm=offsets,
                calibrated_span_mm=span,
            )
        except KeyError as exc:
            raise ValueError(f"range correction lacks {exc.args[0]!r}") from None


@dataclass(frozen=True)
class RangeCalibrationFit:
    """The fitted model and how well it explains the calibration data (mm)."""

    correction: RangeCorrection
    n_samples: int
    n_frames: int
    rms_before_mm: float
    rms_after_mm: float
    pixels_with_offset: int


def _design(d: np.ndarray, amp: np.ndarray, u: float, n_harm: int, a_ref: float) -> np.ndarray:
    phi = 2.0 * np.pi * d / u
    cols = [np.ones_like(d)]
    for k in range(1, n_harm + 1):
        cols += [np.sin(4 * k * phi), np.cos(4 * k * phi)]
    cols.append(np.log10(np.maximum(amp, 1e-3) / a_ref))
    return np.column_stack(cols)


def fit_range_correction(
    samples: Iterable[tuple[np.ndarray, np.ndarray, np.ndarray]],
    unambiguous_range_mm: float,
    *,
    n_harmonics: int = 2,
    per_pixel: bool = True,
    min_amplitude_counts: float = 20.0,
    min_samples_per_pixel: int = 3,
    max_offset_se_mm: float = 2.0,
) -> RangeCalibrationFit:
    """Fit the model from frames (measured distance (H, W), gray (H, W), true distance
    (H, W), NaN where unknown). Alternates the global fit and the per-pixel means of what
    it leaves. Shot noise makes a pixel's range variance ~ 1 / A, so samples are weighted
    by their amplitude (gray) and cut at 3 robust sigmas of the whitened residual; an
    unweighted fit lets the dim, noisy pixels bias the harmonics. A pixel gets an offset
    only where it is determined to ``max_offset_se_mm`` (standard error) from at least
    ``min_samples_per_pixel`` samples; elsewhere it stays 0."""
    d_list, a_list, t_list, i_list = [], [], [], []
    shape: tuple[int, ...] | None = None
    n_frames = 0
    for meas, gray, true in samples:
        shape = meas.shape
        ok = np.isfinite(meas) & np.isfinite(true) & (gray >= min_amplitude_counts)
        idx = np.flatnonzero(ok)
        d_list.append(meas.ravel()[idx])
        a_list.append(gray.ravel()[idx].astype(float))
        t_list.append(true.ravel()[idx])
        i_list.append(idx)
        n_frames += 1
    if shape is None or not sum(len(x) for x in d_list):  # shape is None: no frame
        raise ValueError("no pixel with a known true distance and enough amplitude to fit")
    d, a, t, pix = (np.concatenate(x) for x in (d_list, a_list, t_list, i_list))
    err = d - t
    X = _design(d, a, unambiguous_range_mm, n_harmonics, AMPLITUDE_REFERENCE_COUNTS)
    sw = np.sqrt(a)  # sqrt of the weight 1 / sigma^2 ~ A
    offsets = np.zeros(int(np.prod(shape)))
    keep = np.ones(len(err), bool)
    covered = np.zeros(len(offsets), bool)

    def solve(target: np.ndarray) -> np.ndarray:
        return np.linalg.lstsq(X[keep] * sw[keep, None], (target * sw)[keep], rcond=None)[0]

    for _ in range(4):
        coef = solve(err - offsets[pix])
        resid = err - X @ coef
        per_pix: np.ndarray = np.zeros(len(offsets))
        wsum: np.ndarray = np.ones(len(offsets))
        if per_pixel:
            wk = np.where(keep, a, 0.0)
            wsum = np.bincount(pix, weights=wk, minlength=len(offsets))
            n = np.bincount(pix[keep], minlength=len(offsets))
            sums = np.bincount(pix, weights=wk * resid, minlength=len(offsets))
            per_pix = np.where(n >= min_samples_per_pixel, sums / np.maximum(wsum, 1e-12), 0.0)
        white = (resid - per_pix[pix]) * sw
        mad = np.median(np.abs(white[keep] - np.median(white[keep])))
        unit_sigma = 1.4826 * max(mad, 1e-9)
        keep = np.abs(white - np.median(white)) < 3.0 * unit_sigma
        if per_pixel:
            se = unit_sigma / np.sqrt(np.maximum(wsum, 1e-12))
            covered = (per_pix != 0) & (se <= max_offset_se_mm)
            offsets = np.where(covered, per_pix, 0.0)
            if covered.any():
                offsets[covered] -= offsets[covered].mean()  # the mean belongs to c0
    coef = solve(err - offsets[pix])
    after = err - X @ coef - offsets[pix]
    harm = tuple((float(coef[1 + 2 * k]), float(coef[2 + 2 * k])) for k in range(n_harmonics))
    corr = RangeCorrection(
        unambiguous_range_mm=unambiguous_range_mm,
        offset_mm=float(coef[0]),
        harmonics_mm=harm,
        amplitude_mm_per_decade=float(coef[-1]),
        pixel_offsets_mm=offsets.reshape(shape) if per_pixel else None,
        calibrated_span_mm=(float(d[keep].min()), float(d[keep].max())),
    )
    return RangeCalibrationFit(
        correction=corr,
        n_samples=int(keep.sum()),
        n_frames=n_frames,
        rms_before_mm=float(np.sqrt(np.mean(err[keep] ** 2))),
        rms_after_mm=float(np.sqrt(np.mean(after[keep] ** 2))),
        pixels_with_offset=int(np.count_nonzero(covered)),
    )


def correction_kernel_arguments(correction: RangeCorrection | None) -> RangeCorrectionRecord:
    """Whether a camera's range correction is applied and its model as
    ``stages.persistence.kernels.range_correction.corrected_ranges`` takes it
    (``RangeCorrection.kernel_arguments``), or False and empty arrays without one: a
    ``core.records.RangeCorrectionRecord``."""
    if correction is None:
        return RangeCorrectionRecord(False, np.zeros(4), np.zeros((0, 2)), np.zeros(0))
    model, harmonics, offsets = correction.kernel_arguments()
    return RangeCorrectionRecord(apply=True, model=model, harmonics=harmonics, offsets=offsets)
