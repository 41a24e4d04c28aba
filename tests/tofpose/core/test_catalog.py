import json

import numpy as np
import pytest

from tofpose.core.catalog import Catalog, Reflector, load_catalog, paper_target


def test_paper_target_matches_design_table():
    cat = paper_target()
    assert list(cat.ids) == [1, 2, 3, 4, 5, 6, 7, 8]
    np.testing.assert_array_equal(cat.diameters_mm, [35] * 4 + [80] * 4)
    heights = dict(zip(cat.ids, cat.positions_mm[:, 2], strict=True))
    assert [heights[i] for i in (1, 3, 4, 7)] == [100] * 4
    assert [heights[i] for i in (2, 5, 6, 8)] == [150] * 4
    assert cat.pairwise_distances_mm()[0, 1] == pytest.approx(np.hypot(120, 50))


def test_json_round_trip():
    cat = paper_target()
    again = Catalog.from_json(cat.to_json())
    assert again == cat
    assert load_catalog("paper-target") == cat


def _refl(i, x, y=0.0, d=10.0):
    return Reflector(i, (x, y, 0.0), d)


@pytest.mark.parametrize(
    ("reflectors", "message"),
    [
        ((_refl(1, 0), _refl(1, 10, 5), _refl(2, 0, 9)), "duplicate reflector ids: \\[1\\]"),
        ((_refl(1, 0), _refl(2, 10, 5), _refl(3, 0, 9, -1)), "diameter_mm must be positive"),
        ((_refl(1, 0), _refl(2, 10)), "at least 3"),
        ((_refl(1, 0), _refl(2, 10), _refl(3, 20)), "collinear"),
        ((_refl(1, 0), _refl(2, 1000), _refl(3, 2000, 1e-3)), "collinear.*below 0.0001"),
        ((_refl(1, 5), _refl(2, 5), _refl(3, 5)), "collinear"),
    ],
)
def test_validation_errors(reflectors, message):
    with pytest.raises(ValueError, match=message):
        Catalog("bad", reflectors)


def test_malformed_json_names_the_reflector():
    d = paper_target().to_dict()
    del d["reflectors"][2]["diameter_mm"]
    with pytest.raises(ValueError, match="reflector #2 is malformed"):
        Catalog.from_json(json.dumps(d))
    with pytest.raises(ValueError, match="not valid JSON"):
        Catalog.from_json("[1,")


@pytest.mark.parametrize("scale_mm", [1.0, 1e-3, 1e4])
def test_collinearity_test_is_scale_free(scale_mm):
    """A right triangle is a usable catalog at any size (1 mm was once rejected)."""
    cat = Catalog("tri", (_refl(1, 0), _refl(2, scale_mm), _refl(3, 0, scale_mm)))
    assert len(cat.reflectors) == 3
