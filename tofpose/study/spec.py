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
* ``catalog``: a built-in catalog's name (``tofpose.core.catalog.BUILTIN_CATALOGS``);
* ``preset``: the pipeline's settings, ``PRESETS``.

``requirements`` (optional; every key optional): the accuracy each cell is judged
against, per axis as a campaign's (``x_mm``, ``y_mm``, ``z_mm`` in mm, ``pitch_deg``,
``yaw_deg``, ``roll_deg`` in deg; defaults ``tofpose.lab.requirements.PAPER_REQUIREMENTS``,
the campaign's), and ``percentile``: the share of a cell's frames (%) that must have a
pose within an axis' requirement for the cell to pass it (default 95; 100 = every
frame). ``tofpose.study.verdict`` applies them. A spec written before requirements
existed loads with the defaults.

Every frame is a fresh acquisition. Frame ``i`` of cell ``c`` draws everything from
``numpy.random.SeedSequence(seed).spawn``'s child ``(c, i)``, so a frame's result
depends on the spec alone: not on the chunking, the number of workers or their order.

A study's size is known from its axes alone: cells = the product of the axis lengths,
frames = cells x ``frames_per_cell``. ``from_dict`` checks both against ``StudyLimits``
before anything else is made, and ``StudySpec.cells`` makes each ``Cell`` only when it
is asked for (``CellGrid``), so neither a refusal nor a question about a study's size
costs memory in proportion to its grid.
"""

from __future__ import annotations

import difflib
import itertools
import json
import math
import operator
from collections.abc import Iterator, Sequence
from dataclasses import asdict, dataclass, field, fields

from tofpose.core.catalog import BUILTIN_CATALOGS
from tofpose.lab.requirements import (
    MAX_REQUIREMENT,
    PAPER_REQUIREMENTS,
    REQUIREMENT_AXES,
    axis_unit,
)
from tofpose.pipeline import PipelineConfig
from tofpose.sim.randomise import FAMILIES

#: the pipeline settings a cell may name
PRESETS = {"default": PipelineConfig, "paper": PipelineConfig.paper}

#: ``tofpose study``'s limits (``StudyLimits``' defaults): at most 10^5 cells (the
#: summary and the report hold a row per cell) and 10^8 frames (~900 core-hours at
#: ~30 ms a frame); the server sets its own (``TOFPOSE_STUDY_MAX_CELLS``,
#: ``TOFPOSE_STUDY_MAX_FRAMES``, docs/scaleout.md)
MAX_CELLS = 100_000
MAX_FRAMES = 100_000_000

GRID_AXES = (
    "range_m",
    "attitude_deg",
    "offset_fraction",
    "ambient_lux",
    "physics",
    "catalog",
    "preset",
)
_DEFAULT_GRID = {
    "range_m": [3.0],
    "attitude_deg": [20.0],
    "offset_fraction": [0.5],
    "ambient_lux": [1000.0],
    "physics": ["ideal"],
    "catalog": ["paper-target"],
    "preset": ["default"],
}


class StudySpecError(ValueError):
    """A study specification that cannot run. ``field``: where, as a path into the
    spec's JSON (``grid.range_m[1]``; empty for the spec as a whole); ``problem``: what.
    The message is ``"<field>: <problem>"``."""

    def __init__(self, field: str, problem: str):
        super().__init__(f"{field}: {problem}" if field else problem)
        self.field = field
        self.problem = problem

    @property
    def loc(self) -> list[str | int]:
        """``field`` as a list of keys and indices: ``grid.range_m[1]`` -> ``["grid",
        "range_m", 1]`` (empty for the spec as a whole)."""
        parts = self.field.replace("[", ".").replace("]", "").split(".")
        return [int(p) if p.isdigit() else p for p in parts if p]


#: the share of a cell's frames (%) that must be within a requirement, by default
DEFAULT_PERCENTILE = 95.0
#: the smallest ``percentile`` a spec may ask for: a verdict on fewer than half the frames
#: would say nothing of the cell
MIN_PERCENTILE = 50.0


@dataclass(frozen=True)
class StudyRequirements:
    """What a cell is judged against (module docstring): the largest |error| allowed on
    each axis (mm, deg; the campaign's defaults) and the share of the cell's frames
    (``percentile``, %) that must be within it."""

    x_mm: float = PAPER_REQUIREMENTS["x_mm"]
    y_mm: float = PAPER_REQUIREMENTS["y_mm"]
    z_mm: float = PAPER_REQUIREMENTS["z_mm"]
    pitch_deg: float = PAPER_REQUIREMENTS["pitch_deg"]
    yaw_deg: float = PAPER_REQUIREMENTS["yaw_deg"]
    roll_deg: float = PAPER_REQUIREMENTS["roll_deg"]
    percentile: float = DEFAULT_PERCENTILE

    def axis(self, name: str) -> float:
        """The requirement of axis ``name`` (``REQUIREMENT_AXES``)."""
        return float(getattr(self, name))

    @classmethod
    def from_dict(cls, doc) -> StudyRequirements:
        """Validate a spec's ``requirements`` object (None: the defaults);
        ``StudySpecError`` naming ``requirements.<key>``."""
        if doc is None:
            return cls()
        if not isinstance(doc, dict):
            raise StudySpecError("requirements", "must be an object of axes (" + _KNOWN_REQ + ")")
        known = [f.name for f in fields(cls)]
        for key in doc:
            if key not in known:
                close = difflib.get_close_matches(str(key), known, n=1)
                hint = f"did you mean {close[0]!r}? " if close else ""
                raise StudySpecError(
                    f"requirements.{key}", f"unknown field ({hint}known: {_KNOWN_REQ})"
                )
        values: dict[str, float] = {}
        for axis in REQUIREMENT_AXES:
            if axis in doc:
                hi = MAX_REQUIREMENT[axis_unit(axis)]
                v = _number(doc[axis], f"requirements.{axis}")
                if not 0.0 < v <= hi:
                    raise StudySpecError(
                        f"requirements.{axis}",
                        f"must be > 0 and <= {hi:g} {axis_unit(axis)} (got {v:g})",
                    )
                values[axis] = v
        if "percentile" in doc:
            v = _number(doc["percentile"], "requirements.percentile")
            if not MIN_PERCENTILE <= v <= 100.0:
                raise StudySpecError(
                    "requirements.percentile",
                    f"must be a share of frames in [{MIN_PERCENTILE:g}, 100] % (got {v:g})",
                )
            values["percentile"] = v
        return cls(**values)


_KNOWN_REQ = ", ".join([*REQUIREMENT_AXES, "percentile"])


def _number(v, where: str) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise StudySpecError(where, f"must be a number (got {v!r})")
    return float(v)


@dataclass(frozen=True)
class StudyLimits:
    """How large a study may be: at most ``max_cells`` cells (the product of the grid's
    axis lengths) and ``max_frames`` frames (cells x ``frames_per_cell``). ``source``:
    where the limits are set, named in a refusal (``{what}`` is ``CELLS`` or
    ``FRAMES``)."""

    max_cells: int = MAX_CELLS
    max_frames: int = MAX_FRAMES
    source: str = "tofpose.study.spec.MAX_{what}"

    def check(self, axis_lengths: Sequence[int], frames_per_cell: int) -> None:
        """``StudySpecError`` naming ``grid`` (too many cells) or ``frames_per_cell``
        (too many frames), the numbers and the limit; O(number of axes), nothing made.
        ``axis_lengths``: the number of values on each axis (``GRID_AXES`` order)."""
        n_cells = math.prod(axis_lengths)
        if n_cells > self.max_cells:
            shape = " x ".join(
                f"{n} {a}" for a, n in zip(GRID_AXES, axis_lengths, strict=True) if n > 1
            )
            where = self.source.format(what="CELLS")
            raise StudySpecError(
                "grid",
                f"{n_cells:,} cells ({shape}) is more than the limit "
                f"of {self.max_cells:,} ({where})",
            )
        n_frames = n_cells * frames_per_cell
        if n_frames > self.max_frames:
            where = self.source.format(what="FRAMES")
            raise StudySpecError(
                "frames_per_cell",
                f"{n_cells:,} cells x {frames_per_cell:,} frames = {n_frames:,} frames is more "
                f"than the limit of {self.max_frames:,} ({where})",
            )


#: ``tofpose study``'s limits
CLI_LIMITS = StudyLimits()


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
        return (
            f"{self.range_m:g} m, +-{self.attitude_deg:g} deg, "
            f"off {self.offset_fraction:g}, {self.ambient_lux:g} lx, {self.physics}, "
            f"{self.catalog}, {self.preset}"
        )


class CellGrid(Sequence[Cell]):
    """The cells of a grid, every combination of its axes' values in
    ``itertools.product`` order (the last axis, ``preset``, varies fastest), each
    ``Cell`` made when it is asked for: ``len`` and indexing cost O(number of axes),
    iterating O(1) per cell, and nothing is kept. ``grid``: axis -> tuple of values."""

    def __init__(self, grid: dict):
        self._axes = tuple(tuple(grid[a]) for a in GRID_AXES)
        self._n = math.prod(len(v) for v in self._axes)

    def __len__(self) -> int:
        return self._n

    def __getitem__(self, index):
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(self._n))]
        index = operator.index(index)
        if not -self._n <= index < self._n:
            raise IndexError(f"cell {index} out of range 0..{self._n - 1}")
        index %= self._n
        values, rest = [], index
        for axis in reversed(self._axes):  # mixed radix, the last axis the lowest digit
            rest, k = divmod(rest, len(axis))
            values.append(axis[k])
        return Cell(index, *reversed(values))

    def __iter__(self) -> Iterator[Cell]:
        for i, values in enumerate(itertools.product(*self._axes)):
            yield Cell(i, *values)


@dataclass(frozen=True)
class StudySpec:
    """A validated study (module docstring). ``grid``: axis -> tuple of values."""

    grid: dict
    name: str = "study"
    seed: int = 0
    frames_per_cell: int = 100
    chunk_frames: int = 25
    requirements: StudyRequirements = field(default_factory=StudyRequirements)

    @property
    def shape(self) -> tuple[int, ...]:
        """The number of values on each axis, in ``GRID_AXES`` order."""
        return tuple(len(self.grid[a]) for a in GRID_AXES)

    @property
    def n_cells(self) -> int:
        """The number of cells: the product of the axis lengths (no cell is made)."""
        return math.prod(self.shape)

    @property
    def cells(self) -> CellGrid:
        """Every cell, made on demand (``CellGrid``)."""
        return CellGrid(self.grid)

    @property
    def n_frames(self) -> int:
        """Frames in all: cells x ``frames_per_cell``."""
        return self.n_cells * self.frames_per_cell

    @property
    def n_chunks(self) -> int:
        """The number of tasks, ``len(chunks())``, from the sizes alone."""
        return self.n_cells * -(-self.frames_per_cell // self.chunk_frames)

    def chunks(self) -> list[tuple[int, int, int]]:
        """The study's tasks: (cell index, first frame, end frame) of at most
        ``chunk_frames`` frames each, cell by cell."""
        step = self.chunk_frames
        frames = self.frames_per_cell
        return [
            (c, a, min(a + step, frames))
            for c in range(self.n_cells)
            for a in range(0, frames, step)
        ]

    def to_dict(self) -> dict:
        d = asdict(self)
        d["grid"] = {a: list(self.grid[a]) for a in GRID_AXES}
        return d

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2)

    @classmethod
    def from_json(
        cls, text: str, source: str = "study spec", limits: StudyLimits | None = CLI_LIMITS
    ) -> StudySpec:
        """``from_dict`` of the JSON ``text``; ``source`` names it when it is not JSON."""
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as exc:
            raise StudySpecError(source, f"not JSON ({exc})") from exc
        return cls.from_dict(doc, limits)

    @classmethod
    def from_dict(cls, doc, limits: StudyLimits | None = CLI_LIMITS) -> StudySpec:
        """Validate ``doc``; ``StudySpecError`` naming the first bad field. The study's
        size (``limits``; None: no limit, for a spec already accepted) is checked from
        the axis lengths before the spec is made."""
        if not isinstance(doc, dict):
            raise StudySpecError("", "the study spec must be a JSON object")
        known = {"name", "seed", "frames_per_cell", "chunk_frames", "grid", "requirements"}
        unknown = sorted(set(doc) - known)
        if unknown:
            raise StudySpecError(unknown[0], f"unknown field (known: {', '.join(sorted(known))})")
        name = doc.get("name", "study")
        if not isinstance(name, str) or not name:
            raise StudySpecError("name", "must be a non-empty string")
        seed = _integer(doc, "seed", 0, 0)
        frames = _integer(doc, "frames_per_cell", 100, 1)
        chunk = _integer(doc, "chunk_frames", min(25, frames), 1)
        grid_doc = doc.get("grid")
        if not isinstance(grid_doc, dict):
            raise StudySpecError("grid", "must be an object of axes (" + ", ".join(GRID_AXES) + ")")
        unknown = sorted(set(grid_doc) - set(GRID_AXES))
        if unknown:
            axes = ", ".join(GRID_AXES)
            raise StudySpecError(f"grid.{unknown[0]}", f"unknown axis (known: {axes})")
        grid = {a: tuple(_axis(a, grid_doc.get(a, _DEFAULT_GRID[a]))) for a in GRID_AXES}
        requirements = StudyRequirements.from_dict(doc.get("requirements"))
        if limits is not None:
            limits.check([len(grid[a]) for a in GRID_AXES], frames)
        return cls(
            grid=grid,
            name=name,
            seed=seed,
            frames_per_cell=frames,
            chunk_frames=chunk,
            requirements=requirements,
        )


def _integer(doc: dict, key: str, default: int, minimum: int) -> int:
    v = doc.get(key, default)
    if isinstance(v, bool) or not isinstance(v, int) or v < minimum:
        raise StudySpecError(key, f"must be an integer >= {minimum} (got {v!r})")
    return v


def _axis(name: str, values) -> list:
    if not isinstance(values, list) or not values:
        raise StudySpecError(f"grid.{name}", "must be a non-empty list")
    out = []
    for k, v in enumerate(values):
        where = f"grid.{name}[{k}]"
        if name in ("physics", "catalog", "preset"):
            allowed = {
                "physics": FAMILIES,
                "catalog": tuple(BUILTIN_CATALOGS),
                "preset": tuple(PRESETS),
            }[name]
            if v not in allowed:
                raise StudySpecError(where, f"{v!r} is not one of {', '.join(allowed)}")
            out.append(v)
            continue
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise StudySpecError(where, f"must be a number (got {v!r})")
        v = float(v)
        lo, hi = {
            "range_m": (0.3, 20.0),
            "attitude_deg": (0.0, 60.0),
            "offset_fraction": (0.0, 0.9),
            "ambient_lux": (0.0, 150000.0),
        }[name]
        if not lo <= v <= hi:
            raise StudySpecError(where, f"{v:g} is outside [{lo:g}, {hi:g}]")
        out.append(v)
    if len(set(out)) != len(out):
        raise StudySpecError(f"grid.{name}", "a value is listed twice")
    return out


#: ``tofpose study --example``: 3 ranges x 2 attitude spreads x 2 physics families, 16
#: frames per cell (192 frames), the default requirements spelt out; about a minute on
#: a 2-core machine
EXAMPLE = {
    "name": "example",
    "seed": 1,
    "frames_per_cell": 16,
    "chunk_frames": 8,
    "grid": {
        "range_m": [3.0, 5.0, 8.0],
        "attitude_deg": [5.0, 20.0],
        "offset_fraction": [0.5],
        "ambient_lux": [1000.0],
        "physics": ["ideal", "lens blur"],
        "catalog": ["paper-target"],
        "preset": ["default"],
    },
    "requirements": {**PAPER_REQUIREMENTS, "percentile": DEFAULT_PERCENTILE},
}
