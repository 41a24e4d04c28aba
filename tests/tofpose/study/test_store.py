"""The study store's chunk files: found again by their names whatever the size of the
cell and frame numbers in them; the manifest counts the chunks without listing them."""

from __future__ import annotations

from tofpose.study.columns import COLUMNS
from tofpose.study.spec import StudySpec
from tofpose.study.store import chunk_name, open_store, present_chunks, write_chunk


def test_chunks_beyond_five_digit_cells_and_seven_digit_frames_are_found(tmp_path):
    chunks = {(0, 0, 25), (99_999, 9_999_975, 10_000_000), (123_456, 10_000_000, 10_000_025)}
    for cell, start, stop in chunks:
        write_chunk(tmp_path, cell, start, stop, COLUMNS.empty_table())
    assert chunk_name(123_456, 10_000_000, 10_000_025) == (
        "cell-123456_frames-10000000-10000025.parquet"
    )
    assert present_chunks(tmp_path) == chunks


def test_the_manifest_counts_the_chunks(tmp_path):
    spec = StudySpec.from_dict(
        {"frames_per_cell": 10, "chunk_frames": 4, "grid": {"range_m": [2.0, 4.0, 6.0]}}
    )
    manifest = open_store(tmp_path / "s", spec)
    assert manifest["chunks"] == len(spec.chunks()) == 3 * 3  # 4 + 4 + 2 frames per cell
