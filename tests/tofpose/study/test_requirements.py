"""A study spec's requirements: the campaign's defaults when left out (an old spec loads
with them), explicit values kept, bad values refused naming the field."""

from __future__ import annotations

import pytest

from tofpose.lab.requirements import PAPER_REQUIREMENTS, REQUIREMENT_AXES
from tofpose.study.spec import EXAMPLE, StudyRequirements, StudySpec, StudySpecError

OLD = {  # a spec as written before studies had requirements
    "name": "old",
    "seed": 1,
    "frames_per_cell": 4,
    "chunk_frames": 2,
    "grid": {"range_m": [3.0, 5.0]},
}


def test_an_old_spec_loads_with_the_campaign_requirements():
    spec = StudySpec.from_dict(OLD)
    assert spec.requirements == StudyRequirements()
    # the defaults campaigns take too (tests/backend/api/test_study_requirements.py)
    for axis in REQUIREMENT_AXES:
        assert spec.requirements.axis(axis) == PAPER_REQUIREMENTS[axis]
    assert spec.requirements.percentile == 95.0
    assert (spec.requirements.x_mm, spec.requirements.z_mm, spec.requirements.roll_deg) == (
        6.0,
        28.3,
        0.15,
    )
    # written back, it carries them, and reads back equal
    doc = spec.to_dict()
    assert doc["requirements"]["pitch_deg"] == 0.15
    assert StudySpec.from_dict(doc) == spec


def test_explicit_requirements_are_kept_and_the_rest_default():
    spec = StudySpec.from_dict(
        {**OLD, "requirements": {"z_mm": 40, "pitch_deg": 0.3, "percentile": 99}}
    )
    r = spec.requirements
    assert (r.z_mm, r.pitch_deg, r.percentile) == (40.0, 0.3, 99.0)
    assert (r.x_mm, r.yaw_deg) == (6.0, 0.15)
    assert StudySpec.from_json(spec.to_json()) == spec
    assert StudySpec.from_dict(EXAMPLE).requirements == StudyRequirements()


@pytest.mark.parametrize(
    ("requirements", "field", "words"),
    [
        ({"pitch_deg": 0}, "requirements.pitch_deg", "must be > 0 and <= 180 deg (got 0)"),
        ({"z_mm": -3.5}, "requirements.z_mm", "must be > 0 and <= 100000 mm (got -3.5)"),
        ({"roll_deg": 200}, "requirements.roll_deg", "<= 180 deg (got 200)"),
        ({"x_mm": "6"}, "requirements.x_mm", "must be a number (got '6')"),
        ({"x_mm": True}, "requirements.x_mm", "must be a number (got True)"),
        ({"yaw_deg": float("nan")}, "requirements.yaw_deg", "must be a number"),
        ({"percentile": 40}, "requirements.percentile", "[50, 100] % (got 40)"),
        ({"percentile": 101}, "requirements.percentile", "(got 101)"),
        ({"pitch": 0.1}, "requirements.pitch", "did you mean 'pitch_deg'?"),
        ([0.15], "requirements", "must be an object"),
    ],
)
def test_bad_requirements_are_refused_naming_the_field(requirements, field, words):
    with pytest.raises(StudySpecError) as err:
        StudySpec.from_dict({**OLD, "requirements": requirements})
    assert err.value.field == field
    assert words in err.value.problem
    assert str(err.value).startswith(field + ": ")
