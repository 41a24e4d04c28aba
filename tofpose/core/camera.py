"""Pinhole camera with OpenCV distortion: projection and back-projection (Eqs. 7-9).

Camera frame S follows OpenCV: x right, y down, z along the boresight. Pixel (u, v) is
(column, row) with the origin at the centre of the top-left pixel. The paper's Eq. 7 uses
x left / y up (``tan phi = (u_p - u) / (f s_x)``); we keep OpenCV signs throughout, which
only flips the sign of the two bearing components.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any, Literal

import cv2
import numpy as np

from tofpose.core.kernels.camera import bearings as kernel_bearings
from tofpose.core.kernels.camera import project as kernel_project
from tofpose.core.tof import SPEED_OF_LIGHT_MM_S

#: what a device's distance image holds: the radial distance along each pixel's ray (a
#: CW-ToF camera's own reading, the pipeline's quantity) or the z depth (the coordinate
#: along the boresight: Azure Kinect, ROS depth images)
DistanceKind = Literal["radial", "z"]
DISTANCE_KINDS: tuple[str, ...] = ("radial", "z")
#: the camera's scalar description, every one stated by a camera profile and stored as a
#: recording's /camera attribute (``dist``, ``name`` and the optional
#: ``unwrapped_range_mm`` beside them)
SCALAR_FIELDS: tuple[str, ...] = (
    "width",
    "height",
    "fx",
    "fy",
    "cx",
    "cy",
    "full_scale_counts",
    "modulation_frequency_hz",
    "count_scale",
    "distance_kind",
    "depth_unit_mm",
    "depth_invalid_code",
    "depth_max_valid_code",
    "focal_length_sigma_rel",
)
#: a relative focal-length sigma this large is not a calibration (10 %)
MAX_FOCAL_LENGTH_SIGMA_REL = 0.1


@dataclass(frozen=True)
class CameraModel:
    """Intrinsics of a ToF camera.

    Attributes
    ----------
    width, height : int
        Image size in pixels.
    fx, fy, cx, cy : float
        Focal lengths and principal point in pixels.
    dist : tuple of 5 floats
        OpenCV distortion coefficients (k1, k2, p1, p2, k3).
    name : str
        Free text, e.g. the device model.
    full_scale_counts : float
        The gray (amplitude) value at which the sensor saturates: a pixel at or above it
        is clipped and carries no distance. 4095 for the paper's 12-bit EPC660; another
        sensor states its own (a recording's ``/camera`` attribute; a camera JSON key).
    modulation_frequency_hz : float
        The modulation frequency of the distance image (its unambiguous range is
        ``tofpose.core.tof.unambiguous_range_mm``); 6 MHz by default, the simulator's.
        On a device that combines several frequencies, the highest: its phase sets the
        distance noise.
    unwrapped_range_mm : float or None
        Where the distance wraps on a device that unwraps the phases of several
        modulation frequencies (or stops reporting beyond its range); None: the single
        frequency's ``c / (2 f)``. ``unambiguous_range_mm`` is the one that applies.
    count_scale : float
        Gray (amplitude) counts of this device per count of the reference 12-bit EPC660
        for the same return: the simulator renders its radiometry in reference counts
        and scales the gray image by this; an absolute count threshold tuned on the
        EPC660 scales by it. 1 for the EPC660.
    distance_kind : {"radial", "z"}
        What the distance images that come with this camera hold: "radial" (along each
        pixel's ray: the pipeline's quantity, the EPC660's) or "z" (depth along the
        boresight: Azure Kinect, ROS depth images). ``tofpose.core.depth`` converts.
    depth_unit_mm : float
        Millimetres per unit of the device's raw distance codes (1: mm codes).
    depth_invalid_code, depth_max_valid_code : int
        The device's raw distance code for "no distance" (0 on most devices) and the
        largest code that is a distance (higher codes are status codes: the TOFcam-660's
        64000 on, the HoloLens 2 AHAT's 4090 on). ``tofpose.core.depth.decode_depth``
        turns both into NaN.
    focal_length_sigma_rel : float
        Relative 1-sigma of the focal lengths as calibrated (e.g. OpenCV's
        ``stdDeviationsIntrinsics`` fx over fx): the image scale is known to it, and the
        pose covariance carries it (docs/algorithm.md, "A common range offset and the
        image scale"). 0: the intrinsics are taken as stated, exact (a simulator's, a
        renderer's, or a description that gives no uncertainty); state the calibration's
        uncertainty for a real camera.
    """

    width: int = 320
    height: int = 240
    fx: float = 325.0
    fy: float = 325.0
    cx: float = 159.5
    cy: float = 119.5
    dist: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)
    name: str = "EPC660 f=6.5mm"
    full_scale_counts: float = 4095.0
    modulation_frequency_hz: float = 6.0e6
    unwrapped_range_mm: float | None = None
    count_scale: float = 1.0
    distance_kind: DistanceKind = "radial"
    depth_unit_mm: float = 1.0
    depth_invalid_code: int = 0
    depth_max_valid_code: int = 63999
    focal_length_sigma_rel: float = 0.0
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.width <= 0 or self.height <= 0:
            raise ValueError(f"camera size must be positive, got {self.width} x {self.height}")
        if self.fx <= 0 or self.fy <= 0:
            raise ValueError(f"focal lengths must be positive, got fx={self.fx}, fy={self.fy}")
        if len(self.dist) != 5:
            raise ValueError(f"dist must have 5 coefficients (k1,k2,p1,p2,k3), got {self.dist}")
        if not self.full_scale_counts > 0:
            raise ValueError(f"full_scale_counts must be positive, got {self.full_scale_counts}")
        if not self.modulation_frequency_hz > 0:
            raise ValueError(
                f"modulation_frequency_hz must be positive, got {self.modulation_frequency_hz}"
            )
        if self.unwrapped_range_mm is not None and not self.unwrapped_range_mm > 0:
            raise ValueError(f"unwrapped_range_mm must be positive, got {self.unwrapped_range_mm}")
        if not self.count_scale > 0:
            raise ValueError(f"count_scale must be positive, got {self.count_scale}")
        if not 0.0 <= self.focal_length_sigma_rel < MAX_FOCAL_LENGTH_SIGMA_REL:
            raise ValueError(
                f"focal_length_sigma_rel must be in [0, {MAX_FOCAL_LENGTH_SIGMA_REL:g}) (a "
                f"relative sigma: 0.002 is 0.2 %), got {self.focal_length_sigma_rel}"
            )
        if self.distance_kind not in DISTANCE_KINDS:
            raise ValueError(
                f"distance_kind must be one of {', '.join(DISTANCE_KINDS)}, "
                f"got {self.distance_kind!r}"
            )
        if not self.depth_unit_mm > 0:
            raise ValueError(f"depth_unit_mm must be positive, got {self.depth_unit_mm}")
        object.__setattr__(self, "dist", tuple(float(d) for d in self.dist))

    @staticmethod
    def epc660() -> CameraModel:
        """The paper's camera (§2.1): 320 x 240, 20 um pixels, f = 6.5 mm -> 325 px."""
        return CameraModel()

    @property
    def unambiguous_range_mm(self) -> float:
        """The radial distance at which the device's distance wraps (mm):
        ``unwrapped_range_mm`` when the device unwraps several frequencies, else
        ``c / (2 f)`` of ``modulation_frequency_hz``."""
        if self.unwrapped_range_mm is not None:
            return self.unwrapped_range_mm
        return SPEED_OF_LIGHT_MM_S / (2.0 * self.modulation_frequency_hz)

    @property
    def K(self) -> np.ndarray:
        """Intrinsic matrix, shape (3, 3)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def dist_array(self) -> np.ndarray:
        return np.asarray(self.dist, dtype=np.float64)

    @property
    def has_distortion(self) -> bool:
        return any(d != 0.0 for d in self.dist)

    @property
    def shape(self) -> tuple[int, int]:
        """Image array shape (rows, columns)."""
        return (self.height, self.width)

    # --- projection -------------------------------------------------------------------
    def project(self, points_mm: np.ndarray) -> np.ndarray:
        """Project camera-frame points of shape (N, 3) to pixels (u, v), shape (N, 2).

        Points must be in front of the camera (z > 0). Computed by
        ``core.kernels.camera.project`` (OpenCV's ``projectPoints`` arithmetic where the lens
        distorts; one compiled call, cheap enough for the per-frame pose check).
        """
        p = np.ascontiguousarray(np.atleast_2d(np.asarray(points_mm, dtype=np.float64)))
        if np.any(p[:, 2] <= 0):
            raise ValueError("cannot project points at or behind the camera (z <= 0)")
        return kernel_project(p, self.fx, self.fy, self.cx, self.cy, self.dist_array)

    def normalized(self, uv_px: np.ndarray) -> np.ndarray:
        """Undistorted normalised coordinates (x/z, y/z), shape (N, 2), of pixels (N, 2)."""
        uv = np.atleast_2d(np.asarray(uv_px, dtype=np.float64))
        if not self.has_distortion:
            return np.column_stack(((uv[:, 0] - self.cx) / self.fx, (uv[:, 1] - self.cy) / self.fy))
        xy = cv2.undistortPoints(uv.reshape(-1, 1, 2), self.K, self.dist_array)
        return xy.reshape(-1, 2)

    def bearings(self, uv_px: np.ndarray) -> np.ndarray:
        """Unit line-of-sight vectors e (Eq. 9), shape (N, 3), of pixels (N, 2): Eq. 8's
        u = [tan phi, tan omega, 1] of the undistorted point, normalised. Computed by
        ``core.kernels.camera.bearings`` (``normalized``'s arithmetic, OpenCV's with lens
        distortion; one compiled call instead of a chain of small NumPy ones)."""
        uv = np.ascontiguousarray(np.asarray(uv_px, dtype=np.float64).reshape(-1, 2))
        return kernel_bearings(uv, self.fx, self.fy, self.cx, self.cy, self.dist_array)

    def back_project(self, uv_px: np.ndarray, distance_mm: np.ndarray) -> np.ndarray:
        """3-D points y = rho * e (Eq. 8), shape (N, 3), from pixels (N, 2) and radial
        distances rho of shape (N,)."""
        return self.bearings(uv_px) * np.asarray(distance_mm, dtype=np.float64)[:, None]

    def pixel_bearings(self) -> np.ndarray:
        """Unit bearing of every pixel centre, shape (H, W, 3), cached."""
        cached = self._cache.get("pixel_bearings")
        if cached is None:
            v, u = np.mgrid[0 : self.height, 0 : self.width].astype(np.float64)
            e = self.bearings(np.column_stack((u.ravel(), v.ravel())))
            cached = e.reshape(self.height, self.width, 3)
            cached.flags.writeable = False
            self._cache["pixel_bearings"] = cached
        return cached

    # --- serialisation ----------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "width": self.width,
            "height": self.height,
            "fx": self.fx,
            "fy": self.fy,
            "cx": self.cx,
            "cy": self.cy,
            "dist": list(self.dist),
            "full_scale_counts": self.full_scale_counts,
            "modulation_frequency_hz": self.modulation_frequency_hz,
            **(
                {}
                if self.unwrapped_range_mm is None
                else {"unwrapped_range_mm": self.unwrapped_range_mm}
            ),
            "count_scale": self.count_scale,
            "distance_kind": self.distance_kind,
            "depth_unit_mm": self.depth_unit_mm,
            "depth_invalid_code": self.depth_invalid_code,
            "depth_max_valid_code": self.depth_max_valid_code,
            "focal_length_sigma_rel": self.focal_length_sigma_rel,
        }

    @staticmethod
    def from_dict(d: dict[str, Any]) -> CameraModel:
        """The camera of a description (``to_dict``'s keys); ``ValueError`` naming a
        missing or invalid key. The keys after the intrinsics are optional, with the
        EPC660's values as defaults (so older files read as they did): 4095 counts,
        6 MHz, no unwrapping, count scale 1, radial distances in mm codes, 0 and codes
        above 63999 invalid, intrinsics exact (focal_length_sigma_rel 0)."""
        required = ("width", "height", "fx", "fy", "cx", "cy")
        missing = [k for k in required if k not in d]
        if missing:
            raise ValueError(f"camera description is missing {', '.join(missing)}")

        def get(key: str, kind: type, default: Any = None) -> Any:
            value = d.get(key, default)
            if value is None:
                return None
            try:
                return kind(value)
            except (TypeError, ValueError) as exc:
                raise ValueError(f"camera {key} must be {kind.__name__}, got {value!r}") from exc

        try:
            dist = tuple(float(x) for x in d.get("dist", (0, 0, 0, 0, 0)))
        except (TypeError, ValueError) as exc:
            raise ValueError(f"camera dist must be 5 numbers, got {d.get('dist')!r}") from exc
        if len(dist) != 5:  # as __post_init__ checks it (and with its message)
            raise ValueError(f"dist must have 5 coefficients (k1,k2,p1,p2,k3), got {dist}")
        return CameraModel(
            width=get("width", int),
            height=get("height", int),
            fx=get("fx", float),
            fy=get("fy", float),
            cx=get("cx", float),
            cy=get("cy", float),
            dist=dist,
            name=get("name", str, ""),
            # older files carry none of these: the EPC660's 12 bits, the simulator's 6 MHz,
            # radial distances in mm
            full_scale_counts=get("full_scale_counts", float, 4095.0),
            modulation_frequency_hz=get("modulation_frequency_hz", float, 6.0e6),
            unwrapped_range_mm=get("unwrapped_range_mm", float),
            count_scale=get("count_scale", float, 1.0),
            distance_kind=get("distance_kind", str, "radial"),
            depth_unit_mm=get("depth_unit_mm", float, 1.0),
            depth_invalid_code=get("depth_invalid_code", int, 0),
            depth_max_valid_code=get("depth_max_valid_code", int, 63999),
            # none stated: the intrinsics as given, exact
            focal_length_sigma_rel=get("focal_length_sigma_rel", float, 0.0),
        )

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2)

    @staticmethod
    def from_json(text: str) -> CameraModel:
        try:
            d = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ValueError(f"camera JSON is not valid JSON: {exc}") from exc
        if not isinstance(d, dict):
            raise ValueError("camera JSON must be an object")
        return CameraModel.from_dict(d)
