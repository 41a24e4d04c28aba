"""The files a pipeline over a recording is built from, as ``tofpose`` commands read
them: a camera JSON (the camera model, ``tofpose.core.camera.CameraModel``, with, when
present, the ``range_correction`` that ``tofpose calibrate-range`` adds and the
``covariance_scale`` that ``tofpose calibrate-covariance`` adds), or the name of a
shipped camera profile (``tofpose.core.camera_profiles``), and a catalog JSON.
Errors are ``SystemExit`` with a message for the user, as the commands print them."""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from tofpose.calibration.covariance import CovarianceScale
from tofpose.calibration.range import RangeCorrection
from tofpose.config import (
    PersistenceConfig,
    PixelFitConfig,
    TrackingConfig,
    config_for_camera,
)
from tofpose.core.camera import CameraModel
from tofpose.core.camera_profiles import camera_from_profile, profile_names, profile_text
from tofpose.core.catalog import BUILTIN_CATALOGS, Catalog
from tofpose.pipeline import PipelineConfig, PosePipeline
from tofpose.stages.pose.range_bias import RECORDING_FRAMES, LearnedRangeBias, learn_range_bias


def load_camera(text: str) -> tuple[CameraModel, RangeCorrection | None, CovarianceScale | None]:
    """The camera, its range correction and its covariance scale (None where absent)
    from a camera JSON text; ``ValueError`` (or ``KeyError``/``TypeError``) naming what
    is wrong when it is not one. A JSON with a ``profile`` key is a camera profile and
    must state every field (``camera_profiles.REQUIRED_KEYS``)."""
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"camera JSON is not valid JSON: {exc}") from exc
    if not isinstance(doc, dict):
        raise ValueError("camera JSON must be an object")
    if "profile" in doc:
        camera = camera_from_profile(doc, where=f"camera profile {doc['profile']}")
    else:
        camera = CameraModel.from_dict(doc)
    rc, cs = doc.get("range_correction"), doc.get("covariance_scale")
    return (
        camera,
        RangeCorrection.from_dict(rc) if rc is not None else None,
        CovarianceScale.from_dict(cs) if cs is not None else None,
    )


def read_text_file(path: str, what: str) -> str:
    """The text of file ``path``; ``SystemExit`` naming ``what`` and why it cannot be read."""
    try:
        return Path(path).read_text()
    except OSError as exc:
        raise SystemExit(f"tofpose: cannot read {what} {path}: {exc.strerror}") from exc


def read_camera_text(name_or_path: str) -> str:
    """The camera JSON text of a ``--camera`` argument: a shipped profile's name
    (``tofcam660``, ``azure-kinect-nfov``, ...) or a camera JSON file; ``SystemExit``
    naming the file, or listing the profiles when the argument is neither."""
    if name_or_path in profile_names():
        return profile_text(name_or_path)
    if not Path(name_or_path).exists() and not name_or_path.endswith(".json"):
        raise SystemExit(
            f"tofpose: camera {name_or_path!r} is neither a camera JSON file nor a "
            f"camera profile ({', '.join(profile_names())})"
        )
    return read_text_file(name_or_path, "camera")


def catalog_from_arg(name_or_path: str) -> Catalog:
    """The catalog of a ``--catalog`` argument: a built-in catalog's name
    (``BUILTIN_CATALOGS``: ``paper-target``) or a catalog JSON file; ``SystemExit``
    naming a file that cannot be read, ``ValueError`` naming what is wrong in one that
    can (the CLI prints it and exits with 2)."""
    if name_or_path in BUILTIN_CATALOGS:
        return BUILTIN_CATALOGS[name_or_path]()
    return Catalog.from_json(read_text_file(name_or_path, "catalog"))


def camera_from_arg(name_or_path: str) -> CameraModel:
    """The camera of a ``--camera`` argument (``read_camera_text``); ``SystemExit``
    naming what is wrong."""
    try:
        return load_camera(read_camera_text(name_or_path))[0]
    except (ValueError, KeyError, TypeError) as exc:
        raise SystemExit(f"tofpose: camera {name_or_path}: {exc}") from exc


def intrinsics_differ(a: CameraModel, b: CameraModel) -> bool:
    """Whether two cameras' pinhole intrinsics or distortion differ (beyond 1e-6 px)."""
    ka = np.array([a.fx, a.fy, a.cx, a.cy, *a.dist])
    kb = np.array([b.fx, b.fy, b.cx, b.cy, *b.dist])
    return not np.allclose(ka, kb, rtol=0.0, atol=1e-6)


def intrinsics_text(c: CameraModel) -> str:
    """``fx 325.0, fy 325.0, cx 159.5, cy 119.5`` (+ ``distorted`` with a lens model)."""
    text = f"fx {c.fx:g}, fy {c.fy:g}, cx {c.cx:g}, cy {c.cy:g}"
    return text + (", distorted" if any(c.dist) else "")


