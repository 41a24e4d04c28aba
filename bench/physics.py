"""Physics robustness study: the pipeline on simulated frames whose physics is drawn at
random per frame from what real targets, lenses and sensors do (domain randomisation,
``docs/simulator.md``'s knobs), judged as ``bench/foreign.py`` judges frames from another
renderer (``bench/_foreign_metrics.py``: success, wrong, confidently wrong, share beyond
3 reported sigmas, NEES).

Families: ``tofpose.sim.randomise.ALL_FAMILIES`` (each frame draws its own values;
``draw_frame``): the seven of ``FAMILIES`` on the EPC660, and ``saturating`` (a fixed
exposure: the markers' cores clipped), ``glints`` (15 specular glints around the target),
``other sensor`` (640 x 480, 20 MHz, count scale 4: its own camera, and the pipeline
set for it by ``config_for_camera`` as the CLI does), ``bright plate`` and ``out of
view`` (the target partly out of the frame).

Poses: ranges 3, 4.5, 6 and 8 m, attitude up to 20 deg per axis from facing, the target
centre up to half the half field of view off the optical axis (``out of view``: near an
edge, ``draw_edge_pose``). Each frame is a fresh acquisition.

Run: ``python bench/physics.py [--frames N] [--out DIR] [--families NAME ...]`` (N frames
per family and range; the named families only); ``python bench/physics.py
--compare-pixel-fit [--frames N] [--families NAME ...]``: the same frames with and without
the pixel-level fit, per family.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench._common import pyplot, save_figure, table  # noqa: E402
from bench._foreign_metrics import (  # noqa: E402
    OUTCOME_HEADERS,
    common_scale_error_px,
    common_scale_excess_px,
    marker_errors,
    summarise,
    true_images,
)
from bench.foreign import frame_outcome  # noqa: E402
from tofpose import CameraModel, PipelineConfig, PosePipeline, paper_target  # noqa: E402
from tofpose.config import PixelFitConfig, config_for_camera  # noqa: E402
from tofpose.core.catalog import Catalog  # noqa: E402
from tofpose.sim.randomise import ALL_FAMILIES, DrawnFrame, draw_frame  # noqa: E402

RANGES_M = (3.0, 4.5, 6.0, 8.0)
MAX_ATTITUDE_DEG = 20.0
OFFSET_FRACTION = 0.5  # of the half field of view
#: the examples' crop: this half angle (tan) around the target, 40 px on the EPC660
EXAMPLE_HALF_FOV = 40.0 / 325.0


def run(n: int = 12, seed: int = 0, families: Sequence[str] = ALL_FAMILIES):
    """{(family, range_m): (summary dict, per-marker range errors by diameter)}; the
    summary also holds ``scale_excess_px`` (``common_scale_excess_px`` of the cell)."""
    cat = paper_target()
    pipes = _Pipelines(cat, PipelineConfig())
    out = {}
    jobs = [(f, r) for f in _checked(families) for r in RANGES_M]
    for family, range_m in tqdm(jobs, desc="physics", unit="cell", file=sys.stderr):
        outcomes, scale = [], []
        ranges: dict[int, list[float]] = {}
        for i, (f, d) in enumerate(_frames(family, range_m, n, seed, cat)):
            pipe = pipes.get(d.camera)
            pipe.reset()
            r = pipe.process(f.gray, f.distance_mm)
            T = d.T_camera_target
            truth = true_images(d.camera, cat, T)
            markers = marker_errors(r, truth, cat, 0)  # [] without a pose
            c = common_scale_error_px(r, truth, cat)
            if c is not None:
                scale.append(c)
            for m in markers:
                if m.correct:
                    ranges.setdefault(int(m.diameter_mm), []).append(m.range_error_mm)
            outcomes.append(frame_outcome(i, r, T, markers))
        summary = summarise(outcomes)
        summary["scale_excess_px"] = common_scale_excess_px(scale)
        out[(family, range_m)] = (summary, ranges)
    return out


class _Pipelines:
    """One pipeline per camera, its settings scaled to the camera as the CLI scales them
    (``config_for_camera``)."""

    def __init__(self, catalog: Catalog, config: PipelineConfig) -> None:
        self.catalog, self.config = catalog, config
        self._by_camera: dict[CameraModel, PosePipeline] = {}

    def get(self, camera: CameraModel) -> PosePipeline:
        if camera not in self._by_camera:
            config = config_for_camera(
                self.config,
                width=camera.width,
                height=camera.height,
                count_scale=camera.count_scale,
            )
            self._by_camera[camera] = PosePipeline(camera, self.catalog, config)
        return self._by_camera[camera]


def _checked(families: Sequence[str]) -> list[str]:
    """``families`` in the study's order; ``ValueError`` naming an unknown one."""
    unknown = [f for f in families if f not in ALL_FAMILIES]
    if unknown:
        raise ValueError(f"unknown families {unknown} (one of {', '.join(ALL_FAMILIES)})")
    return [f for f in ALL_FAMILIES if f in families]


