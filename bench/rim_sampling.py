"""How finely the frames of a recording with truth were sampled at the reflectors' rims:
a renderer that point-samples each pixel on an S x S grid instead of integrating its area
quantises a partly covered pixel's coverage to multiples of 1/S^2, and that error (the
same on every frame of one pose) is a model error of the pixel fit that no frame's noise
explains. It sets how near the bound a fit on those frames can come.

Per pose (consecutive frames with the same truth are averaged: their noise shrinks, the
sampling error does not), each catalog disc in view is drawn at the true pose by the
pixel fit's exact-area model (``stages.pixelfit.model``, 8 x 8 sub-cells); its gain and
its surround's level are the medians of the window's wholly covered and wholly clear
pixels. A rim pixel (exact coverage in 0.02-0.98, no other disc) reads the coverage
``(gray - level) / (gain - level)``. Reported: the RMS of read less exact coverage, and
for S = 1..6 the mean distance of ``S^2 * read`` from the nearest integer (0.25 for a
read that is not quantised; near 0 on an S x S grid, raised by the noise left).

    python bench/rim_sampling.py recording.h5 [...]
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tofpose.core.catalog import Catalog  # noqa: E402
from tofpose.core.tof import SPEED_OF_LIGHT_MM_S  # noqa: E402
from tofpose.io.recording import Recording, RecordingError, open_recording  # noqa: E402
from tofpose.stages.pixelfit.model import Discs, build_windows, disc_images  # noqa: E402

#: grids tested: S x S point samples per pixel (1: one sample, a coverage of 0 or 1;
#: the coarsest that fits is named, since a read on 1/S^2 steps is on 1/(kS)^2 too)
GRIDS = (1, 2, 3, 4, 5, 6)
#: a grid is named when its mean distance to the nearest level is below this (0.25 when
#: the reads are not quantised on it)
QUANTISED_BELOW = 0.15
#: rim pixels: exact coverage inside (RIM_MIN, 1 - RIM_MIN)
RIM_MIN = 0.02
#: fewest wholly covered and wholly clear pixels a disc's window needs for its gain and level
MIN_LEVEL_PIXELS = 5
#: sub-cells per pixel side of the exact-area model
MODEL_SUBSAMPLES = 8


@dataclass(frozen=True)
class RimSampling:
    """What a recording's rim pixels say of its renderer's sampling.

    n_poses, n_pixels : poses and rim pixels read; coverage_error_rms : RMS of read less
    exact coverage (noise of the averaged frames included); distance_to_level : S -> mean
    distance of ``S^2 * read`` from the nearest integer; grid : the S whose distance is
    smallest, when below ``QUANTISED_BELOW`` (None: no grid of ``GRIDS`` fits)."""

    n_poses: int
    n_pixels: int
    coverage_error_rms: float
    distance_to_level: dict[int, float]
    grid: int | None

    def describe(self) -> str:
        if self.n_pixels == 0:
            return (
                "no rim pixel could be read (no disc in view with a core below full "
                "scale and a clear surround)"
            )
        if self.grid is None:
            how = f"no point-sampling grid of {GRIDS[0]}-{GRIDS[-1]} per side"
        elif self.grid == 1:
            how = "rims sampled at one point per pixel (coverage 0 or 1)"
        else:
            how = (
                f"rims point-sampled on a {self.grid} x {self.grid} grid per pixel "
                f"(coverage in steps of 1/{self.grid**2})"
            )
        levels = ", ".join(f"{s}: {d:.3f}" for s, d in self.distance_to_level.items())
        return (
            f"{how}; rim coverage read less the exact area's: {self.coverage_error_rms:.3f} "
            f"RMS over {self.n_pixels} rim pixels of {self.n_poses} poses (distance to the "
            f"nearest 1/S^2 level per S, 0.25 unquantised: {levels})"
        )


def _poses(rec: Recording, max_poses: int) -> list[list[int]]:
    """Runs of consecutive frames with the same truth, at most ``max_poses`` of them."""
    assert rec.truth_R is not None and rec.truth_t_mm is not None
    runs: list[list[int]] = []
    for i in range(rec.n_frames):
        same = (
            runs
            and np.array_equal(rec.truth_R[i], rec.truth_R[runs[-1][0]])
            and np.array_equal(rec.truth_t_mm[i], rec.truth_t_mm[runs[-1][0]])
        )
        if same:
            runs[-1].append(i)
        elif len(runs) < max_poses:
            runs.append([i])
        else:
            break
    return runs


def read_rims(
    gray: np.ndarray,
    distance_mm: np.ndarray,
    rec: Recording,
    catalog: Catalog,
    R: np.ndarray,
    t_mm: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """(read, exact) coverages (n,) of the rim pixels of every disc of ``catalog`` in
    view, ``gray`` (H, W) averaged over a pose's frames, at the true pose ``(R, t_mm)``."""
    cam = rec.camera
    front = (catalog.positions_mm @ R.T + t_mm)[:, 2] > 0
    discs = Discs.from_catalog(catalog, [int(i) for i in catalog.ids[front]])
    win = build_windows(gray, distance_mm, cam, discs, R, t_mm, subsamples=MODEL_SUBSAMPLES)
    mm_per_radian = SPEED_OF_LIGHT_MM_S / (4 * np.pi * cam.modulation_frequency_hz)
    images = disc_images(
        R, t_mm, discs, win, mm_per_radian=mm_per_radian, reference_mm=float(t_mm[2])
    )
    total = images.coverage.sum(axis=0)
    read, exact = [], []
    for k in range(len(discs.ids)):
        mine = win.owner == k
        c = images.coverage[k]
        alone = np.isclose(total, c)
        core = mine & alone & (c > 1 - 1e-9)
        clear = mine & (total == 0)
        if core.sum() < MIN_LEVEL_PIXELS or clear.sum() < MIN_LEVEL_PIXELS:
            continue
        gain, level = np.median(win.gray[core]), np.median(win.gray[clear])
        if np.any(win.gray[core] >= cam.full_scale_counts) or gain - level <= 0:
            continue  # a saturated core has no gain to read against
        rim = mine & alone & (c > RIM_MIN) & (c < 1 - RIM_MIN)
        read.append((win.gray[rim] - level) / (gain - level))
        exact.append(c[rim])
    if not read:
        return np.zeros(0), np.zeros(0)
    return np.concatenate(read), np.concatenate(exact)


