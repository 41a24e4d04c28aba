"""``tofpose export mcap`` and ``tofpose import mcap`` as functions."""

from __future__ import annotations

import argparse

from tofpose.io.camera_file import pipeline_for
from tofpose.io.interop import DEFAULT_MCAP_PROFILE
from tofpose.io.recording import open_recording


def export_file(args: argparse.Namespace) -> str:
    """``tofpose export mcap``: the recording, and with ``--estimate`` each frame's pose,
    as the ``--profile`` (foxglove or ros2) says."""
    from tofpose.io.interop.mcap_profiles import (  # lazy: foxglove-sdk loads a runtime
        check_profile,
        export_mcap_profile,
    )

    profile = check_profile(getattr(args, "profile", DEFAULT_MCAP_PROFILE))

    with open_recording(args.recording) as rec:
        pipe = (
            pipeline_for(rec, args.recording, args.catalog, args.camera, args.tracking)
            if args.estimate
            else None
        )
        s = export_mcap_profile(
            rec, args.out, pipe, profile=profile, overwrite=args.force, previews=args.previews
        )
    poses = f", {s['ok']} with a pose" if args.estimate else ""
    return f"{s['frames']} frames{poses} -> {args.out} ({profile})"


def import_file(args: argparse.Namespace) -> str:
    """``tofpose import mcap``."""
    from tofpose.io.interop.mcap_import import import_mcap

    s = import_mcap(
        args.file,
        args.out,
        gray_topic=args.gray_topic,
        distance_topic=args.distance_topic,
        overwrite=args.force,
    )
    return f"{s['frames']} frames -> {args.out}"
