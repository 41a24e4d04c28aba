"""Camera profiles: the camera JSON of a device model, shipped with tofpose and loadable
by name (``tofpose ... --camera azure-kinect-nfov``).

A profile is a camera JSON (``CameraModel.to_dict``'s keys) that states every field
(intrinsics, full scale, count scale, modulation frequency and, where the device unwraps
several frequencies, ``unwrapped_range_mm``, what its distance is and how its raw codes
read) so that nothing falls back to the EPC660's defaults by accident, plus two keys of
its own: ``profile`` (its name) and ``source`` (where the numbers come from). The files
live in ``tofpose/core/profiles/NAME.json``; docs/devices.md says how to write one.
"""

from __future__ import annotations

import json
from importlib import resources
from typing import Any

from tofpose.core.camera import SCALAR_FIELDS, CameraModel

#: the keys a profile must state (``unwrapped_range_mm`` is optional: single frequency)
REQUIRED_KEYS: tuple[str, ...] = ("profile", "source", "name", "dist", *SCALAR_FIELDS)
#: optional keys: a multi-frequency device's range, and what ``tofpose calibrate-range``
#: and ``calibrate-covariance`` add to a camera JSON (``tofpose.io.camera_file``)
OPTIONAL_KEYS: tuple[str, ...] = ("unwrapped_range_mm", "range_correction", "covariance_scale")

#: the profile tofpose uses when none is named: the paper's camera (``CameraModel()``)
DEFAULT_PROFILE = "tofcam660"


def _profile_dir():
    return resources.files("tofpose.core").joinpath("profiles")


def profile_names() -> tuple[str, ...]:
    """The names of the shipped profiles, sorted."""
    return tuple(
        sorted(
            p.name.removesuffix(".json")
            for p in _profile_dir().iterdir()
            if p.name.endswith(".json")
        )
    )


def profile_text(name: str) -> str:
    """The JSON text of the shipped profile ``name``; ``ValueError`` listing the names
    for an unknown one."""
    names = profile_names()
    if name not in names:
        raise ValueError(f"unknown camera profile {name!r}; choose one of {', '.join(names)}")
    return _profile_dir().joinpath(f"{name}.json").read_text()


def camera_from_profile(doc: dict[str, Any], *, where: str = "camera profile") -> CameraModel:
    """The camera of a profile document; ``ValueError`` naming ``where`` and each
    missing or unknown key (a misspelt key would otherwise read as its default)."""
    if not isinstance(doc, dict):
        raise ValueError(f"{where} must be a JSON object")
    missing = [k for k in REQUIRED_KEYS if k not in doc]
    if missing:
        raise ValueError(f"{where} is missing {', '.join(missing)}")
    unknown = sorted(set(doc) - set(REQUIRED_KEYS) - set(OPTIONAL_KEYS))
    if unknown:
        raise ValueError(
            f"{where} has unknown keys {', '.join(unknown)} "
            f"(a profile has {', '.join(REQUIRED_KEYS + OPTIONAL_KEYS)})"
        )
    try:
        return CameraModel.from_dict(doc)
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from exc


def parse_profile(text: str, *, where: str = "camera profile") -> CameraModel:
    """``camera_from_profile`` of a JSON text; ``ValueError`` if it is not JSON."""
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{where} is not valid JSON: {exc}") from exc
    return camera_from_profile(doc, where=where)


def load_profile(name: str) -> CameraModel:
    """The camera of the shipped profile ``name`` (``profile_names()``); ``ValueError``
    listing the names for an unknown one."""
    return parse_profile(profile_text(name), where=f"camera profile {name}")