def _families_of(out) -> list[str]:
    """The families of a ``run`` or ``compare_pixel_fit`` result, in the study's order."""
    present = {k[0] if isinstance(k, tuple) else k for k in out}
    return [f for f in ALL_FAMILIES if f in present]


def _frames(family: str, range_m: float, n: int, seed: int, cat: Catalog):
    """The study's frames of one cell, (frame, its ``DrawnFrame``) each, drawn as ``run``
    draws them (the same rng stream, so both modes of ``compare_pixel_fit`` see one set;
    seeded by the family's place in ``ALL_FAMILIES``, new families appended)."""
    rng = np.random.default_rng([seed, ALL_FAMILIES.index(family), int(range_m * 10)])
    for _ in range(n):
        d = _draw(family, range_m, rng, cat)
        yield d.render(rng), d


def _draw(family: str, range_m: float, rng: np.random.Generator, cat: Catalog) -> DrawnFrame:
    return draw_frame(
        family,
        range_m,
        rng,
        cat,
        max_attitude_deg=MAX_ATTITUDE_DEG,
        offset_fraction=OFFSET_FRACTION,
    )


def compare_pixel_fit(n: int = 12, seed: int = 0, families: Sequence[str] = ALL_FAMILIES) -> dict:
    """The study's frames (all ranges) measured twice per family: by the default
    pipeline and with the pixel-level fit (``PipelineConfig.pixel_fit``). {family:
    (centroid outcomes, pixel-fit outcomes, ok poses where the fit held, ok poses)}."""
    cat = paper_target()
    plain = _Pipelines(cat, PipelineConfig())
    fitted = _Pipelines(cat, PipelineConfig(pixel_fit=PixelFitConfig(enabled=True)))
    out: dict = {}
    jobs = [(f, r) for f in _checked(families) for r in RANGES_M]
    for family, range_m in tqdm(jobs, desc="physics, pixel fit", unit="cell", file=sys.stderr):
        base, pixel, held, ok = out.setdefault(family, ([], [], [0], [0]))
        for i, (f, d) in enumerate(_frames(family, range_m, n, seed, cat)):
            a_pipe, b_pipe = plain.get(d.camera), fitted.get(d.camera)
            a_pipe.reset()
            b_pipe.reset()
            a = a_pipe.process(f.gray, f.distance_mm)
            b = b_pipe.process(f.gray, f.distance_mm)
            base.append(frame_outcome(i, a, d.T_camera_target, []))
            pixel.append(frame_outcome(i, b, d.T_camera_target, []))
            ok[0] += int(b.ok)
            held[0] += int(b.ok and b.pixel_fit == "ok")
    return {k: (v[0], v[1], v[2][0], v[3][0]) for k, v in out.items()}


#: the ``other sensor`` (20 MHz: 7.49 m unambiguous) at ranges straddling and beyond
#: its unambiguous range, 1-2 ranges wrapped
WRAP_RANGES_M = (7.0, 7.5, 8.0, 10.0, 12.0, 16.0)


