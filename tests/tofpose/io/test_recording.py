import threading
from dataclasses import replace

import h5py
import numpy as np
import pytest

from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.io.read_ahead import THREAD_NAME
from tofpose.io.recording import RecordingError, RecordingWriter, open_recording


def _write(path, n=3, truth=True):
    cam = CameraModel()
    rng = np.random.default_rng(0)
    frames = []
    with RecordingWriter(path, cam, paper_target(), with_truth=truth) as w:
        for i in range(n):
            g = rng.integers(0, 4096, (240, 320)).astype(np.uint16)
            d = rng.uniform(300, 15000, (240, 320)).astype(np.float32)
            d[0, i] = np.nan
            frames.append((g, d))
            if truth:
                w.append(g, d, i * 0.1, np.eye(3), np.array([0, 0, 1000.0 + i]))
            else:
                w.append(g, d, i * 0.1)
    return frames


def test_round_trip(tmp_path):
    p = tmp_path / "r.h5"
    frames = _write(p)
    with open_recording(p) as rec:
        assert rec.n_frames == 3 and rec.camera == CameraModel() and rec.catalog == paper_target()
        for i, (g, d, t) in enumerate(rec.frames()):
            np.testing.assert_array_equal(g, frames[i][0])
            np.testing.assert_array_equal(d, frames[i][1])  # NaN preserved
            assert t == pytest.approx(0.1 * i)
        np.testing.assert_allclose(rec.truth_t_mm[:, 2], [1000, 1001, 1002])


def _filters(dset: h5py.Dataset) -> list[int]:
    """The HDF5 filter ids of ``dset``'s pipeline, in the order they run on writing."""
    plist = dset.id.get_create_plist()
    return [plist.get_filter(k)[0] for k in range(plist.get_nfilters())]


def test_images_are_stored_shuffled_and_deflated_with_filters_every_hdf5_library_has(tmp_path):
    """Byte shuffle then deflate level 1 (both built into HDF5: no plugin needed to read
    the file), one frame a chunk; a plain h5py read gives the frames back bit for bit,
    NaN included. ``compression=None`` stores them without filters."""
    p = tmp_path / "r.h5"
    frames = _write(p, n=3)
    with h5py.File(p) as f:
        for name in ("frames/gray", "frames/distance_mm"):
            ds = f[name]
            assert _filters(ds) == [h5py.h5z.FILTER_SHUFFLE, h5py.h5z.FILTER_DEFLATE]
            assert ds.compression_opts == 1 and ds.chunks == (1, 240, 320)
        for i, (g, d) in enumerate(frames):
            np.testing.assert_array_equal(f["frames/gray"][i], g)
            assert f["frames/distance_mm"][i].tobytes() == d.tobytes()
    plain = tmp_path / "plain.h5"
    with RecordingWriter(plain, CameraModel(), compression=None) as w:
        w.append(*frames[0], 0.0)
    with h5py.File(plain) as f:
        assert _filters(f["frames/gray"]) == [] == _filters(f["frames/distance_mm"])


@pytest.mark.parametrize("compression", ["lzf", "GZIP", "zstd", ""])
def test_an_unknown_compression_is_named_and_an_existing_recording_is_kept(tmp_path, compression):
    """A compression the writer does not offer is refused by name before the file is
    opened (it used to write the images uncompressed without a word), so a recording
    already at that path keeps its frames."""
    p = tmp_path / "r.h5"
    frames = _write(p, n=2)
    with pytest.raises(
        ValueError, match=f"compression must be one of 'gzip', None, got '{compression}'"
    ):
        RecordingWriter(p, CameraModel(), compression=compression)
    with open_recording(p) as rec:
        assert rec.n_frames == 2
        np.testing.assert_array_equal(rec.frame(1)[0], frames[1][0])


def test_missing_dataset_is_named(tmp_path):
    p = tmp_path / "r.h5"
    _write(p)
    with h5py.File(p, "a") as f:
        del f["frames/time_s"]
    with pytest.raises(RecordingError, match="missing dataset /frames/time_s"):
        open_recording(p)


def test_disagreeing_lengths(tmp_path):
    p = tmp_path / "r.h5"
    _write(p)
    with h5py.File(p, "a") as f:
        f["frames/time_s"].resize((2,))
    with pytest.raises(RecordingError, match="frame counts disagree"):
        open_recording(p)


def test_corrupt_and_foreign_files(tmp_path):
    bad = tmp_path / "bad.h5"
    bad.write_bytes(b"\x89HDF\r\n\x1a\n" + b"garbage" * 100)
    with pytest.raises(RecordingError, match="not a readable HDF5 file"):
        open_recording(bad)
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f.attrs["format"] = "something-else"
    with pytest.raises(RecordingError, match="not a tofpose recording"):
        open_recording(other)
    with pytest.raises(RecordingError, match="no such file"):
        open_recording(tmp_path / "missing.h5")


