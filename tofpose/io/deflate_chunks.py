"""Read and write a recording's image datasets by their stored chunks, deflated and
inflated with ISA-L.

A recording's images are deflate-compressed HDF5 chunks (ours: one frame a chunk,
level 1 after the byte shuffle; other writers': tiles of several frames, any level).
HDF5 inflates them with zlib, about 0.5-0.7 ms a 320 x 240 frame pair, half of what
``tofpose estimate`` spends on a frame. Intel's ISA-L (``isal``, the library made for
fast deflate) inflates the same bytes 2-3x faster. ``ChunkReader`` reads each chunk's
stored bytes (``read_direct_chunk``: HDF5 does the file I/O, no filter runs), inflates
them with ISA-L, undoes the shuffle and places them, so that a block of frames is
bit-identical to h5py's ``ds[a:b]``.

It reads only what it can read exactly: a chunked dataset whose filters are deflate,
optionally after the shuffle, of a fixed-size numeric type. Anything else (contiguous,
other filters, a chunk stored with a filter skipped, a chunk never written, bytes that
do not inflate) is read by h5py, whose errors name the problem as before.
``chunk_reader(ds)`` gives None for a dataset it cannot read, or when ``isal`` is not
installed. ``chunk_writer(ds)`` is the other way: a frame shuffled in NumPy and deflated
by ISA-L at level 1 (a zlib stream, as HDF5's deflate filter writes and reads), stored
with ``write_direct_chunk`` into a dataset of one frame a chunk with exactly those
filters; any HDF5 library reads it back: 2.5 -> 0.67 ms a frame written (the other
renderer's frames, ``RecordingWriter.append``), the file 4 % smaller.

Reading a recording's blocks (``Recording.blocks``, one core), h5py then this: 1.25 ->
0.77 ms a frame on the bench's 3000-frame recording (one frame a chunk, shuffled, level
1), 1.16 -> 0.60 ms on the other renderer's tiled files (12 frames of 30 x 40 a chunk,
level 4). A single frame of a chunk of several frames is left to h5py
(``Recording.frame``), whose chunk cache keeps the chunk for the next frame.
"""

from __future__ import annotations

import importlib.util
from typing import cast

import h5py
import numpy as np

#: HDF5 filter ids (``h5py.h5z``) the reader undoes itself
_DEFLATE, _SHUFFLE = h5py.h5z.FILTER_DEFLATE, h5py.h5z.FILTER_SHUFFLE


class ChunkReader:
    """``read(start, stop)``: frames [start, stop) of a (n, H, W) chunked dataset,
    inflated with ISA-L; bit-identical to ``ds[start:stop]`` (module docstring)."""

    def __init__(self, ds: h5py.Dataset, shuffled: bool) -> None:
        from isal import isal_zlib

        self._ds = ds
        self._inflate = isal_zlib.decompress
        # the inflater's error class (its type stub calls it an instance)
        self._error = cast("type[Exception]", isal_zlib.error)
        self._shuffled = shuffled
        self._chunk = tuple(int(c) for c in ds.chunks)
        self._dtype = ds.dtype
        self._shape = tuple(int(s) for s in ds.shape)
        #: reads h5py made instead (a chunk missing or not inflating): the tests' witness
        #: that the fast path ran
        self.fallbacks = 0

    @property
    def frames_per_chunk(self) -> int:
        """Frames along the first axis of one chunk (a single frame's read inflates the
        whole chunk: h5py's chunk cache serves frame after frame of one chunk better)."""
        return self._chunk[0]

    def read(self, start: int, stop: int) -> np.ndarray:
        """(stop - start, H, W) array of the dataset's dtype; h5py's read where a chunk
        cannot be read here (its errors then name what is wrong)."""
        try:
            return self._read(start, stop)
        except (RuntimeError, OSError, ValueError, KeyError, self._error):
            # a chunk never written (HDF5: RuntimeError), bytes that do not inflate
            self.fallbacks += 1
            return self._ds[start:stop]

    def _read(self, start: int, stop: int) -> np.ndarray:
        ds, (cz, cy, cx) = self._ds, self._chunk
        _, height, width = self._shape
        out = np.empty((stop - start, height, width), self._dtype)
        first = start // cz * cz
        for z0 in range(first, stop, cz):
            a, b = max(start, z0), min(stop, z0 + cz)
            for y0 in range(0, height, cy):
                for x0 in range(0, width, cx):
                    mask, raw = ds.id.read_direct_chunk((z0, y0, x0))
                    if mask:  # a filter was skipped for this chunk: h5py knows which
                        self.fallbacks += 1
                        return ds[start:stop]
                    chunk = self._decoded(raw).reshape(cz, cy, cx)
                    out[a - start : b - start, y0 : y0 + cy, x0 : x0 + cx] = chunk[
                        a - z0 : b - z0, : height - y0, : width - x0
                    ]
        return out

    def _decoded(self, raw: bytes) -> np.ndarray:
        """A chunk's elements (flat) from its stored bytes: inflated, then unshuffled
        (the shuffle stores byte k of every element together, k = 0..itemsize-1)."""
        data = self._inflate(raw)
        size = self._dtype.itemsize
        if not self._shuffled or size == 1:
            return np.frombuffer(data, self._dtype)
        planes = np.frombuffer(data, np.uint8).reshape(size, -1)
        elements = np.empty((planes.shape[1], size), np.uint8)
        for k in range(size):
            elements[:, k] = planes[k]
        return elements.view(self._dtype).ravel()