def beyond_unambiguous(n: int = 12, seed: int = 0) -> dict:
    """The ``other sensor`` family at ``WRAP_RANGES_M``, each frame a fresh acquisition:
    {range_m: (summary, frames whose pose came from distances read whole unambiguous
    ranges further)}."""
    cat = paper_target()
    pipes = _Pipelines(cat, PipelineConfig())
    out = {}
    for range_m in tqdm(WRAP_RANGES_M, desc="beyond the unambiguous range", file=sys.stderr):
        outcomes, unwrapped = [], 0
        for i, (f, d) in enumerate(_frames("other sensor", range_m, n, seed, cat)):
            pipe = pipes.get(d.camera)
            pipe.reset()
            r = pipe.process(f.gray, f.distance_mm)
            u = d.camera.unambiguous_range_mm
            unwrapped += int(r.ok and any(m.distance_mm > u for m in r.matched))
            outcomes.append(frame_outcome(i, r, d.T_camera_target, []))
        out[range_m] = (summarise(outcomes), unwrapped)
    return out


def beyond_unambiguous_markdown(out: dict, n: int) -> str:
    """``beyond_unambiguous`` as a table, one row per range."""
    rows = [
        [
            f"{r:g} m",
            str(s["frames"]),
            str(unwrapped),
            *_outcome_cells(s),
        ]
        for r, (s, unwrapped) in out.items()
    ]
    return "\n".join(
        [
            "### Beyond the camera's unambiguous range",
            "",
            f"The `other sensor` family (20 MHz: distances wrap at 7.49 m) at ranges "
            f"straddling and beyond its unambiguous range, {n} fresh acquisitions per range; "
            '"read further" counts the ok poses measured with the distances read whole '
            "unambiguous ranges further (docs/algorithm.md, §3.2, distances beyond the "
            "unambiguous range).",
            "",
            table(
                ["range", "frames", "read further", *OUTCOME_HEADERS],
                rows,
            ),
            "",
        ]
    )


def pixel_fit_markdown(cmp: dict, n: int) -> str:
    """The comparison of ``compare_pixel_fit`` as a table, one row per family and mode."""
    rows = []
    for family in _families_of(cmp):
        base, pixel, held, ok = cmp[family]
        for mode, outcomes in (("centroid", base), ("pixel fit", pixel)):
            s = summarise(outcomes)
            rows.append(
                [
                    family,
                    mode,
                    str(s["frames"]),
                    _num(s["success_pct"], 0),
                    str(s["wrong"]),
                    str(s["confident_wrong"]),
                    _num(s["beyond_3sigma_pct"], 0),
                    _num(s["nees_over_6"]),
                    _num(s["median_attitude_deg"], 3),
                    _num(s["median_position_mm"], 2),
                    f"{100.0 * held / ok:.0f}" if mode == "pixel fit" and ok else "-",
                ]
            )
    worst = sum(summarise(v[1])["confident_wrong"] for v in cmp.values())
    return "\n".join(
        [
            "### The pixel-level fit on the same frames",
            "",
            f"The study's frames ({n} per family and range, all four ranges pooled) measured "
            "by the default pipeline and with the pixel-level fit (`--pixel-fit`, "
            '`PipelineConfig.pixel_fit`); "fit held" is the share of ok poses the fit '
            "refined (else it fell back to the centroid pose and said why).",
            "",
            table(
                [
                    "family",
                    "mode",
                    "frames",
                    "success %",
                    "wrong ok",
                    "conf. wrong",
                    "ok > 3 sigma %",
                    "NEES/6",
                    "med att deg",
                    "med pos mm",
                    "fit held %",
                ],
                rows,
            ),
            "",
            f"Confidently wrong poses with the pixel fit, all families: {worst}.",
            "",
        ]
    )


def _outcome_cells(s: dict) -> list[str]:
    """A ``summarise`` result's cells under ``OUTCOME_HEADERS``."""
    return [
        _num(s["success_pct"], 0),
        str(s["wrong"]),
        str(s["confident_wrong"]),
        str(s["no_pose"]),
        _num(s["beyond_3sigma_pct"], 0),
        _num(s["nees_over_6"]),
        _num(s["median_attitude_deg"], 3),
        _num(s["median_position_mm"], 1),
    ]


def _num(x: float, digits: int = 2) -> str:
    return "-" if not math.isfinite(x) else f"{x:.{digits}f}"


