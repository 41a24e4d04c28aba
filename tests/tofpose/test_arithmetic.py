"""``PosePipeline(implementation="reference")``: every stage's arithmetic through
``tofpose.reference`` (``tofpose.arithmetic.REFERENCE``) instead of the kernels, against
the compiled pipeline on rendered frames (0.7-10 m, a few attitudes, clutter, a tracked
stream).

Agreement asserted: the same ok flags, reasons, modes and matched catalog ids (as sets:
the two halves of a split pair may come in either order, the split's axis sign being
LAPACK's in one and the kernel's in the other); poses equal to ``POSE_SIGMAS`` of their
reported covariance (the whitened 6-vector of the rotation vector and translation
difference: the reference's ML fit is SciPy's ``least_squares``, equal to the kernels'
Gauss-Newton only to its tolerance: measured up to ~2e-2 sigma at 8 m, ~2e-3 at 1.5 m);
covariances to ``COVARIANCE_REL`` of their largest entry (measured up to ~8e-4, at 8 m,
where the covariance follows the pose). And the switch itself: "compiled" by default,
an unknown name refused, and the reference pipeline never calling a kernel outside what
``tofpose.arithmetic`` names as not covered.
"""

from __future__ import annotations

import dataclasses
import sys

import numba
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tests.conftest import facing_pose, render
from tofpose import arithmetic
from tofpose.arithmetic import COMPILED, REFERENCE
from tofpose.config import PipelineConfig, TrackingConfig
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.pipeline import PosePipeline
from tofpose.sim.scene import Clutter, TargetScene

pytestmark = pytest.mark.unit

CAM = CameraModel()
#: the poses' largest whitened difference, in sigmas (measured 3e-4 at most: the two ML
#: optimisers' tolerances; 2e-2 before the kernel's range-offset Jacobian took the
#: lateral sigmas' dependence on the offset into account)
POSE_SIGMAS = 3e-3
#: the covariances' largest difference over their largest entry (measured 3e-6)
COVARIANCE_REL = 5e-5

#: (distance mm, pitch, yaw, roll deg, offset mm): 0.7 m sees part of the target (4
#: markers); 5.7 m merges markers 7 and 8 (split there)
FRAMES = [
    (700.0, 0.0, 0.0, 0.0, (-100.0, -50.0)),
    (700.0, 3.0, -5.0, 8.0, (-200.0, -100.0)),
    (1500.0, 5.0, -8.0, 20.0, (0.0, 0.0)),
    (3000.0, -6.0, 4.0, -35.0, (0.0, 0.0)),
    (5700.0, 5.0, -8.0, 20.0, (0.0, 0.0)),
    (5700.0, 0.0, 0.0, 0.0, (0.0, 0.0)),
    (8000.0, 3.0, 10.0, 60.0, (0.0, 0.0)),
    (10000.0, -4.0, -3.0, 5.0, (0.0, 0.0)),
]


def both(config=None):
    cat = paper_target()
    return (
        PosePipeline(CAM, cat, config),
        PosePipeline(CAM, cat, config, implementation="reference"),
    )


def assert_agree(a, b):
    """``a`` compiled, ``b`` reference results of one frame agree (module docstring)."""
    assert (a.ok, a.reason, a.mode) == (b.ok, b.reason, b.mode)
    assert sorted(m.catalog_id for m in a.matched) == sorted(m.catalog_id for m in b.matched)
    if not a.ok:
        return
    d = np.concatenate((Rotation.from_matrix(b.R @ a.R.T).as_rotvec(), b.t_mm - a.t_mm))
    assert np.sqrt(d @ np.linalg.solve(a.covariance, d)) < POSE_SIGMAS
    scale = np.abs(a.covariance).max()
    np.testing.assert_allclose(b.covariance, a.covariance, rtol=0, atol=COVARIANCE_REL * scale)


@pytest.mark.parametrize(("distance_mm", "pitch", "yaw", "roll", "offset_mm"), FRAMES)
def test_the_reference_pipeline_agrees_with_the_compiled_one(
    distance_mm, pitch, yaw, roll, offset_mm
):
    frame = render(facing_pose(distance_mm, pitch, yaw, roll, offset_mm), seed=3)
    a, b = (p.process(frame.gray, frame.distance_mm) for p in both())
    assert a.ok
    assert_agree(a, b)


