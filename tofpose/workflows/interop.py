"""``tofpose export mcap`` and ``tofpose import mcap|ros2|k4a`` as functions."""

from __future__ import annotations

import argparse

from tofpose.io.camera_file import camera_from_arg, pipeline_for
from tofpose.io.interop import DEFAULT_MCAP_PROFILE
from tofpose.io.recording import open_recording


def export_file(args: argparse.Namespace) -> str:
    """``tofpose export mcap|rrd``: the recording, and with ``--estimate`` each frame's
    pose, as MCAP in the ``--profile`` (foxglove or ros2) or as a Rerun recording (its
    blueprint embedded); beside a Foxglove-profile MCAP, unless ``--no-viewers``, the
    Foxglove layout and a Rerun blueprint (``viewers.write_viewers``)."""
    from tofpose.io.interop.mcap_profiles import (  # lazy: foxglove-sdk loads a runtime
        check_profile,
        export_mcap_profile,
    )
    from tofpose.io.interop.viewers import write_viewers

    fmt = getattr(args, "format", "mcap")
    profile = check_profile(getattr(args, "profile", DEFAULT_MCAP_PROFILE))
    if fmt == "rrd" and profile != DEFAULT_MCAP_PROFILE:
        raise ValueError("--profile is an MCAP option: export rrd does not take it")

    with open_recording(args.recording) as rec:
        pipe = (
            pipeline_for(rec, args.recording, args.catalog, args.camera, args.tracking)
            if args.estimate
            else None
        )
        if fmt == "rrd":
            from tofpose.io.interop.rerun_export import export_rrd

            s = export_rrd(rec, args.out, pipe, overwrite=args.force)
        else:
            s = export_mcap_profile(
                rec, args.out, pipe, profile=profile, overwrite=args.force, previews=args.previews
            )
    poses = f", {s['ok']} with a pose" if args.estimate else ""
    viewers = ""
    if fmt == "mcap" and profile == DEFAULT_MCAP_PROFILE and getattr(args, "viewers", True):
        written = write_viewers(args.out)
        viewers = f"; beside it: {', '.join(p.name for p in written)}"
        if len(written) == 1:
            viewers += " (no Rerun blueprint: rerun-sdk is not installed)"
    kind = "rrd" if fmt == "rrd" else profile
    return f"{s['frames']} frames{poses} -> {args.out} ({kind}){viewers}"


def import_file(args: argparse.Namespace) -> str:
    """``tofpose import mcap|ros2|k4a``; ``ValueError`` naming an option the format
    does not take."""
    fmt = args.format
    taken = {
        "mcap": ("gray_topic", "distance_topic"),
        "ros2": ("image", "depth", "camera_info", "depth_kind", "camera"),
        "k4a": (),
    }
    options = ("gray_topic", "distance_topic", "image", "depth", "camera_info", "depth_kind")
    wrong = [
        "--" + o.replace("_", "-")
        for o in (*options, "camera")
        if getattr(args, o, None) is not None and o not in taken[fmt]
    ]
    if wrong:
        raise ValueError(f"import {fmt} does not take {', '.join(wrong)}")
    if fmt == "ros2":
        return _import_ros2(args)
    if fmt == "k4a":
        from tofpose.io.interop.k4a_import import import_k4a

        s = import_k4a(args.file, args.out, overwrite=args.force)
        return (
            f"{s['frames']} frames -> {args.out} ({s['camera'].name}, lens as 5 "
            f"coefficients within {s['lens_fit_max_px']:.2f} px)"
        )
    from tofpose.io.interop.mcap_import import import_mcap

    s = import_mcap(
        args.file,
        args.out,
        gray_topic=args.gray_topic,
        distance_topic=args.distance_topic,
        overwrite=args.force,
    )
    return f"{s['frames']} frames -> {args.out}"


def _import_ros2(args: argparse.Namespace) -> str:
    from tofpose.io.interop import ros2_topics
    from tofpose.io.interop.ros2_import import import_ros2

    camera = camera_from_arg(args.camera) if args.camera else None
    s = import_ros2(
        args.file,
        args.out,
        image_topic=args.image or ros2_topics.AMPLITUDE,
        depth_topic=args.depth or ros2_topics.DEPTH,
        camera_info_topic=args.camera_info,
        depth_kind=args.depth_kind,
        camera=camera,
        overwrite=args.force,
    )
    skipped = (
        f", left out {s.unpaired_image} images and {s.unpaired_depth} depth images "
        "without a partner at their stamp"
        if s.unpaired_image or s.unpaired_depth
        else ""
    )
    lens = (
        f", lens as 5 coefficients within {s.lens_fit_max_px:.2f} px" if s.lens_fit_max_px else ""
    )
    clipped = (
        f"; warning: amplitudes up to {s.max_amplitude_counts:.0f} counts, above the "
        f"camera's full scale of {s.camera.full_scale_counts:.0f} ("
        + ("the TOFcam-660's: no --camera given" if camera is None else "--camera's")
        + "): every pixel above it reads as saturated; give --camera with this device's "
        "profile or camera JSON (docs/devices.md) and import again"
        if s.max_amplitude_counts > s.camera.full_scale_counts
        else ""
    )
    return f"{s.frames} frames -> {args.out}{skipped}{lens}{clipped}"
