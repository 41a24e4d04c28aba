"""A study's specification: the grid of cells, frames per cell, seed (``tofpose study``).

JSON (every key but ``grid`` optional; each grid axis a non-empty list, the study runs
every combination)::

    {"name": "envelope", "seed": 1, "frames_per_cell": 100, "chunk_frames": 25,
     "grid": {"range_m": [3, 6], "attitude_deg": [5, 20], "offset_fraction": [0.5],
              "ambient_lux": [1000, 10000], "physics": ["ideal", "lens blur"],
              "catalog": ["paper-target"], "preset": ["default"]}}

* ``range_m``: the target centre's distance from the camera (m);
* ``attitude_deg``: the attitude spread, each of pitch, yaw and roll uniform within
  +- this from facing the camera (deg);
* ``offset_fraction``: the target centre up to this fraction of the half field of view
  off the optical axis (uniform in the image plane);
* ``ambient_lux``: ambient light on the target (lx; 1000 normal, 10000 high, §2.1);
* ``physics``: a domain-randomisation family of ``tofpose.sim.randomise.FAMILIES``;
* ``catalog``: a built-in catalog's name (``tofpose.catalog.BUILTIN_CATALOGS``);
* ``preset``: the pipeline's settings, ``PRESETS``.

Every frame is a fresh acquisition. Frame ``i`` of cell ``c`` draws everything from
``numpy.random.SeedSequence(seed).spawn``'s child ``(c, i)``, so a frame's result
depends on the spec alone: not on the chunking, the number of workers or their order.
"""

from __future__ import annotations

import itertools
import json
import math
from dataclasses import asdict, dataclass, field

from tofpose.catalog import BUILTIN_CATALOGS
from tofpose.pipeline import PipelineConfig
from tofpose.sim.randomise import FAMILIES

#: the pipeline settings a cell may name
PRESETS = {"default": PipelineConfig, "paper": PipelineConfig.paper}

#: the most frames one study may ask for (10^8: ~500 core-hours)
MAX_FRAMES = 100_000_000

GRID_AXES = ("range_m", "attitude_deg", "offset_fraction", "ambient_lux", "physics",
             "catalog", "preset")  # fmt: skip
_DEFAULT_GRID = {"range_m": [3.0], "attitude_deg": [20.0], "offset_fraction": [0.5],
                 "ambient_lux": [1000.0], "physics": ["ideal"], "catalog": ["paper-target"],
                 "preset": ["default"]}  # fmt: skip


class StudySpecError(ValueError):
    """A study specification that cannot run; the message names the field."""


@dataclass(frozen=True)
class Cell:
    """One combination of the grid's values (``StudySpec`` module docstring)."""

    index: int
    range_m: float
    attitude_deg: float
    offset_fraction: float
    ambient_lux: float
    physics: str
    catalog: str
    preset: str

    @property
    def label(self) -> str:
        return (f"{self.range_m:g} m, +-{self.attitude_deg:g} deg, "
                f"off {self.offset_fraction:g}, {self.ambient_lux:g} lx, {self.physics}, "
                f"{self.catalog}, {self.preset}")  # fmt: skip


