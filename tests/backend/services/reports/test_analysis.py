"""Campaign statistics recover a known truth; singular points; findings' conditions."""

from __future__ import annotations

import numpy as np
import pytest

from backend.services.reports.analysis import AXES, analyse, axis_stats, findings, keep_mask

REQ = {"x_mm": 6.0, "y_mm": 6.0, "z_mm": 28.3, "pitch_deg": 0.15, "yaw_deg": 0.15, "roll_deg": 0.15}


def test_stats_recover_a_known_bias_and_spread():
    rng = np.random.default_rng(3)
    truth = np.full(20000, 1000.0)
    measured = truth + 2.0 + rng.normal(0, 0.5, truth.size)
    st = axis_stats(measured, truth, np.full(truth.size, 0.5), requirement=6.0)
    assert st.bias == pytest.approx(2.0, abs=0.02)
    assert st.std == pytest.approx(0.5, rel=0.03)
    assert st.rms == pytest.approx(np.hypot(2.0, 0.5), rel=0.02)
    assert st.sigma_ratio == pytest.approx(1.0, rel=0.03)
    assert st.fluctuation == pytest.approx(st.maximum - st.minimum)
    assert st.passed is True and st.n_removed < 5


def test_singular_points_are_removed_by_the_stated_rule():
    e = np.r_[np.random.default_rng(0).normal(0, 1.0, 200), 50.0, -40.0]
    keep = keep_mask(e)
    assert not keep[-1] and not keep[-2] and keep[:200].mean() > 0.99
    st = axis_stats(e, np.zeros_like(e), np.ones_like(e), requirement=10.0)
    assert st.n_removed >= 2 and st.max_abs < 10.0 and st.passed is True
    assert (
        axis_stats(e, np.zeros_like(e), np.ones_like(e), 10.0, remove_singular=False).passed
        is False
    )


def _rows(n_sp=2, n=30, offset=0.0, fail_every=0):
    rng = np.random.default_rng(1)
    rows = []
    for sp in range(n_sp):
        for k in range(n):
            r = {"setpoint_index": sp, "ok": 0 if fail_every and k % fail_every == 0 else 1}
            for a in AXES:
                ref = 100.0 * sp
                r["reference_" + a] = ref
                r["truth_" + a] = ref
                r[a] = ref + offset + rng.normal(0, 0.01)
                r["sigma_" + a] = 0.01
            rows.append(r)
    return rows


def test_findings_are_written_only_when_their_condition_holds():
    good = analyse(_rows(), REQ)
    assert good["overall"]["passed"] is True
    f = findings(good)
    assert f[0].startswith("All 2 set-points meet every requirement")
    assert not any("exceed" in s or "gave no pose" in s for s in f)
    bad = analyse(_rows(offset=0.2, fail_every=5), REQ)
    f = findings(bad)
    assert bad["overall"]["passed"] is False
    assert any(s.startswith("pitch_deg: 2 of 2 set-points exceed") for s in f)
    assert any("systematic offset" in s for s in f)
    assert any("12 of 60 frames gave no pose" in s for s in f)
    assert not any(s.startswith("All ") for s in f)


def test_a_campaign_measured_with_the_pixel_fit_says_which_poses_are_its():
    """Rows say which pose they hold (``pixel_fit``): none says nothing (the fit did not
    run, or an older CSV without the column); all fitted says so; a mix says how many
    fell back and that the statistics pool both."""
    assert not any("pixel-level fit" in s for s in findings(analyse(_rows(), REQ)))
    all_fit = _rows()
    for r in all_fit:
        r["pixel_fit"] = "ok"
    res = analyse(all_fit, REQ)
    assert (res["n_pixel_fit_tried"], res["n_pixel_fit"]) == (60, 60)
    assert "60 of the 60 poses are the pixel-level fit's." in findings(res)
    mixed = _rows(fail_every=6)
    for k, r in enumerate(mixed):
        if k % 6 == 1:  # an ok frame on which the fit fell back
            r["pixel_fit"] = "markers [7] have clipped cores"
        elif k % 6 in (2, 3, 4):
            r["pixel_fit"] = "ok"
        elif k % 6 == 0:
            r["pixel_fit"] = "ok"  # a frame without a pose does not count
    res = analyse(mixed, REQ)
    assert (res["n_ok"], res["n_pixel_fit_tried"], res["n_pixel_fit"]) == (50, 40, 30)
    [line] = [s for s in findings(res) if "pixel-level fit" in s]
    assert line == (
        "30 of the 50 poses are the pixel-level fit's; on 10 it fell back to the centroid "
        "pose, and the statistics pool both; 10 were measured without it."
    )
