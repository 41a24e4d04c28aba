"""Study specs: validation names the field; the grid expands to every combination; the
chunks cover every frame once; a study too large is refused from its axis lengths, before
any cell is made, naming the limit and the numbers."""

import itertools
import json
import tracemalloc

import pytest

from tofpose.sim.randomise import FAMILIES
from tofpose.study import spec as spec_module
from tofpose.study.spec import EXAMPLE, Cell, StudyLimits, StudySpec, StudySpecError

#: 64 x 64 x 64 x 7 = 1,835,008 cells (64 values: the most the server's schema takes per axis)
HUGE = {
    "name": "huge",
    "frames_per_cell": 1,
    "grid": {
        "range_m": [1.0 + 0.25 * i for i in range(64)],
        "attitude_deg": [0.5 * i for i in range(64)],
        "offset_fraction": [0.01 * i for i in range(64)],
        "physics": list(FAMILIES),
    },
}
HUGE_CELLS = 64**3 * len(FAMILIES)


@pytest.fixture
def cells_made(monkeypatch) -> list[int]:
    """Counts the ``Cell`` objects made while the test runs (one entry per cell)."""
    made: list[int] = []
    init = Cell.__init__

    def counting(self, index, *values):
        made.append(index)
        init(self, index, *values)

    monkeypatch.setattr(Cell, "__init__", counting)
    return made


def test_example_expands_to_every_combination_and_chunks_cover_each_frame_once():
    spec = StudySpec.from_dict(EXAMPLE)
    g = EXAMPLE["grid"]
    n_cells = 1
    for values in g.values():
        n_cells *= len(values)
    assert len(spec.cells) == n_cells == 12
    combos = {(c.range_m, c.attitude_deg, c.physics) for c in spec.cells}
    assert len(combos) == n_cells
    frames = [(c, i) for c, a, b in spec.chunks() for i in range(a, b)]
    assert sorted(frames) == [(c.index, i) for c in spec.cells for i in range(16)]
    assert all(b - a <= spec.chunk_frames for _, a, b in spec.chunks())
    assert StudySpec.from_json(spec.to_json()) == spec


@pytest.mark.parametrize(
    ("doc", "field"),
    [
        ({"grid": {"range_m": [0.1]}}, "grid.range_m[0]"),
        ({"grid": {"range_m": [3, "far"]}}, "grid.range_m[1]"),
        ({"grid": {"physics": ["fog"]}}, "grid.physics[0]"),
        ({"grid": {"catalog": ["nope"]}}, "grid.catalog[0]"),
        ({"grid": {"preset": []}}, "grid.preset"),
        ({"grid": {"range_m": [3, 3]}}, "grid.range_m"),
        ({"grid": {"speed": [1]}}, "grid.speed"),
        ({"grid": {}, "frames_per_cell": 0}, "frames_per_cell"),
        ({"grid": {}, "seed": 1.5}, "seed"),
        ({"grid": {}, "colour": "red"}, "colour"),
        ({}, "grid"),
    ],
)
def test_a_bad_field_is_named(doc, field):
    with pytest.raises(StudySpecError) as exc:
        StudySpec.from_dict(doc)
    assert exc.value.field == field and str(exc.value).startswith(field + ": ")


def test_text_that_is_not_json_names_the_source():
    with pytest.raises(StudySpecError, match="my.json: not JSON"):
        StudySpec.from_json("{grid", "my.json")
    assert StudySpec.from_json(json.dumps({"grid": {}})).cells[0].physics == "ideal"


def test_the_cells_made_on_demand_are_itertools_products_order():
    grid = {
        "range_m": [2.0, 4.0, 8.0],
        "attitude_deg": [5.0, 20.0],
        "offset_fraction": [0.1, 0.5],
        "ambient_lux": [1000.0, 10000.0],
        "physics": ["ideal", "gains", "all"],
        "preset": ["default", "paper"],
    }
    spec = StudySpec.from_dict({"grid": grid})
    axes = [
        grid.get(a, [3.0]) if a != "catalog" else ["paper-target"] for a in spec_module.GRID_AXES
    ]
    truth = [Cell(i, *v) for i, v in enumerate(itertools.product(*axes))]
    assert spec.n_cells == len(spec.cells) == len(truth) == 3 * 2 * 2 * 2 * 3 * 2
    assert spec.shape == (3, 2, 2, 2, 3, 1, 2)
    assert list(spec.cells) == truth  # iterating
    assert [spec.cells[i] for i in range(len(truth))] == truth  # indexing, mixed radix
    assert spec.cells[-1] == truth[-1] and spec.cells[5:9] == truth[5:9]
    with pytest.raises(IndexError, match="cell 144 out of range 0..143"):
        spec.cells[144]