def test_they_agree_on_a_frame_with_clutter():
    clutter = (Clutter((-380.0, 250.0, 60.0), 60.0, 1.0), Clutter((420.0, -200.0, 0.0), 45.0))
    scene = TargetScene(paper_target(), clutter=clutter)
    frame = render(facing_pose(2500.0, 4.0, -6.0, 12.0), seed=5, scene=scene)
    a, b = (p.process(frame.gray, frame.distance_mm) for p in both())
    assert a.ok and len(a.unmatched) >= 1
    assert_agree(a, b)


def test_they_agree_on_a_tracked_stream():
    """A stream moving 4 mm per frame: acquisition, then tracking frames (the reference's
    ``stages.tracking.reference.tracking_frame.track_frame``) with persistence building up."""
    a_pipe, b_pipe = both(PipelineConfig(tracking=TrackingConfig(enabled=True)))
    modes = []
    for f in range(6):
        frame = render(facing_pose(3000.0 + 4.0 * f, 2.0, -3.0, 10.0), seed=20 + f)
        a, b = (
            a_pipe.process(frame.gray, frame.distance_mm),
            b_pipe.process(frame.gray, frame.distance_mm),
        )
        assert_agree(a, b)
        assert a.frames_used == b.frames_used
        modes.append(a.mode)
    assert modes.count("tracking") >= 4


def test_compiled_is_the_default_and_an_unknown_name_is_refused():
    pipe = PosePipeline(CAM, paper_target())
    assert pipe.implementation == "compiled" and pipe.arithmetic is COMPILED
    assert PosePipeline(CAM, paper_target(), implementation="reference").arithmetic is REFERENCE
    with pytest.raises(ValueError, match=r"'numpy'.*'compiled', 'reference'"):
        PosePipeline(CAM, paper_target(), implementation="numpy")


#: kernels the reference path still runs (``tofpose.arithmetic``'s docstring)
NOT_COVERED = {"checked_frame", "clean_distance", "pixel_mask"}


def test_the_reference_pipeline_calls_no_kernel(monkeypatch):
    """Every compiled kernel the library's modules hold, and every field of ``COMPILED``,
    raises; the reference pipeline still tracks and splits markers 7 and 8 at 5.7 m."""
    pipe = PosePipeline(
        CAM,
        paper_target(),
        PipelineConfig(tracking=TrackingConfig(enabled=True)),
        implementation="reference",
    )
    frames = [render(facing_pose(5700.0 + 3.0 * f, 5.0, -8.0, 20.0), seed=40 + f) for f in range(3)]

    def raiser(name):
        def call(*args, **kwargs):
            raise AssertionError(f"the reference pipeline called the kernel {name}")

        return call

    for mod_name, mod in list(sys.modules.items()):
        if not mod_name.startswith("tofpose.") or ".kernels." in mod_name:
            continue
        for name, value in list(vars(mod).items()):
            if isinstance(value, numba.core.registry.CPUDispatcher) and name not in NOT_COVERED:
                monkeypatch.setattr(mod, name, raiser(f"{mod_name}.{name}"))
    # every stage's compiled functions, restored below
    stages = [getattr(COMPILED, f.name) for f in dataclasses.fields(COMPILED) if f.name != "name"]
    saved = [
        (stage, f.name, getattr(stage, f.name))
        for stage in stages
        for f in dataclasses.fields(stage)
        if f.name != "name"
    ]
    assert len(saved) >= 25  # every field of every stage (28 now): not an empty table
    try:
        for stage, field, _ in saved:
            object.__setattr__(stage, field, raiser(f"COMPILED.{field}"))
        for frame in frames:
            r = pipe.process(frame.gray, frame.distance_mm)
            assert r.ok, r.reason
        assert r.mode == "tracking"
    finally:
        for stage, field, value in saved:
            object.__setattr__(stage, field, value)
    assert arithmetic.COMPILED.pose.solve_pairs is not None
