"""Chunks inflated with ISA-L (``tofpose.io.deflate_chunks``) against h5py's own read of
the same file: bit for bit in every layout it takes, and h5py's read (and errors) in
every one it does not."""

from __future__ import annotations

import importlib.util

import h5py
import numpy as np
import pytest

from tofpose.io import deflate_chunks
from tofpose.io.deflate_chunks import chunk_reader


def _data(dtype, shape=(14, 37, 53), seed=0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    if np.dtype(dtype).kind == "f":
        a = rng.normal(1000.0, 300.0, shape).astype(dtype)
        a[3, 5, 7] = np.nan
        a.reshape(-1)[::97] = np.inf
        return a
    return rng.integers(0, 4096, shape).astype(dtype)


LAYOUTS = {
    "one frame a chunk, shuffled": {"chunks": (1, 37, 53), "compression": "gzip", "shuffle": True},
    "tiles of 4 frames, level 4": {
        "chunks": (4, 10, 16),
        "compression": "gzip",
        "compression_opts": 4,
    },
    "tiles, shuffled, level 9": {
        "chunks": (3, 20, 20),
        "compression": "gzip",
        "compression_opts": 9,
        "shuffle": True,
    },
}


@pytest.mark.parametrize("dtype", ["<u2", "<f4", ">f4", ">u2"])
@pytest.mark.parametrize("layout", LAYOUTS.values(), ids=list(LAYOUTS))
def test_blocks_are_h5pys_bit_for_bit(tmp_path, layout, dtype):
    """Spans that start and end inside chunks, edge tiles that overhang the image, NaN
    and inf, both byte orders."""
    data = _data(dtype)
    with h5py.File(tmp_path / "r.h5", "w") as f:
        f.create_dataset("x", data=data, **layout)
    with h5py.File(tmp_path / "r.h5", "r") as f:
        reader = chunk_reader(f["x"])
        assert reader is not None
        for a, b in ((0, 14), (1, 2), (2, 9), (5, 14), (13, 14)):
            got = reader.read(a, b)
            assert got.dtype == f["x"].dtype and got.shape == (b - a, 37, 53)
            assert got.tobytes() == f["x"][a:b].tobytes()
        assert reader.fallbacks == 0  # every read was the fast path's


def test_layouts_it_cannot_read_exactly_are_left_to_h5py(tmp_path):
    data = _data("<u2")
    with h5py.File(tmp_path / "r.h5", "w") as f:
        f.create_dataset("contiguous", data=data)
        f.create_dataset("lzf", data=data, chunks=(1, 37, 53), compression="lzf")
        f.create_dataset(
            "checksummed", data=data, chunks=(1, 37, 53), compression="gzip", fletcher32=True
        )
        f.create_dataset("scaled", data=data, chunks=(1, 37, 53), scaleoffset=0)
        f.create_dataset("plain chunks", data=data, chunks=(1, 37, 53))
        f.create_dataset("two d", data=data[0], chunks=(37, 53), compression="gzip")
    with h5py.File(tmp_path / "r.h5", "r") as f:
        for name in ("contiguous", "lzf", "checksummed", "scaled", "plain chunks", "two d"):
            assert chunk_reader(f[name]) is None, name


def test_a_chunk_never_written_reads_as_h5py_fills_it(tmp_path):
    with h5py.File(tmp_path / "r.h5", "w") as f:
        ds = f.create_dataset(
            "x", (6, 37, 53), "<f4", chunks=(1, 37, 53), compression="gzip", fillvalue=np.nan
        )
        ds[0] = 1.0
        ds[2] = 2.0  # frames 1 and 3-5: no chunk stored
    with h5py.File(tmp_path / "r.h5", "r") as f:
        reader = chunk_reader(f["x"])
        assert reader is not None
        got = reader.read(0, 6)
        assert got.tobytes() == f["x"][0:6].tobytes()
        assert reader.fallbacks == 1  # h5py fills what was never written
        assert np.isnan(got[1]).all() and (got[2] == 2.0).all()


def test_bytes_that_do_not_inflate_give_h5pys_error(tmp_path):
    with h5py.File(tmp_path / "r.h5", "w") as f:
        f.create_dataset("x", data=_data("<u2"), chunks=(1, 37, 53), compression="gzip")
        info = f["x"].id.get_chunk_info_by_coord((4, 0, 0))
    with open(tmp_path / "r.h5", "r+b") as fh:
        fh.seek(info.byte_offset)
        fh.write(b"\xff" * 16)
    with h5py.File(tmp_path / "r.h5", "r") as f:
        reader = chunk_reader(f["x"])
        assert reader is not None
        assert reader.read(0, 4).tobytes() == f["x"][0:4].tobytes()
        assert reader.fallbacks == 0
        with pytest.raises(OSError, match="(?i)filter|inflate|read"):
            reader.read(3, 6)
        assert reader.fallbacks == 1


def test_without_isal_h5py_reads_everything(tmp_path, monkeypatch):
    with h5py.File(tmp_path / "r.h5", "w") as f:
        f.create_dataset("x", data=_data("<u2"), chunks=(1, 37, 53), compression="gzip")
    real = importlib.util.find_spec
    monkeypatch.setattr(
        deflate_chunks.importlib.util,
        "find_spec",
        lambda name, *a: None if name == "isal" else real(name, *a),
    )
    with h5py.File(tmp_path / "r.h5", "r") as f:
        assert chunk_reader(f["x"]) is None


@pytest.mark.parametrize("dtype", ["<u2", "<f4", ">f4"])
@pytest.mark.parametrize("shuffle", [True, False])
def test_frames_written_by_chunk_are_read_back_by_hdf5_bit_for_bit(tmp_path, dtype, shuffle):
    """Frames deflated by ISA-L and stored chunk by chunk read back through HDF5's own
    filters (h5py, no ISA-L) as the same bytes, NaN and inf included."""
    data = _data(dtype)
    with h5py.File(tmp_path / "w.h5", "w") as f:
        ds = f.create_dataset(
            "x",
            (0, 37, 53),
            dtype,
            maxshape=(None, 37, 53),
            chunks=(1, 37, 53),
            compression="gzip",
            compression_opts=1,
            shuffle=shuffle,
        )
        writer = chunk_writer_of(ds)
        for k, frame in enumerate(data):
            ds.resize(k + 1, axis=0)
            writer.write(k, frame)
    with h5py.File(tmp_path / "w.h5", "r") as f:
        assert f["x"].compression == "gzip" and f["x"].shuffle == shuffle
        assert f["x"][:].tobytes() == data.astype(dtype).tobytes()


def chunk_writer_of(ds):
    from tofpose.io.deflate_chunks import chunk_writer

    writer = chunk_writer(ds)
    assert writer is not None
    return writer


def test_datasets_it_cannot_write_exactly_are_left_to_h5py(tmp_path):
    from tofpose.io.deflate_chunks import chunk_writer

    with h5py.File(tmp_path / "w.h5", "w") as f:
        tiled = f.create_dataset(
            "tiled", (4, 37, 53), "<u2", chunks=(1, 10, 16), compression="gzip"
        )
        several = f.create_dataset(
            "several", (4, 37, 53), "<u2", chunks=(2, 37, 53), compression="gzip"
        )
        lzf = f.create_dataset("lzf", (4, 37, 53), "<u2", chunks=(1, 37, 53), compression="lzf")
        plain = f.create_dataset("plain", (4, 37, 53), "<u2", chunks=(1, 37, 53))
        for ds in (tiled, several, lzf, plain):
            assert chunk_writer(ds) is None, ds.name
        good = f.create_dataset("good", (4, 37, 53), "<u2", chunks=(1, 37, 53), compression="gzip")
        with pytest.raises(ValueError, match=r"frame \(37, 52\) != the dataset's \(37, 53\)"):
            chunk_writer_of(good).write(0, np.zeros((37, 52), np.uint16))
        # another type: HDF5 converts it (clips), as h5py's own write would
        chunk_writer_of(good).write(1, np.full((37, 53), 70000.0))
        chunk_writer_of(good).write(2, np.full((37, 53), -5.0))
        assert (good[1] == 65535).all() and (good[2] == 0).all()
