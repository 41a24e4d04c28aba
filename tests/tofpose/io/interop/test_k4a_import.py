"""``tofpose import k4a`` on a real Azure Kinect recording that no one here wrote: the one
pyk4a ships with its tests (data/k4a/NOTICE.md). Its truths come from the file and from
pyk4a's own tests of it: the factory calibration (pyk4a's ``RECORD_CALIBRATION_JSON``),
the capture's device timestamp (800222 us), the IR and depth bytes of its one capture
(read here as raw big-endian blocks, not through the importer's decoder)."""

from __future__ import annotations

import csv
from pathlib import Path

import av
import cv2
import numpy as np
import pytest
from numpy.testing import assert_allclose

from tofpose.cli import main
from tofpose.core.catalog import paper_target
from tofpose.io.interop.k4a_import import K4aImportError, import_k4a
from tofpose.io.recording import open_recording
from tofpose.pipeline import PosePipeline
from tofpose.stages.extraction.reference.extraction import saturated_fraction

MKV = Path(__file__).parent / "data" / "k4a" / "recording.mkv"
W, H = 640, 576
#: the depth camera's ModelParameters in the file (pyk4a's RECORD_CALIBRATION_JSON):
#: cx, cy, fx, fy normalised by the 1024 x 1024 sensor, k1..k6, codx, cody, p2, p1
PARAMS = [
    0.51296979188919067,
    0.51692354679107666,
    0.4927808940410614,
    0.49290284514427185,
    0.54793977737426758,
    -0.020971370860934258,
    -0.0026522316038608551,
    0.88967907428741455,
    0.086130209267139435,
    -0.013910384848713875,
    0,
    0,
    -7.2104157879948616e-5,
    2.0557534298859537e-5,
]


def raw_blocks() -> dict[str, np.ndarray]:
    """The DEPTH and IR blocks of the file's capture as 16-bit big-endian (H, W) arrays."""
    out = {}
    with av.open(str(MKV)) as c:
        streams = [s for s in c.streams.video if s.metadata.get("title") in ("DEPTH", "IR")]
        for packet in c.demux(*streams):
            if packet.size:
                out[packet.stream.metadata["title"]] = np.frombuffer(bytes(packet), ">u2").reshape(
                    H, W
                )
    return out


@pytest.fixture(scope="module")
def imported(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("k4a") / "k4a.h5"
    assert main(["import", "k4a", str(MKV), "--out", str(out)]) == 0
    return out


def test_camera_is_the_files_factory_calibration(imported):
    # the SDK's NFOV-unbinned window of the 1024 x 1024 sensor: crop (192, 180), and
    # -0.5 from the pixel corner to its centre
    cx, cy, fx, fy = PARAMS[:4]
    with open_recording(imported) as rec:
        cam = rec.camera
    assert (cam.width, cam.height) == (W, H)
    assert_allclose(
        [cam.fx, cam.fy, cam.cx, cam.cy],
        [fx * 1024, fy * 1024, cx * 1024 - 192.5, cy * 1024 - 180.5],
        rtol=1e-12,
    )
    assert cam.full_scale_counts == 65535.0
    assert cam.distance_kind == "radial"  # stored converted
    assert cam.name == "Azure Kinect 001514394512 NFOV_UNBINNED"  # the file's device


def test_lens_follows_the_rational_model_over_the_depth_field(imported):
    """The five stored coefficients put rays where OpenCV's rational model with the
    file's eight does (the SDK's Brown-Conrady), within 0.25 px over the 75 x 65 deg
    field that lands in the image."""
    with open_recording(imported) as rec:
        cam = rec.camera
    k1, k2, k3, k4, k5, k6, _, _, p2, p1 = PARAMS[4:]
    dist8 = np.array([k1, k2, p1, p2, k3, k4, k5, k6])
    t = np.linspace(-0.8, 0.8, 41)
    x, y = np.meshgrid(t, t)
    rays = np.column_stack((x.ravel(), y.ravel(), np.ones(x.size)))
    rays = rays[np.hypot(rays[:, 0], rays[:, 1]) <= 0.99]
    truth = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), cam.K, dist8)[0].reshape(-1, 2)
    inside = (truth[:, 0] > 0) & (truth[:, 0] < W - 1) & (truth[:, 1] > 0) & (truth[:, 1] < H - 1)
    assert inside.sum() > 1000
    err = np.hypot(*(cam.project(rays[inside]) - truth[inside]).T)
    assert err.max() < 0.25