def test_truncated_file_is_a_clear_error(tmp_path):
    p = tmp_path / "r.h5"
    _write(p, n=4)
    data = p.read_bytes()
    p.write_bytes(data[: len(data) // 2])
    with pytest.raises(RecordingError), open_recording(p) as rec:
        for _ in rec.frames():
            pass


def test_the_reference_is_stored_beside_the_truth_under_its_own_name_and_checked(tmp_path):
    p = tmp_path / "r.h5"
    cam = CameraModel()
    g = np.zeros((240, 320), np.uint16)
    d = np.full((240, 320), 1000.0, np.float32)
    with RecordingWriter(p, cam, with_truth=True, with_reference=True) as w:
        with pytest.raises(ValueError, match="stores reference"):
            w.append(g, d, 0.0, np.eye(3), np.zeros(3))
        lab = {"lab_R_camera_target": np.eye(3), "lab_t_camera_target_mm": np.array([2, 0, 1e3])}
        w.append(g, d, 0.0, np.eye(3), np.array([0, 0, 1000.0]), **lab)
    with h5py.File(p) as f:
        assert sorted(k for k in f if k not in ("camera", "frames")) == ["reference", "truth"]
        assert "lab_truth" not in f
    with open_recording(p) as rec:
        np.testing.assert_allclose(rec.truth_t_mm, [[0, 0, 1000]])
        np.testing.assert_allclose(rec.reference_t_mm, [[2, 0, 1000]])
        np.testing.assert_allclose(rec.lab_truth_t_mm, rec.reference_t_mm)  # the older name
    with h5py.File(p, "a") as f:
        del f["reference/R_camera_target"]
    with pytest.raises(RecordingError, match="/reference needs both"):
        open_recording(p)


def _write_old_layout(path, t_truth_mm, t_reference_mm):
    """A recording as versions before the rename wrote it, by hand: the lab's reference
    under ``/lab_truth``. (N, 3) translations; identity rotations."""
    n = len(t_truth_mm)
    cam = CameraModel()
    with h5py.File(path, "w") as f:
        f.attrs["format"], f.attrs["version"] = "tofpose-recording", 1
        c = f.create_group("camera")
        for k in ("width", "height", "fx", "fy", "cx", "cy"):
            c.attrs[k] = getattr(cam, k)
        c.attrs["dist"] = np.asarray(cam.dist, float)
        c.attrs["name"] = cam.name
        fr = f.create_group("frames")
        fr.create_dataset(
            "gray", data=np.zeros((n, 240, 320), np.uint16), maxshape=(None, 240, 320)
        )
        fr.create_dataset(
            "distance_mm",
            data=np.full((n, 240, 320), 1000.0, np.float32),
            maxshape=(None, 240, 320),
        )
        fr.create_dataset("time_s", data=np.arange(n) * 0.1, maxshape=(None,))
        for group, t in (("truth", t_truth_mm), ("lab_truth", t_reference_mm)):
            g = f.create_group(group)
            g.create_dataset(
                "R_camera_target", data=np.tile(np.eye(3), (n, 1, 1)), maxshape=(None, 3, 3)
            )
            g.create_dataset("t_camera_target_mm", data=np.asarray(t, float), maxshape=(None, 3))


def test_a_recording_written_before_the_rename_reads_its_lab_truth_as_the_reference(tmp_path):
    p = tmp_path / "old.h5"
    _write_old_layout(p, [[0, 0, 1000.0], [0, 0, 1001.0]], [[3, 0, 1000.0], [3, 0, 1001.0]])
    with open_recording(p) as rec:
        np.testing.assert_allclose(rec.truth_t_mm[:, 0], [0, 0])
        np.testing.assert_allclose(rec.reference_t_mm, [[3, 0, 1000], [3, 0, 1001]])
        np.testing.assert_allclose(rec.reference_R, np.tile(np.eye(3), (2, 1, 1)))
    # appending to it grows the group it has, not a second one beside it
    w = RecordingWriter.reopen(p)
    g, d = np.zeros((240, 320), np.uint16), np.full((240, 320), 1000.0, np.float32)
    lab = {"lab_R_camera_target": np.eye(3), "lab_t_camera_target_mm": np.array([3, 0, 1002.0])}
    w.append(g, d, 0.2, np.eye(3), np.array([0, 0, 1002.0]), **lab)
    w.close()
    with h5py.File(p) as f:
        assert "reference" not in f and f["lab_truth/t_camera_target_mm"].shape == (3, 3)
    with open_recording(p) as rec:
        np.testing.assert_allclose(rec.reference_t_mm[:, 2], [1000, 1001, 1002])
    with h5py.File(p, "a") as f:
        del f["lab_truth/t_camera_target_mm"]
    with pytest.raises(RecordingError, match="/lab_truth needs both"):
        open_recording(p)


def test_a_recording_can_be_reopened_appended_and_truncated(tmp_path):
    p = tmp_path / "r.h5"
    frames = _write(p, n=3)
    w = RecordingWriter.reopen(p)
    assert w.n == 3
    g, d = frames[0]
    w.append(g, d, 9.0, np.eye(3), np.array([0, 0, 2000.0]))
    w.append(g, d, 9.1, np.eye(3), np.array([0, 0, 2001.0]))
    w.truncate(4)  # drop the last one (an aborted batch)
    with pytest.raises(ValueError, match="cannot truncate"):
        w.truncate(7)
    w.close()
    with open_recording(p) as rec:
        assert rec.n_frames == 4
        np.testing.assert_allclose(rec.time_s, [0.0, 0.1, 0.2, 9.0])
        np.testing.assert_allclose(rec.truth_t_mm[:, 2], [1000, 1001, 1002, 2000])
    (tmp_path / "x.h5").write_bytes(b"nope")
    with pytest.raises(RecordingError, match="cannot open for appending"):
        RecordingWriter.reopen(tmp_path / "x.h5")


def test_blocks_read_what_frames_read_in_aligned_reads(tmp_path):
    p = tmp_path / "r.h5"
    frames = _write(p, n=40)
    with open_recording(p) as rec:
        assert rec.frames_per_chunk == 1
        spans = []
        for first, (g, d, t) in rec.blocks(5, 40):
            spans.append((first, first + len(t)))
            for k in range(len(t)):
                np.testing.assert_array_equal(g[k], frames[first + k][0])
                np.testing.assert_array_equal(d[k], frames[first + k][1])
                assert t[k] == rec.time_s[first + k]
        # a ramp of reads (1, 2, 4, 8 frames), then reads end on multiples of 32 frames
        assert spans == [(5, 6), (6, 8), (8, 12), (12, 20), (20, 32), (32, 40)]
        with pytest.raises(IndexError, match="frames 30..41"):
            rec.block(30, 41)


def test_the_cameras_full_scale_and_modulation_are_stored_and_old_files_read_as_before(
    tmp_path,
):
    cam = CameraModel(full_scale_counts=16383.0, modulation_frequency_hz=12e6)
    path = tmp_path / "r.h5"
    with RecordingWriter(path, cam, paper_target()) as w:
        w.append(np.zeros(cam.shape, np.uint16), np.full(cam.shape, np.nan, np.float32), 0.0)
    with open_recording(path) as rec:
        assert rec.camera == cam
    with h5py.File(path, "r+") as f:  # a recording written before these attributes
        del f["camera"].attrs["full_scale_counts"]
        del f["camera"].attrs["modulation_frequency_hz"]
    with open_recording(path) as rec:
        assert (rec.camera.full_scale_counts, rec.camera.modulation_frequency_hz) == (
            4095.0,
            6.0e6,
        )


def test_a_z_depth_recording_reads_as_radial_distance(tmp_path):
    """A z-depth device's frames are stored as it gave them; frame() and block() return
    the radial distance through each pixel's ray (a plane at z = 1500 mm reads
    1500 / e_z), and the camera the reader hands out says so."""
    from tofpose.core.camera_profiles import load_profile

    cam = load_profile("azure-kinect-nfov")
    path = tmp_path / "k.h5"
    z = np.full(cam.shape, 1500.0, np.float32)
    z[0, 0] = np.nan
    with RecordingWriter(path, cam) as w:
        for i in range(3):
            w.append(np.zeros(cam.shape, np.uint16), z, 0.1 * i)
    with h5py.File(path, "r") as f:
        assert f["camera"].attrs["distance_kind"] == "z"
        np.testing.assert_array_equal(f["frames/distance_mm"][1], z)  # stored as given
        assert f["camera"].attrs["unwrapped_range_mm"] == 3860.0
    e_z = cam.pixel_bearings()[:, :, 2]
    with open_recording(path) as rec:
        assert rec.stored_distance_kind == "z"
        assert rec.camera.distance_kind == "radial"
        assert rec.camera == replace(cam, distance_kind="radial")
        _, d, _ = rec.frame(1)
        assert np.isnan(d[0, 0])
        np.testing.assert_allclose(d[1:], (1500.0 / e_z)[1:], rtol=1e-6)
        assert d[0, 1] > 1500.0 * 1.4  # the corner's ray is 45 deg off axis
        _, block, _ = rec.block(0, 3)
        np.testing.assert_array_equal(block[2], d)
    # a recording of the camera the reader hands out stores radial: no second conversion
    copy = tmp_path / "copy.h5"
    with open_recording(path) as rec, RecordingWriter(copy, rec.camera) as w:
        g, d, t = rec.frame(0)
        w.append(g, d, t)
    with open_recording(copy) as rec2:
        assert rec2.stored_distance_kind == "radial"
        np.testing.assert_array_equal(rec2.frame(0)[1], d)


def test_a_recording_without_the_device_attributes_reads_as_the_epc660s(tmp_path):
    p = tmp_path / "r.h5"
    frames = _write(p, n=1, truth=False)
    with h5py.File(p, "r+") as f:  # a recording written before these attributes
        for k in (
            "count_scale",
            "distance_kind",
            "depth_unit_mm",
            "depth_invalid_code",
            "depth_max_valid_code",
        ):
            del f["camera"].attrs[k]
    with open_recording(p) as rec:
        assert rec.camera == CameraModel()
        assert rec.stored_distance_kind == "radial"
        np.testing.assert_array_equal(rec.frame(0)[1], frames[0][1])


def test_a_recordings_wall_clock_is_read_when_every_frame_has_one(tmp_path):
    """``/frames/wall_time_ns`` (the server's recordings) is the message time of an
    export; a file without it, or with a gap or a step back in it, has none."""
    stamps = {
        "ok": [1_765_000_000_000_000_000 + k * 100_000_000 for k in range(3)],
        "zero": [1_765_000_000_000_000_000, 0, 1_765_000_000_200_000_000],
        "back": [1_765_000_000_200_000_000, 1_765_000_000_100_000_000, 1_765_000_000_300_000_000],
    }
    for name, ns in stamps.items():
        path = tmp_path / f"{name}.h5"
        _write(path)
        with h5py.File(path, "a") as f:
            f["frames/wall_time_ns"] = np.array(ns, np.int64)
        with open_recording(path) as rec:
            if name == "ok":
                np.testing.assert_array_equal(rec.wall_time_ns, ns)
            else:
                assert rec.wall_time_ns is None
    _write(tmp_path / "none.h5")
    with open_recording(tmp_path / "none.h5") as rec:
        assert rec.wall_time_ns is None


def _write_many(path, n):
    """A recording of ``n`` frames cheap to compress (a ramp plus the frame's index; in
    frame i's distance image a NaN with payload i at row i % 240, column 3) with a time
    of 0.1 s a frame: its (gray, distance)."""
    ramp = np.arange(240 * 320).reshape(240, 320)
    frames = []
    with RecordingWriter(path, CameraModel()) as w:
        for i in range(n):
            g = ((ramp + i) % 4096).astype(np.uint16)
            d = (300.0 + ramp / 7.0 + i).astype(np.float32)
            d.view(np.uint32)[i % 240, 3] = 0x7FC0_0000 + i
            frames.append((g, d))
            w.append(g, d, 0.1 * i)
    return frames


LAYOUTS = {
    "the writer's (shuffle, deflate)": {},
    "deflate alone": {"compression": "gzip", "compression_opts": 4},
    "contiguous": {"chunks": None},
    "several frames a chunk, tiled": {"chunks": (6, 30, 40), "compression": "gzip"},
    "lzf": {"compression": "lzf", "shuffle": True},
}


def _restore(path, frames, layout):
    """Store ``frames``' images again in another HDF5 layout (``create_dataset``
    options), as files written by other tools are."""
    if not layout:
        return
    layout = {"chunks": (1, 240, 320), **layout}
    with h5py.File(path, "a") as f:
        for k, name in enumerate(("gray", "distance_mm")):
            del f[f"frames/{name}"]
            data = np.stack([fr[k] for fr in frames])
            f["frames"].create_dataset(name, data=data, **layout)


@pytest.mark.parametrize("layout", LAYOUTS.values(), ids=list(LAYOUTS))
@pytest.mark.parametrize("read_ahead", [True, False])
def test_blocks_are_bit_identical_to_a_plain_h5py_read_in_every_layout(
    tmp_path, layout, read_ahead
):
    """Whatever the chunking and filters, ``blocks`` (read ahead in a thread or not)
    gives what h5py reads, NaN payloads and all, in the spans ``block_spans`` says."""
    p = tmp_path / "r.h5"
    frames = _write_many(p, 45)
    _restore(p, frames, layout)
    with h5py.File(p) as f:
        gray, dist = f["frames/gray"][...], f["frames/distance_mm"][...]
    with open_recording(p) as rec:
        got = list(rec.blocks(2, 45, read_ahead=read_ahead))
        assert [(a, a + len(t)) for a, (_, _, t) in got] == rec.block_spans(2, 45)
        assert not rec.reading_ahead
    g = np.concatenate([b[0] for _, b in got])
    d = np.concatenate([b[1] for _, b in got])
    assert g.dtype == np.uint16 and d.dtype == np.float32
    assert g.tobytes() == gray[2:].tobytes() and d.tobytes() == dist[2:].tobytes()
    assert np.isnan(d[5, 7, 3]) and d[5].view(np.uint32)[7, 3] == 0x7FC0_0007  # frame 7's


def test_block_spans_follow_the_files_chunks(tmp_path):
    p = tmp_path / "r.h5"
    frames = _write_many(p, 45)
    with open_recording(p) as rec:
        # one frame, then twice as many each read up to 32 frames, then on 32-frame edges
        assert rec.block_spans(5, 45) == [(5, 6), (6, 8), (8, 12), (12, 20), (20, 32), (32, 45)]
        assert rec.block_spans(0, 45) == [(0, 1), (1, 3), (3, 7), (7, 15), (15, 32), (32, 45)]
    _restore(p, frames, LAYOUTS["several frames a chunk, tiled"])
    with open_recording(p) as rec:  # 6 frames a chunk: reads of 36 frames, on chunk edges
        assert rec.frames_per_chunk == 6
        assert rec.block_spans(5, 45) == [(5, 6), (6, 18), (18, 36), (36, 45)]


def _reader_threads():
    return [t for t in threading.enumerate() if t.name.startswith(THREAD_NAME)]


def test_a_z_depth_recording_read_ahead_is_converted_to_radial_as_frame_converts_it(tmp_path):
    from tofpose.core.camera_profiles import load_profile

    cam = load_profile("azure-kinect-nfov")
    path = tmp_path / "k.h5"
    with RecordingWriter(path, cam) as w:
        for i in range(40):
            w.append(np.zeros(cam.shape, np.uint16), np.full(cam.shape, 1000.0 + i, np.float32), i)
    with open_recording(path) as rec:
        for first, (_, d, _) in rec.blocks(read_ahead=True):
            for k in (0, len(d) - 1):
                assert d[k].tobytes() == rec.frame(first + k)[1].tobytes()


def test_a_caller_that_stops_early_leaves_no_reader_thread(tmp_path):
    p = tmp_path / "r.h5"
    _write_many(p, 100)
    with open_recording(p) as rec:
        for first, _ in rec.blocks(read_ahead=True):
            assert rec.reading_ahead
            if first >= 32:
                break
        assert not rec.reading_ahead and not _reader_threads()
        assert rec.frame(99)[2] == pytest.approx(9.9)  # the file is still usable


def test_closing_the_recording_stops_its_reader_thread(tmp_path):
    p = tmp_path / "r.h5"
    _write_many(p, 100)
    rec = open_recording(p)
    blocks = rec.blocks(read_ahead=True)
    first, _ = next(blocks)  # the next block is being read meanwhile
    assert first == 0 and rec.reading_ahead
    rec.close()
    assert not rec.reading_ahead and not _reader_threads()
    with pytest.raises(RecordingError, match="closed before frame 1 was read"):
        next(blocks)


def _spoil_chunk(path, name, frame):
    """Overwrite the start of frame ``frame``'s stored chunk of ``/frames/name``."""
    with h5py.File(path) as f:
        info = f[f"frames/{name}"].id.get_chunk_info_by_coord((frame, 0, 0))
    with open(path, "r+b") as fh:
        fh.seek(info.byte_offset)
        fh.write(b"\xff" * 16)


@pytest.mark.parametrize("read_ahead", [True, False])
def test_an_unreadable_chunk_is_an_error_naming_its_frame(tmp_path, read_ahead):
    p = tmp_path / "r.h5"
    _write_many(p, 70)
    _spoil_chunk(p, "distance_mm", 40)
    with open_recording(p) as rec:
        seen = []
        with pytest.raises(RecordingError, match=rf"{p.name}: frame 40 cannot be read"):
            for first, _ in rec.blocks(read_ahead=read_ahead):
                seen.append(first)
        # the frames before the bad block (frames 32-63) came through
        assert seen == [0, 1, 3, 7, 15]
        with pytest.raises(RecordingError, match="frame 40 cannot be read"):
            rec.frame(40)
        assert not _reader_threads()