def plot(out, path: Path) -> None:
    plt = pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.2))
    families = _families_of(out)
    for k, family in enumerate(families):
        s = [out[(family, r)][0] for r in RANGES_M]
        # ten colours, then dashed lines and squares: no two families look alike
        style = {
            "color": f"C{k % 10}",
            "ls": "-" if k < 10 else "--",
            "marker": "o" if k < 10 else "s",
            "label": family,
        }
        axes[0].plot(RANGES_M, [x["success_pct"] for x in s], **style)
        axes[1].plot(RANGES_M, [x["beyond_3sigma_pct"] for x in s], **style)
        axes[2].plot(RANGES_M, [x["median_attitude_deg"] for x in s], **style)
    for ax, yl in zip(
        axes,
        ("success %", "ok poses beyond 3 sigma %", "median attitude error of successes (deg)"),
        strict=True,
    ):
        ax.set_xlabel("range (m)")
        ax.set_ylabel(yl)
        ax.grid(alpha=0.3)
    axes[1].axhline(5.0, color="k", lw=0.8, ls="--")
    axes[2].legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    fig.suptitle("physics robustness study (domain randomisation per frame)")
    save_figure(fig, path)
    plot_examples(examples_path(path), families=families)


def examples_path(path) -> Path:
    """Where ``plot`` puts the example frames beside the study's plot."""
    return Path(path).with_name(Path(path).stem + "-examples.png")