def test_frame_keeps_the_captures_pixels_and_device_time(imported):
    blocks = raw_blocks()
    with open_recording(imported) as rec:
        assert rec.n_frames == 1
        gray, distance, time_s = rec.frame(0)
        cam = rec.camera
    assert time_s == pytest.approx(0.800222, abs=1e-9)  # pyk4a: depth_timestamp_usec 800222
    np.testing.assert_array_equal(gray, blocks["IR"])
    z = blocks["DEPTH"].astype(float)
    np.testing.assert_array_equal(np.isnan(distance), z == 0)
    # each valid pixel's point, back-projected at the radial distance, has the file's z
    v, u = np.nonzero(z > 0)
    pick = np.random.default_rng(0).choice(len(u), 2000, replace=False)
    uv = np.column_stack((u[pick], v[pick])).astype(float)
    points = cam.back_project(uv, distance[v[pick], u[pick]])
    assert_allclose(points[:, 2], z[v[pick], u[pick]], rtol=1e-6)


def test_saturated_ir_pixels_read_as_saturated(imported):
    blocks = raw_blocks()
    n_saturated = int((blocks["IR"] == 65535).sum())
    assert n_saturated == 9809  # the file's own
    with open_recording(imported) as rec:
        gray, distance, _ = rec.frame(0)
        full_scale = rec.camera.full_scale_counts
    fraction = saturated_fraction(gray, saturated_counts=full_scale)
    assert fraction == pytest.approx(n_saturated / (W * H))
    assert np.isnan(distance[gray >= full_scale]).mean() > 0.9  # no distance behind them


def test_estimate_says_no_target(imported, tmp_path):
    """The scene has no reflector target: a clear failure, never a pose."""
    catalog = tmp_path / "target.json"
    catalog.write_text(paper_target().to_json())
    csv_path = tmp_path / "poses.csv"
    args = ["estimate", str(imported), "--out", str(csv_path), "--catalog", str(catalog)]
    assert main(args) == 0
    (row,) = list(csv.DictReader(csv_path.open()))
    assert row["ok"] == "0" and row["x_mm"] == "" and row["n_matched"] == "0"
    with open_recording(imported) as rec:
        r = PosePipeline(rec.camera, paper_target()).process(*rec.frame(0))
    assert not r.ok and r.R is None and r.t_mm is None
    assert "need 3" in r.reason


@pytest.mark.parametrize(
    ("make", "names"),
    [
        (lambda p: p.write_bytes(MKV.read_bytes()[: MKV.stat().st_size // 2]), "truncated"),
        (lambda p: p.write_bytes(MKV.read_bytes()[:-10_000]), "truncated"),
        (lambda p: p.write_text("not a video"), "not a readable Matroska file"),
    ],
    ids=["half", "last-block-cut", "text"],
)
def test_bad_file_is_named(tmp_path, make, names):
    bad = tmp_path / "bad.mkv"
    make(bad)
    out = tmp_path / "out.h5"
    with pytest.raises(K4aImportError, match=names) as info:
        import_k4a(bad, out, progress=False)
    assert str(bad) in str(info.value)
    assert not out.exists() and not out.with_name("out.h5.partial").exists()


def test_existing_output_is_kept(tmp_path):
    out = tmp_path / "out.h5"
    out.write_text("mine")
    with pytest.raises(K4aImportError, match="exists"):
        import_k4a(MKV, out, progress=False)
    assert out.read_text() == "mine"


def test_options_of_another_format_are_refused(tmp_path, capsys):
    out = tmp_path / "out.h5"
    assert main(["import", "k4a", str(MKV), "--out", str(out), "--depth", "/d"]) == 2
    assert "import k4a does not take --depth" in capsys.readouterr().err
    assert not out.exists()
