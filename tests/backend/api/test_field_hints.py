"""An unknown field in a request body names the closest valid one
(``backend/api/field_hints.py``), at the top of the body and inside a discriminated
union; the rest of the 422 is FastAPI's."""

from __future__ import annotations

from typing import Annotated, Literal

import pytest
from pydantic import BaseModel, ConfigDict, Field

from backend.api.field_hints import fields_at, unknown_field_message
from tests.backend.conftest import AUTH, running_app


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class _Ramp(_Strict):
    kind: Literal["ramp"]
    rate_deg_s: float


class _Sine(_Strict):
    kind: Literal["sine"]
    period_s: float


class _Body(_Strict):
    name: str
    steps: list[Annotated[_Ramp | _Sine, Field(discriminator="kind")]] = []


def test_the_fields_at_a_location_follow_models_lists_and_the_union_tag():
    assert fields_at(_Body, []) == {"name", "steps"}
    assert fields_at(_Body, ["steps", 0, "ramp"]) == {"kind", "rate_deg_s"}
    assert fields_at(_Body, ["steps", 3, "sine"]) == {"kind", "period_s"}
    assert fields_at(_Body, ["nothing"]) == set()


def test_the_message_offers_the_closest_name_or_lists_the_few_valid_ones():
    said = unknown_field_message("rate_deg", {"kind", "rate_deg_s"})
    assert said.endswith("did you mean 'rate_deg_s'?")
    listed = unknown_field_message("zzz", {"kind", "period_s"})
    assert "(valid: 'kind', 'period_s')" in listed
    assert unknown_field_message("zzz", set()).endswith("is not a field here")


@pytest.mark.parametrize(
    ("body", "loc", "meant"),
    [
        (
            {"name": "a", "generatr": {"kind": "calibration", "rails_mm": [11000, 12500]}},
            ["body", "generatr"],
            "generator",
        ),
        (
            {"name": "a", "generator": {"kind": "calibration", "rail_mm": [11000, 12500]}},
            ["body", "generator", "calibration", "rail_mm"],
            "rails_mm",
        ),
    ],
)
def test_a_typo_in_a_campaign_names_the_field_that_was_meant(settings, body, loc, meant):
    with running_app(settings) as c:
        r = c.post("/api/campaigns", json=body, headers=AUTH)
        assert r.status_code == 422, r.text
        extra = [e for e in r.json()["detail"] if e["type"] == "extra_forbidden"]
        assert [e["loc"] for e in extra] == [loc], r.text
        assert extra[0]["msg"].endswith(f"did you mean '{meant}'?"), r.text
        assert c.get("/api/campaigns", headers=AUTH).json() == []  # nothing stored
