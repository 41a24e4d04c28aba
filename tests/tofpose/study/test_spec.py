"""Study specs: validation names the field; the grid expands to every combination; the
chunks cover every frame once."""

import json

import pytest

from tofpose.study.spec import EXAMPLE, StudySpec, StudySpecError


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
    assert str(exc.value).startswith(field + ":") or str(exc.value).startswith(field)


def test_text_that_is_not_json_names_the_source():
    with pytest.raises(StudySpecError, match="my.json: not JSON"):
        StudySpec.from_json("{grid", "my.json")
    assert StudySpec.from_json(json.dumps({"grid": {}})).cells[0].physics == "ideal"
