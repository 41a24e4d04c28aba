"""The reference statement of the merged pair's model fit
(``tofpose.stages.ellipses.reference.pair_fit``)
against the compiled one (``tofpose.stages.ellipses.kernels.pair_fit``) on random and rendered pairs
(markers 7 and 8 at 5-8 m, with and without lens distortion), and against known truth
(drawn discs; the rendered markers' projected centres).

Equality: ``half_erfc`` to 7.5e-8 (the kernel's Abramowitz & Stegun 7.1.26 against
SciPy's erfc); the model's residuals to (a1 + a2) 7.5e-8 and its Jacobian to the larger
of 7.5e-8 and the kernel's flat tails (sub-samples beyond |z| = 4.5 left out: at most
(a1 + a2) exp(-4.5^2) 6.4 / (sqrt(2 pi) s));
the normal equations to 1e-12 relative. ``fit_pair_lm``: SciPy's least_squares replaces
the kernel's Levenberg-Marquardt, so the fits agree to the optimiser's tolerance: centres
within 1e-3 px on drawn pairs (the kernel stops once a step moves no centre by 1e-4 px)
and 5e-3 px on rendered ones (where the blur runs into its bound the kernel's centre test
stops it a little short: its cost is then the higher)."""

from __future__ import annotations

import math
from functools import cache

import cv2
import numpy as np
import pytest
from scipy.optimize import approx_fprime

from tests.conftest import facing_pose, render
from tests.tofpose.stages.ellipses.test_pair_split import BACKGROUND, _component, _discs
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.stages.ellipses.kernels import pair_fit as kernel
from tofpose.stages.ellipses.pair_fit import (
    CENTRE_TOLERANCE_PX,
    COST_TOLERANCE,
    MAX_EVALUATIONS,
    _problem,
)
from tofpose.stages.ellipses.reference import pair_fit as reference

DISTORTED = CameraModel(dist=(-0.02, 0.008, 0.0004, -0.0003, 0.0))
SETTINGS = (MAX_EVALUATIONS, CENTRE_TOLERANCE_PX, COST_TOLERANCE)


@cache
def _rendered_pair(distance_mm, distorted, seed=1):
    """The fit problem (su, sv, values, start, lower, upper) of markers 7 and 8 rendered
    at ``distance_mm`` (the pixels of the components holding them above a quarter of the
    peak, one component from ~6.5 m on), started 0.3 px off their projected centres;
    and those centres (2, 2)."""
    cam = DISTORTED if distorted else CameraModel()
    T = facing_pose(distance_mm, 3, -5, 12)
    gray = render(T, seed=seed, camera=cam).gray
    truth = cam.project(T.apply(paper_target().positions_mm))[6:8]
    level = float(np.median(gray))
    _, labels, _, _ = cv2.connectedComponentsWithStats(
        (gray >= level + 0.25 * (gray.max() - level)).astype(np.uint8), connectivity=8
    )
    ours = [labels[int(round(v)), int(round(u))] for u, v in truth]
    pixels = np.flatnonzero(np.isin(labels, ours))
    start = truth + np.random.default_rng(seed).uniform(-0.3, 0.3, (2, 2))
    return _problem(gray, pixels, start, level), truth


def _random_model_point(rng, n=40):
    su, sv = rng.uniform(10, 20, (n, 9)), rng.uniform(9, 14, (n, 9))
    p = np.array(
        [
            *rng.uniform(11, 19, 4),
            *rng.uniform(500, 2500, 2),
            rng.uniform(1.2, 3.0),
            rng.uniform(0.2, 1.5),
            rng.uniform(0, 300),
        ]
    )
    return p, su, sv, rng.uniform(0, 2000, n)


def _assert_model_agrees(p, su, sv, values):
    want_jac, got_jac = np.empty((len(su), 9)), np.empty((len(su), 9))
    want = kernel.pair_model(p, su, sv, values, want_jac)
    got = reference.pair_model(p, su, sv, values, got_jac)
    assert np.abs(got - want).max() <= (p[4] + p[5]) * 7.5e-8 + 1e-9
    # the kernel's tails: a sub-sample beyond |z| = 4.5 adds at most a k(4.5) sqrt(2) 4.5
    tail = (p[4] + p[5]) * math.exp(-(4.5**2)) / (math.sqrt(2 * math.pi) * p[7]) * 6.4
    atol = max(tail, 7.5e-8) + 1e-12 * np.abs(want_jac).max()
    np.testing.assert_allclose(got_jac, want_jac, rtol=0, atol=atol)
    return got, got_jac