@pytest.mark.parametrize(("frames", "chunk"), [(1, 1), (16, 8), (17, 8), (5, 25), (100, 7)])
def test_the_chunk_count_is_known_without_listing_them(frames, chunk):
    spec = StudySpec.from_dict({**EXAMPLE, "frames_per_cell": frames, "chunk_frames": chunk})
    assert spec.n_chunks == len(spec.chunks())
    assert spec.n_frames == sum(b - a for _, a, b in spec.chunks()) == 12 * frames


def test_a_study_at_its_limits_runs_and_one_more_cell_or_frame_is_refused():
    # EXAMPLE: 3 x 2 x 2 = 12 cells of 16 frames, 192 frames
    assert StudySpec.from_dict(EXAMPLE, StudyLimits(max_cells=12, max_frames=192)).n_frames == 192
    with pytest.raises(StudySpecError) as cells:
        StudySpec.from_dict(EXAMPLE, StudyLimits(max_cells=11, max_frames=192, source="X_{what}"))
    assert cells.value.field == "grid" and cells.value.loc == ["grid"]
    assert cells.value.problem == (
        "12 cells (3 range_m x 2 attitude_deg x 2 physics) is more than the limit of 11 (X_CELLS)"
    )
    with pytest.raises(StudySpecError) as frames:
        StudySpec.from_dict(EXAMPLE, StudyLimits(max_cells=12, max_frames=191, source="X_{what}"))
    assert str(frames.value) == (
        "frames_per_cell: 12 cells x 16 frames = 192 frames is more "
        "than the limit of 191 (X_FRAMES)"
    )


def test_tofpose_studys_own_limits_and_none_for_a_stored_spec():
    with pytest.raises(
        StudySpecError,
        match=r"^grid: 1,835,008 cells .* limit of 100,000 "
        r"\(tofpose.study.spec.MAX_CELLS\)$",
    ):
        StudySpec.from_dict(HUGE)
    with pytest.raises(
        StudySpecError,
        match=r"^frames_per_cell: 12 cells x 10,000,000 frames "
        r"= 120,000,000 frames is more than the limit of "
        r"100,000,000 \(tofpose.study.spec.MAX_FRAMES\)$",
    ):
        StudySpec.from_dict({**EXAMPLE, "frames_per_cell": 10**7})
    assert StudySpec.from_dict(HUGE, limits=None).n_cells == HUGE_CELLS  # no cell made


def test_refusing_a_huge_grid_makes_no_cell_and_allocates_almost_nothing(cells_made):
    limits = StudyLimits(max_cells=10_000, max_frames=1_000_000)
    tracemalloc.start()
    try:
        with pytest.raises(StudySpecError) as exc:
            StudySpec.from_dict(HUGE, limits)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert exc.value.field == "grid" and f"{HUGE_CELLS:,} cells" in exc.value.problem
    assert cells_made == []
    assert peak < 1_000_000  # bytes; building the grid took ~330 MB


def test_an_accepted_huge_grid_answers_its_size_and_any_cell_without_making_the_others(
    cells_made,
):
    spec = StudySpec.from_dict(HUGE, limits=None)
    assert (spec.n_cells, spec.n_frames, spec.n_chunks) == (HUGE_CELLS,) * 3
    assert len(spec.cells) == HUGE_CELLS and cells_made == []
    last = spec.cells[HUGE_CELLS - 1]
    assert (last.range_m, last.attitude_deg, last.offset_fraction, last.physics) == (
        16.75,
        31.5,
        0.63,
        "all",
    )
    assert cells_made == [HUGE_CELLS - 1]