def plot_examples(
    path: Path, range_m: float = 6.0, seed: int = 0, families: Sequence[str] = ALL_FAMILIES
) -> None:
    """One frame per family at ``range_m`` (the first draw of a stream seeded like the
    study's, so the picture shows what the table measures), the gray image around the
    target (the same field of view on every camera), each panel scaled to its own
    1st-99.9th percentile, in two rows when there are more than five families."""
    plt = pyplot()
    cat = paper_target()
    families = _checked(families)
    cols = len(families) if len(families) <= 5 else math.ceil(len(families) / 2)
    rows = math.ceil(len(families) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(2.6 * cols, 3.2 * rows), squeeze=False)
    for ax in axes.ravel()[len(families) :]:
        ax.set_visible(False)
    for ax, family in zip(axes.ravel(), families, strict=False):
        rng = np.random.default_rng([seed, ALL_FAMILIES.index(family), int(range_m * 10)])
        d = _draw(family, range_m, rng, cat)
        f = d.render(rng)
        cam, T = d.camera, d.T_camera_target
        u, v = cam.project(T.apply(cat.positions_mm.mean(axis=0)[None]))[0]
        half = round(EXAMPLE_HALF_FOV * cam.fx)
        v0, u0 = max(int(v) - half, 0), max(int(u) - half, 0)
        crop = np.asarray(f.gray, float)[v0 : v0 + 2 * half, u0 : u0 + 2 * half]
        lo, hi = np.percentile(crop, [1, 99.9])
        ax.imshow(crop, cmap="gray", vmin=lo, vmax=max(hi, lo + 1))
        ax.set_title(family, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(f"one frame of each family at {range_m:g} m (gray image around the target)")
    save_figure(fig, path)


def markdown(out, img: str, n: int) -> str:
    rows = []
    for family in _families_of(out):
        for r in RANGES_M:
            s, ranges = out[(family, r)]
            bias = {d: float(np.median(v)) if v else math.nan for d, v in ranges.items()}
            rows.append(
                [
                    family,
                    f"{r:g} m",
                    str(s["frames"]),
                    *_outcome_cells(s),
                    _num(bias.get(35, math.nan), 1),
                    _num(bias.get(80, math.nan), 1),
                    _num(s["scale_excess_px"], 3),
                ]
            )
    worst = max(out.values(), key=lambda v: v[0]["confident_wrong"])[0]["confident_wrong"]
    beyond = max(
        v[0]["beyond_3sigma_pct"] for v in out.values() if math.isfinite(v[0]["beyond_3sigma_pct"])
    )
    scale = max(
        (v[0]["scale_excess_px"] for v in out.values() if math.isfinite(v[0]["scale_excess_px"])),
        default=math.nan,
    )
    lines = [
        "## Physics robustness study",
        "",
        f"`bench/physics.py`: {n} frames per family and range, each with its own draw of the "
        "physics (domain randomisation) and a random pose (attitude up to 20 deg per axis, up "
        "to half the half field of view off axis), fresh acquisition; judged as "
        "`bench/foreign.py` judges frames from another renderer (success: <= 1 deg and <= "
        "max(20 mm, 0.5 % range); wrong: ok and > 2 deg or > 2.5x that; confidently wrong: "
        "wrong and beyond chi2_6(0.9973) = 20.06; NEES/6 = 1 is a consistent covariance). "
        "Families: `ideal` the defaults; `grey plate` reflectance 0.25-0.6, no wall; "
        "`lens blur` PSF sigma 0.3-1.5 px and a 0-10 % halo; `gains` reflectors at 0.7-1.3 "
        "of a new one's return and a fall-off exponent of 2-6; `systematic` an uncalibrated "
        "camera (cyclic error 0-15 and 0-5 mm, -10 to +2 mm per decade of amplitude, "
        "per-pixel offsets, a zero offset of -15 to +15 mm, lens scatter); `background` a "
        "room around the target (furniture, a person, shiny fittings; an arm in front of "
        "the target in 30 % of frames); `all` every knob but the background at once with "
        "1-10 klx ambient; `saturating` a fixed exposure for the plate, reflectors facing "
        "the camera at 2-5x full scale (cores clipped, no distance); `glints` 15 specular "
        "glints (Gaussian spots of sigma 0.5-1.6 px, peaks of 400-2500 counts, within 250 mm "
        "of the target's range, around its image); `other sensor` the defaults on a 640 x 480 "
        "camera (same field of view, 20 MHz: 7.49 m unambiguous, so the 8 m frames wrap and are "
        "read one range further; "
        "count scale 4), the pipeline set for it by `config_for_camera`; `bright plate` a "
        "light-painted plate (reflectance 0.6-0.95, no wall) with weaker reflectors (gains "
        "0.7-1.3 each, the retro-reflector gain 4-40 times a white diffuser, default 40); "
        "`out of view` the defaults with the target's centre 0.85-1.2 half fields of view "
        "off the axis towards an edge (part of the target, often all but three markers, "
        "out of the frame). "
        "Range bias: signed median of the matched "
        "reflectors' range error, by diameter. Scale error: the matched centroids' "
        "common-mode (image-scale) error in px of the pattern's rms radius, beyond what "
        "their own sigmas give (`common_scale_excess_px`; the prior "
        "`common_centroid_bias_px` must cover it).",
        "",
        table(
            [
                "family",
                "range",
                "frames",
                *OUTCOME_HEADERS,
                "35 mm range bias",
                "80 mm range bias",
                "scale error px",
            ],
            rows,
        ),
        "",
        f"Largest count of confidently wrong poses in a cell: {worst}; largest share of ok "
        f"poses beyond 3 sigma: {beyond:.0f} %; largest common-mode centroid error: "
        f"{scale:.3f} px.",
        "",
        f"![physics robustness]({img})",
        "",
        f"![one frame per family]({examples_path(img).as_posix()})",
        "",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    """The command line (module docstring): the study's table (and its plots in
    ``--out``), or with ``--compare-pixel-fit`` the pixel-fit comparison's."""
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--frames", type=int, default=12, help="frames per family and range")
    ap.add_argument("--out", default="docs/img/results", help="where the plots go")
    ap.add_argument(
        "--families",
        nargs="+",
        choices=ALL_FAMILIES,
        default=list(ALL_FAMILIES),
        metavar="NAME",
        help=f"the families to run (default all: {', '.join(ALL_FAMILIES)})",
    )
    ap.add_argument("--compare-pixel-fit", action="store_true")
    args = ap.parse_args(argv)
    if args.compare_pixel_fit:
        cmp = compare_pixel_fit(args.frames, families=args.families)
        print(pixel_fit_markdown(cmp, args.frames))
        return
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    data = run(args.frames, families=args.families)
    img = out / "physics.png"
    plot(data, img)
    print(markdown(data, str(img), args.frames))


if __name__ == "__main__":
    main()