def test_the_edge_is_erfc_within_the_kernels_stated_error():
    z = np.linspace(-6.0, 6.0, 4001)
    want = np.array([kernel.half_erfc(x, math.exp(-x * x)) for x in z])
    assert np.abs(reference.half_erfc(z, np.exp(-z * z)) - want).max() <= 7.5e-8
    assert reference.half_erfc(0.0, 1.0) == 0.5
    assert reference.half_erfc(-3.0, None) + reference.half_erfc(3.0, None) == 1.0


def test_the_model_and_its_normal_equations_equal_the_kernel():
    rng = np.random.default_rng(3)
    for _ in range(200):
        p, su, sv, values = _random_model_point(rng)
        res, jac = _assert_model_agrees(p, su, sv, values)
        want = kernel._normal_equations(res, jac)
        got = reference._normal_equations(res, jac)
        for a, b in zip(got, want, strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * np.abs(b).max())


def test_the_jacobian_is_the_derivative_of_the_residuals():
    rng = np.random.default_rng(9)
    for _ in range(10):
        p, su, sv, values = _random_model_point(rng)
        jac = np.empty((len(su), 9))
        reference.pair_model(p, su, sv, values, jac)

        def residual(q, i, su=su, sv=sv, values=values):
            return reference.pair_model(q, su, sv, values, np.empty((len(su), 9)))[i]

        numeric = np.array([approx_fprime(p, residual, 1e-6, i) for i in range(len(su))])
        np.testing.assert_allclose(jac, numeric, rtol=0, atol=1e-4 * np.abs(numeric).max())


def _fits(problem):
    return (kernel.fit_pair_lm(*problem, *SETTINGS), reference.fit_pair_lm(*problem, *SETTINGS))


def test_the_fit_equals_the_kernel_and_finds_drawn_discs():
    """Twelve drawn pairs (separation 3.5-6 px, radius 1.6-2.6 px, blur 0.4-1.2 px, gains
    within 30 %, pixel noise of 15 counts): both fits converge, their centres agree
    within 1e-3 px and lie within 0.1 px of the drawn centres."""
    rng = np.random.default_rng(4)
    for _ in range(12):
        c1 = np.array([12.0, 11.0]) + rng.uniform(-0.5, 0.5, 2)
        angle, sep = rng.uniform(0, np.pi), rng.uniform(3.5, 6.0)
        centres = np.array([c1, c1 + sep * np.array([np.cos(angle), np.sin(angle)])])
        img = _discs(
            centres, rng.uniform(1.6, 2.6), (1.0, rng.uniform(0.7, 1.3)), rng.uniform(0.4, 1.2)
        )
        img += rng.normal(0.0, 15.0, img.shape).astype(np.float32)
        comp = _component(img, BACKGROUND + 0.25 * (img.max() - BACKGROUND))
        problem = _problem(img, comp.pixels, centres + rng.uniform(-0.3, 0.3, (2, 2)), BACKGROUND)
        (p_k, _, _, ok_k), (p_r, H, cost, ok_r) = _fits(problem)
        assert ok_k and ok_r
        np.testing.assert_allclose(p_r[:4], p_k[:4], atol=1e-3)
        np.testing.assert_allclose(p_r[:4].reshape(2, 2), centres, atol=0.1)
        res = reference.pair_model(p_r, *problem[:3], jac := np.empty((len(problem[2]), 9)))
        assert cost == pytest.approx(res @ res) and np.allclose(H, jac.T @ jac)


@pytest.mark.parametrize("distorted", [False, True])
@pytest.mark.parametrize("distance_mm", [5000.0, 6000.0, 7000.0, 8000.0])
def test_the_fit_equals_the_kernel_on_the_rendered_pair(distance_mm, distorted):
    """Markers 7 and 8 rendered at 5-8 m: both fits converge, their centres agree within
    5e-3 px, the reference's cost is not above the kernel's, and the centres are within
    0.1 px of the markers' projected centres."""
    problem, truth = _rendered_pair(distance_mm, distorted)
    (p_k, _, cost_k, ok_k), (p_r, _, cost_r, ok_r) = _fits(problem)
    assert ok_k and ok_r
    np.testing.assert_allclose(p_r[:4], p_k[:4], atol=5e-3)
    assert cost_r <= cost_k * (1 + 1e-9)
    np.testing.assert_allclose(p_r[:4].reshape(2, 2), truth, atol=0.1)
    _assert_model_agrees(p_r, *problem[:3])


def test_a_fit_out_of_evaluations_has_not_converged():
    problem, _ = _rendered_pair(7000.0, False)
    assert not reference.fit_pair_lm(*problem, 2, CENTRE_TOLERANCE_PX, COST_TOLERANCE)[3]
