"""Target reflector catalogs: the built-in ``paper-target``, validation, JSON I/O.

Catalog JSON (docs/architecture.md §7)::

    {"name": str, "reflectors": [{"id": int, "position_mm": [x, y, z], "diameter_mm": d}]}

Target frame: origin at the plate centre, x right, y up, z out of the plate towards the
camera. Reflectors are flat discs facing +z.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

import numpy as np

# Smallest spread off the best-fit line, relative to the spread along it, for which the
# reflectors count as non-collinear (scale-free: a 1 mm triangle is as good as a 1 m one).
MIN_OFF_LINE_RATIO = 1e-4


@dataclass(frozen=True)
class Reflector:
    """One circular retro-reflector: catalog id, centre in the target frame, diameter."""

    id: int
    position_mm: tuple[float, float, float]
    diameter_mm: float


@dataclass(frozen=True)
class Catalog:
    """A validated set of reflectors.

    Attributes
    ----------
    name : str
    reflectors : tuple of Reflector
    plate_size_mm : (width, height) of the backing plate, centred on the target's origin in
        its z = 0 plane: the simulator draws it and the pixel fit models its edge
        (``stages.pixelfit``); a catalog JSON without it reads the paper target's.
    """

    name: str
    reflectors: tuple[Reflector, ...]
    plate_size_mm: tuple[float, float] = (990.0, 550.0)

    def __post_init__(self) -> None:
        validate_reflectors(self.reflectors)
        object.__setattr__(self, "reflectors", tuple(self.reflectors))

    @property
    def ids(self) -> np.ndarray:
        """Reflector ids, shape (eta,)."""
        return np.array([r.id for r in self.reflectors], dtype=int)

    @property
    def positions_mm(self) -> np.ndarray:
        """Reflector centres in the target frame, shape (eta, 3)."""
        return np.array([r.position_mm for r in self.reflectors], dtype=np.float64)

    @property
    def diameters_mm(self) -> np.ndarray:
        """Reflector diameters, shape (eta,)."""
        return np.array([r.diameter_mm for r in self.reflectors], dtype=np.float64)

    def __len__(self) -> int:
        return len(self.reflectors)

    def pairwise_distances_mm(self) -> np.ndarray:
        """Catalog inter-reflector distances C_relative_ij (Eq. 25), shape (eta, eta)."""
        x = self.positions_mm
        return np.linalg.norm(x[:, None, :] - x[None, :, :], axis=-1)

    # --- serialisation ----------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "plate_size_mm": list(self.plate_size_mm),
            "reflectors": [
                {"id": r.id, "position_mm": list(r.position_mm), "diameter_mm": r.diameter_mm}
                for r in self.reflectors
            ],
        }

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2)

    @staticmethod
    def from_dict(d: Any) -> Catalog:
        if not isinstance(d, dict):
            raise ValueError("catalog must be a JSON object with 'name' and 'reflectors'")
        if "reflectors" not in d or not isinstance(d["reflectors"], list):
            raise ValueError("catalog needs a 'reflectors' list")
        reflectors = []
        for n, r in enumerate(d["reflectors"]):
            try:
                pos = tuple(float(c) for c in r["position_mm"])
                if len(pos) != 3:
                    raise ValueError("position_mm must have 3 coordinates")
                reflectors.append(Reflector(int(r["id"]), pos, float(r["diameter_mm"])))
            except (KeyError, TypeError, ValueError) as exc:
                raise ValueError(
                    f"catalog reflector #{n} is malformed ({exc}); each needs 'id', "
                    "'position_mm' [x, y, z] and 'diameter_mm'"
                ) from exc
        plate = tuple(float(v) for v in d.get("plate_size_mm", (990.0, 550.0)))
        if len(plate) != 2:
            raise ValueError(f"plate_size_mm must be [width, height], got {list(plate)}")
        return Catalog(str(d.get("name", "unnamed")), tuple(reflectors), plate)

    @staticmethod
    def from_json(text: str) -> Catalog:
        try:
            d = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ValueError(f"catalog JSON is not valid JSON: {exc}") from exc
        return Catalog.from_dict(d)


def validate_reflectors(reflectors: tuple[Reflector, ...]) -> None:
    """Raise ``ValueError`` naming the problem: duplicate ids, non-positive or non-finite
    diameters or positions, fewer than 3 reflectors, or all reflectors collinear."""
    if len(reflectors) < 3:
        raise ValueError(f"a catalog needs at least 3 reflectors, got {len(reflectors)}")
    ids = [r.id for r in reflectors]
    dupes = sorted({i for i in ids if ids.count(i) > 1})
    if dupes:
        raise ValueError(f"catalog has duplicate reflector ids: {dupes}")
    for r in reflectors:
        if not (np.isfinite(r.diameter_mm) and r.diameter_mm > 0):
            raise ValueError(f"reflector {r.id}: diameter_mm must be positive, got {r.diameter_mm}")
        if not np.all(np.isfinite(r.position_mm)):
            raise ValueError(f"reflector {r.id}: position_mm must be finite, got {r.position_mm}")
    x = np.array([r.position_mm for r in reflectors], dtype=np.float64)
    centred = x - x.mean(axis=0)
    s = np.linalg.svd(centred, compute_uv=False)
    # s[0] ~ extent along the best-fit line, s[1] ~ spread off it.
    ratio = s[1] / s[0] if s[0] > 0 else 0.0
    if ratio < MIN_OFF_LINE_RATIO:
        raise ValueError(
            "catalog reflectors are collinear (or coincide): their spread off the best-fit "
            f"line is {ratio:.3g} of their extent along it, below {MIN_OFF_LINE_RATIO:g}; "
            "a pose is not determined"
        )


PAPER_TARGET_TABLE = (
    # id, x, y, z, diameter (mm) -- docs/architecture.md §4
    (1, -300.0, -150.0, 100.0, 35.0),
    (2, -300.0, -30.0, 150.0, 35.0),
    (3, -300.0, 120.0, 100.0, 35.0),
    (4, -140.0, -150.0, 100.0, 35.0),
    (5, 100.0, -170.0, 150.0, 80.0),
    (6, 100.0, 60.0, 150.0, 80.0),
    (7, 330.0, -170.0, 100.0, 80.0),
    (8, 420.0, -170.0, 150.0, 80.0),
)


def paper_target() -> Catalog:
    """The paper's target (§2.1, Fig. 1d): 990 x 550 mm plate, 8 raised reflectors."""
    return Catalog(
        "paper-target",
        tuple(Reflector(i, (x, y, z), d) for i, x, y, z, d in PAPER_TARGET_TABLE),
        (990.0, 550.0),
    )


BUILTIN_CATALOGS = {"paper-target": paper_target}


def load_catalog(name_or_json: str) -> Catalog:
    """A built-in catalog by name, or a catalog parsed from JSON text."""
    if name_or_json in BUILTIN_CATALOGS:
        return BUILTIN_CATALOGS[name_or_json]()
    return Catalog.from_json(name_or_json)
