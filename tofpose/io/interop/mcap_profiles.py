"""HDF5 recording -> MCAP file in either profile (``tofpose export mcap --profile``,
the server's ``?profile=``; docs/interop.md): Foxglove's schemas (``mcap_export``) or
ROS 2's messages (``ros2_export``)."""

from __future__ import annotations

from pathlib import Path

from tofpose.io.interop import DEFAULT_MCAP_PROFILE, MCAP_PROFILES
from tofpose.io.interop.mcap_export import export_mcap
from tofpose.io.interop.ros2_export import export_ros2_mcap
from tofpose.io.recording import Recording
from tofpose.pipeline import PosePipeline


def check_profile(profile: str) -> str:
    """``profile`` when it is one of ``MCAP_PROFILES``, else ValueError naming it and them."""
    if profile not in MCAP_PROFILES:
        raise ValueError(
            f"unknown MCAP profile {profile!r}: expected one of {', '.join(MCAP_PROFILES)}"
        )
    return profile


def export_mcap_profile(
    rec: Recording,
    out: str | Path,
    pipeline: PosePipeline | None = None,
    *,
    profile: str = DEFAULT_MCAP_PROFILE,
    progress: bool = True,
    overwrite: bool = False,
    previews: bool = True,
) -> dict[str, int]:
    """``mcap_export.export_mcap`` (``foxglove``) or ``ros2_export.export_ros2_mcap``
    (``ros2``, which has no preview images: ``previews`` is the Foxglove profile's only);
    ValueError naming another profile, before anything is written."""
    if check_profile(profile) == "ros2":
        return export_ros2_mcap(rec, out, pipeline, progress=progress, overwrite=overwrite)
    return export_mcap(
        rec, out, pipeline, progress=progress, overwrite=overwrite, previews=previews
    )