def _shuffled_deflate(ds: h5py.Dataset) -> bool | None:
    """For a chunked 3-D numeric dataset whose filters are deflate, optionally after
    the shuffle, and with ``isal`` installed: whether it is shuffled; else None."""
    if importlib.util.find_spec("isal") is None:
        return None
    if ds.chunks is None or ds.ndim != 3 or ds.dtype.kind not in "uif":
        return None
    plist = ds.id.get_create_plist()
    filters = [plist.get_filter(i)[0] for i in range(plist.get_nfilters())]
    if filters not in ([_DEFLATE], [_SHUFFLE, _DEFLATE]):
        return None
    return filters[0] == _SHUFFLE


def chunk_reader(ds: h5py.Dataset) -> ChunkReader | None:
    """A ``ChunkReader`` of the 3-D dataset ``ds`` when it can read it exactly (module
    docstring), else None (h5py reads it)."""
    shuffled = _shuffled_deflate(ds)
    if shuffled is None or ds.size == 0:
        return None
    return ChunkReader(ds, shuffled=shuffled)


class ChunkWriter:
    """``write(index, frame)``: frame (H, W) stored as chunk ``index`` of a (n, H, W)
    dataset of one frame a chunk, shuffled (when the dataset's filters say so) and
    deflated by ISA-L; the dataset must already be long enough."""

    def __init__(self, ds: h5py.Dataset, shuffled: bool) -> None:
        from isal import isal_zlib

        self._ds = ds
        self._deflate = isal_zlib.compress
        self._shuffled = shuffled
        self._dtype = ds.dtype
        self._frame_shape = tuple(int(s) for s in ds.shape[1:])

    def write(self, index: int, frame: np.ndarray) -> None:
        """``frame`` of the dataset's type (either byte order); of another type HDF5
        converts it (clipping where NumPy would wrap), via h5py."""
        if frame.shape != self._frame_shape:
            raise ValueError(f"frame {frame.shape} != the dataset's {self._frame_shape}")
        if frame.dtype.newbyteorder("=") != self._dtype.newbyteorder("="):
            self._ds[index] = frame
            return
        data = np.ascontiguousarray(frame, dtype=self._dtype)
        raw = data.view(np.uint8).reshape(-1, self._dtype.itemsize)
        if self._shuffled and self._dtype.itemsize > 1:
            raw = raw.T  # byte k of every element together, as HDF5's shuffle stores them
        payload = self._deflate(np.ascontiguousarray(raw).tobytes(), 1)
        self._ds.id.write_direct_chunk((index, 0, 0), payload, filter_mask=0)


def chunk_writer(ds: h5py.Dataset) -> ChunkWriter | None:
    """A ``ChunkWriter`` of the 3-D dataset ``ds`` when it is stored one frame a chunk
    with the deflate filter (optionally after the shuffle) and ``isal`` is installed,
    else None (h5py writes it)."""
    shuffled = _shuffled_deflate(ds)
    if shuffled is None or ds.chunks[0] != 1 or ds.chunks[1:] != ds.shape[1:]:
        return None
    return ChunkWriter(ds, shuffled=shuffled)