@dataclass(frozen=True)
class StudySpec:
    """A validated study (module docstring). ``grid``: axis -> tuple of values."""

    grid: dict
    name: str = "study"
    seed: int = 0
    frames_per_cell: int = 100
    chunk_frames: int = 25
    cells: tuple[Cell, ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        axes = [self.grid[a] for a in GRID_AXES]
        cells = tuple(Cell(i, *values) for i, values in enumerate(itertools.product(*axes)))
        object.__setattr__(self, "cells", cells)

    @property
    def n_frames(self) -> int:
        return len(self.cells) * self.frames_per_cell

    def chunks(self) -> list[tuple[int, int, int]]:
        """The study's tasks: (cell index, first frame, end frame) of at most
        ``chunk_frames`` frames each, cell by cell."""
        step = self.chunk_frames
        return [(c.index, a, min(a + step, self.frames_per_cell))
                for c in self.cells for a in range(0, self.frames_per_cell, step)]  # fmt: skip

    def to_dict(self) -> dict:
        d = asdict(self)
        d.pop("cells")
        d["grid"] = {a: list(self.grid[a]) for a in GRID_AXES}
        return d

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2)

    @classmethod
    def from_json(cls, text: str, source: str = "study spec") -> StudySpec:
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as exc:
            raise StudySpecError(f"{source}: not JSON ({exc})") from exc
        return cls.from_dict(doc)

    @classmethod
    def from_dict(cls, doc) -> StudySpec:
        """Validate ``doc``; ``StudySpecError`` naming the first bad field."""
        if not isinstance(doc, dict):
            raise StudySpecError("the study spec must be a JSON object")
        known = {"name", "seed", "frames_per_cell", "chunk_frames", "grid"}
        unknown = sorted(set(doc) - known)
        if unknown:
            raise StudySpecError(f"{unknown[0]}: unknown field (known: {', '.join(sorted(known))})")
        name = doc.get("name", "study")
        if not isinstance(name, str) or not name:
            raise StudySpecError("name: must be a non-empty string")
        seed = _integer(doc, "seed", 0, 0)
        frames = _integer(doc, "frames_per_cell", 100, 1)
        chunk = _integer(doc, "chunk_frames", min(25, frames), 1)
        grid_doc = doc.get("grid")
        if not isinstance(grid_doc, dict):
            raise StudySpecError("grid: must be an object of axes (" + ", ".join(GRID_AXES) + ")")
        unknown = sorted(set(grid_doc) - set(GRID_AXES))
        if unknown:
            raise StudySpecError(f"grid.{unknown[0]}: unknown axis (known: {', '.join(GRID_AXES)})")
        grid = {a: tuple(_axis(a, grid_doc.get(a, _DEFAULT_GRID[a]))) for a in GRID_AXES}
        spec = cls(grid=grid, name=name, seed=seed, frames_per_cell=frames, chunk_frames=chunk)
        if spec.n_frames > MAX_FRAMES:
            raise StudySpecError(f"frames_per_cell: {len(spec.cells)} cells x {frames} frames "
                                 f"is more than {MAX_FRAMES:.0e} frames")  # fmt: skip
        return spec


def _integer(doc: dict, key: str, default: int, minimum: int) -> int:
    v = doc.get(key, default)
    if isinstance(v, bool) or not isinstance(v, int) or v < minimum:
        raise StudySpecError(f"{key}: must be an integer >= {minimum} (got {v!r})")
    return v


def _axis(name: str, values) -> list:
    if not isinstance(values, list) or not values:
        raise StudySpecError(f"grid.{name}: must be a non-empty list")
    out = []
    for k, v in enumerate(values):
        where = f"grid.{name}[{k}]"
        if name in ("physics", "catalog", "preset"):
            allowed = {"physics": FAMILIES, "catalog": tuple(BUILTIN_CATALOGS),
                       "preset": tuple(PRESETS)}[name]  # fmt: skip
            if v not in allowed:
                raise StudySpecError(f"{where}: {v!r} is not one of {', '.join(allowed)}")
            out.append(v)
            continue
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise StudySpecError(f"{where}: must be a number (got {v!r})")
        v = float(v)
        lo, hi = {"range_m": (0.3, 20.0), "attitude_deg": (0.0, 60.0),
                  "offset_fraction": (0.0, 0.9), "ambient_lux": (0.0, 150000.0)}[name]  # fmt: skip
        if not lo <= v <= hi:
            raise StudySpecError(f"{where}: {v:g} is outside [{lo:g}, {hi:g}]")
        out.append(v)
    if len(set(out)) != len(out):
        raise StudySpecError(f"grid.{name}: a value is listed twice")
    return out


#: ``tofpose study --example``: 3 ranges x 2 attitude spreads x 2 physics families, 16
#: frames per cell (192 frames); about a minute on a 2-core machine
EXAMPLE = {
    "name": "example", "seed": 1, "frames_per_cell": 16, "chunk_frames": 8,
    "grid": {"range_m": [3.0, 5.0, 8.0], "attitude_deg": [5.0, 20.0], "offset_fraction": [0.5],
             "ambient_lux": [1000.0], "physics": ["ideal", "lens blur"],
             "catalog": ["paper-target"], "preset": ["default"]},
}  # fmt: skip