def rim_sampling(
    rec: Recording, max_poses: int = 16, catalog: Catalog | None = None
) -> RimSampling:
    """``RimSampling`` of the first ``max_poses`` poses of ``rec`` (which needs /truth,
    and /catalog unless ``catalog`` is given: ``RecordingError`` otherwise)."""
    catalog = rec.catalog if catalog is None else catalog
    if rec.truth_R is None or rec.truth_t_mm is None or catalog is None:
        raise RecordingError(f"{rec.path}: rim sampling needs /truth and a catalog")
    read, exact = [np.zeros(0)], [np.zeros(0)]
    runs = _poses(rec, max_poses)
    for run in runs:
        gray = np.mean([rec.frame(i)[0].astype(float) for i in run], axis=0)
        distance = rec.frame(run[0])[1]
        r, e = read_rims(gray, distance, rec, catalog, rec.truth_R[run[0]], rec.truth_t_mm[run[0]])
        read.append(r)
        exact.append(e)
    r, e = np.concatenate(read), np.concatenate(exact)
    if len(r) == 0:
        return RimSampling(len(runs), 0, float("nan"), {}, None)
    dist = {s: float(np.mean(np.abs(s * s * r - np.round(s * s * r)))) for s in GRIDS}
    best = min(dist, key=lambda s: dist[s])
    return RimSampling(
        n_poses=len(runs),
        n_pixels=len(r),
        coverage_error_rms=float(np.sqrt(np.mean((r - e) ** 2))),
        distance_to_level=dist,
        grid=best if dist[best] < QUANTISED_BELOW else None,
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("recordings", nargs="+", help="recordings with /truth (HDF5)")
    ap.add_argument("--poses", type=int, default=16, help="poses read per recording")
    args = ap.parse_args(argv)
    for path in args.recordings:
        try:
            with open_recording(path) as rec:
                found = rim_sampling(rec, args.poses)
            print(f"{Path(path).name}: {found.describe()}")
        except RecordingError as exc:
            print(f"bench/rim_sampling.py: {exc}", file=sys.stderr)
            return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