def pipeline_for(
    rec,
    rec_path: str,
    catalog_path: str | None,
    camera_path: str | None,
    tracking: bool,
    *,
    pixel_fit: bool = False,
    moving: bool = False,
    range_bias: LearnedRangeBias | None = None,
) -> PosePipeline:
    """The pipeline ``estimate`` runs over an open recording: its camera and catalog, or
    the ones given (a camera JSON with its range correction and covariance scale), with
    the pixel- and count-valued settings scaled to the camera (``config_for_camera``);
    ``pixel_fit``: refine each pose on the markers' pixels (``PixelFitConfig``);
    ``moving``: a target whose motion a filter follows (``estimate --filter``): each pose
    from its own frame (``PersistenceConfig.single_frame``), since combining frames
    makes a pose lag a motion too slow for persistence's gates to see;
    ``range_bias``: the range offset's prior learned over the recording
    (``learned_range_bias``): its mean, and its sigma in place of the configured
    calibrated and uncalibrated ones (each capped at the configured one unless the
    frames show a wider spread, ``LearnedRangeBias.prior_sigma_mm``); None: the
    configured prior."""
    camera, correction, scale = rec.camera, None, None
    if camera_path:
        camera, correction, scale = load_camera(read_camera_text(camera_path))
    if catalog_path:
        catalog = catalog_from_arg(catalog_path)
    elif rec.catalog is not None:
        catalog = rec.catalog
    else:
        raise SystemExit(
            f"tofpose: {rec_path} has no /catalog; pass --catalog with a built-in catalog's "
            f"name ({', '.join(BUILTIN_CATALOGS)}) or a catalog JSON file "
            "(its format: docs/architecture.md, 'Catalog JSON')"
        )
    if camera.shape != rec.camera.shape:
        raise SystemExit(
            f"tofpose: camera {camera.width}x{camera.height} does not match the recording's "
            f"{rec.camera.width}x{rec.camera.height} frames"
        )
    if camera_path and intrinsics_differ(camera, rec.camera):
        print(
            f"tofpose: warning: --camera {camera_path} replaces the recording's intrinsics "
            f"({intrinsics_text(rec.camera)}) with its own ({intrinsics_text(camera)}): the "
            "poses are measured with --camera's; give a camera JSON with the recording's "
            "intrinsics to keep them",
            file=sys.stderr,
        )
    config = config_for_camera(
        PipelineConfig(
            tracking=TrackingConfig(enabled=tracking),
            pixel_fit=PixelFitConfig(enabled=pixel_fit),
            persistence=PersistenceConfig.single_frame() if moving else PersistenceConfig(),
        ),
        width=camera.width,
        height=camera.height,
        count_scale=camera.count_scale,
    )
    if range_bias is not None:
        config = replace(
            config,
            range_bias_sigma_mm=range_bias.prior_sigma_mm(config.range_bias_sigma_mm),
            calibrated_range_bias_sigma_mm=range_bias.prior_sigma_mm(
                config.calibrated_range_bias_sigma_mm
            ),
            range_offset_mean_mm=range_bias.mean_mm,
        )
    return PosePipeline(
        camera, catalog, config, range_correction=correction, covariance_scale=scale
    )


def learned_range_bias(
    rec,
    rec_path: str,
    catalog_path: str | None,
    camera_path: str | None,
    *,
    pixel_fit: bool = False,
    max_frames: int = RECORDING_FRAMES,
    progress: bool = True,
    should_stop: Callable[[], bool] | None = None,
) -> LearnedRangeBias | None:
    """The spread of the camera's range offsets over the open recording ``rec``
    (``stages.pose.range_bias``): up to ``max_frames`` frames spaced evenly over it, each
    measured on its own (``pipeline_for``'s pipeline without tracking or persistence
    across frames) with the configured prior, their
    ``PoseResult.range_offset`` pooled. None when the pipeline estimates no offset, or
    too few frames tell it, and when the camera carries a covariance scale
    (``calibrate-covariance``): that was fitted on covariances with the configured
    priors, and keeps them. ``estimate`` and ``reprocess`` measure every frame with it
    (``pipeline_for``'s ``range_bias``). The frames are reset before each (persistence
    and the track; the RANSAC fallback's generator runs on, deterministically). With
    ``pixel_fit`` only the frames it refined count. ``should_stop() -> bool``, polled
    before each frame: True stops it (None returned; the caller says why)."""
    pipe = pipeline_for(
        rec, rec_path, catalog_path, camera_path, False, pixel_fit=pixel_fit, moving=True
    )
    if (
        not pipe.config.solve.estimate_range_offset
        or pipe.covariance_scale is not None
        or rec.n_frames == 0
    ):
        return None
    picked = np.unique(np.linspace(0, rec.n_frames - 1, min(rec.n_frames, max_frames)).astype(int))
    offsets = []
    for i in tqdm(
        picked.tolist(), desc="range bias", unit="frame", disable=not progress, file=sys.stderr
    ):
        if should_stop is not None and should_stop():
            return None
        gray, distance, t = rec.frame(i)
        pipe.reset()
        r = pipe.process(gray, distance, t)
        # with the pixel fit, only its frames: where it falls back, the centroid pose's
        # likelihood is too wide and would read the spread too small
        if r.ok and (not pixel_fit or r.pixel_fit == "ok"):
            offsets.append(r.range_offset)
    return learn_range_bias(offsets)


def resolve_pixel_fit(pixel_fit: bool | None, camera_path: str | None) -> bool:
    """Whether ``estimate`` / ``reprocess`` refine each pose on its pixels: ``pixel_fit``
    when given; by default (None) yes, unless the camera JSON ``camera_path`` carries a
    covariance scale (``calibrate-covariance``), which calibrates the centroid pose's
    covariance: its sigmas are then what the camera's user asked for."""
    if pixel_fit is not None:
        return pixel_fit
    if not camera_path:
        return True  # a recording's own camera carries no covariance scale
    return load_camera(read_camera_text(camera_path))[2] is None
