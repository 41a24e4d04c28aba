"""The physics robustness study (``bench/physics.py``): a short run judges every cell (its
draws: tests/tofpose/sim/test_randomise.py)."""

from __future__ import annotations

import pytest

from bench import physics
from tofpose.sim.randomise import ALL_FAMILIES


def test_a_short_run_judges_every_cell_and_reports_it(tmp_path):
    out = physics.run(1)
    assert set(out) == {(f, r) for f in ALL_FAMILIES for r in physics.RANGES_M}
    for summary, _ in out.values():
        assert summary["frames"] == 1
        assert summary["success_pct"] in (0.0, 100.0)
    # the ideal sensor at 3 m is the easy cell: its one frame succeeds, on either camera
    assert out[("ideal", 3.0)][0]["success_pct"] == 100.0
    assert out[("other sensor", 3.0)][0]["success_pct"] == 100.0
    text = physics.markdown(out, "physics.png", 1)
    assert text.count("\n|") == 2 + len(out)  # header, rule and one row per cell
    assert "physics-examples.png" in text  # the picture of each family's frames
    physics.plot(out, tmp_path / "physics.png")
    assert (tmp_path / "physics.png").stat().st_size > 10_000
    assert (tmp_path / "physics-examples.png").stat().st_size > 10_000


def test_the_command_line_runs_the_named_families_only(tmp_path, capsys):
    physics.main(["--frames", "1", "--out", str(tmp_path), "--families", "other sensor", "gains"])
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| ")]
    # header, then four ranges per family in the study's order
    assert [r.split("|")[1].strip() for r in rows[1:]] == ["gains"] * 4 + ["other sensor"] * 4
    assert (tmp_path / "physics-examples.png").exists()
    with pytest.raises(SystemExit):
        physics.main(["--families", "fog"])


def test_the_pixel_fit_comparison_measures_both_modes_on_the_same_frames():
    """``compare_pixel_fit`` runs every family's frames through the default pipeline and
    the pixel fit: the same frames (counts equal per family), the fit holding on some ok
    poses of the ideal family (sharp, no background), and a table row per family and
    mode."""
    cmp = physics.compare_pixel_fit(1)
    assert set(cmp) == set(ALL_FAMILIES)
    for base, pixel, held, ok in cmp.values():
        assert len(base) == len(pixel) == len(physics.RANGES_M)
        assert 0 <= held <= ok <= len(pixel)
    base, pixel, held, ok = cmp["ideal"]
    assert ok == len(physics.RANGES_M) and held >= 1
    # the frames are the same: the centroid poses' range is the pixel-fit frames' range
    assert [o.range_mm for o in base] == [o.range_mm for o in pixel]
    text = physics.pixel_fit_markdown(cmp, 1)
    assert text.count("\n|") == 2 + 2 * len(ALL_FAMILIES)
