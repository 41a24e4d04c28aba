"""A study's directory: the spec and status (``study.json``), the per-frame results as
Parquet files, one per chunk (``frames/``), and what is derived from them
(``summary.json``, ``report.html``, ``report.pdf``, ``plots/``).

Parquet, not Zarr: a study's results are a table (a row per frame, columns of mixed
types: numbers, the failure reason, the cell's physics family), which is what Parquet
stores and what pandas, pyarrow and DuckDB read directly; Zarr stores N-d arrays.
Workers write without locks: each chunk is its own file, named by the chunk (cell and
frame range), written under a temporary name and renamed into place (atomic on a POSIX
file system), so a task that Dask reschedules after a worker died rewrites the same
file with the same rows, and a worker killed mid-write leaves only a temporary file,
which readers skip and the next run removes. The directory must be on a file system
every worker sees (a local disk for a LocalCluster; a shared mount for lab machines).
"""

from __future__ import annotations

import json
import os
import re
import uuid
from pathlib import Path
from typing import TYPE_CHECKING

from tofpose.study.spec import StudySpec

if TYPE_CHECKING:  # pyarrow is imported where chunks are read or written: a server that
    import pyarrow as pa  # only lists studies does not load it (docs/server.md, "Memory")

MANIFEST = "study.json"
# at least 5 and 7 digits: a larger number takes more (``chunk_name``)
_CHUNK = re.compile(r"^cell-(\d{5,})_frames-(\d{7,})-(\d{7,})\.parquet$")


class StudyStoreError(ValueError):
    """A study directory that cannot be used as asked; the message says why."""


def chunk_name(cell: int, start: int, stop: int) -> str:
    return f"cell-{cell:05d}_frames-{start:07d}-{stop:07d}.parquet"


def write_chunk(store_dir: str | Path, cell: int, start: int, stop: int, table: pa.Table) -> Path:
    """Write one chunk's rows atomically (module docstring); returns the file's path."""
    frames = Path(store_dir) / "frames"
    frames.mkdir(parents=True, exist_ok=True)
    final = frames / chunk_name(cell, start, stop)
    tmp = frames / f".{final.name}.{uuid.uuid4().hex}.tmp"
    import pyarrow.parquet as pq

    pq.write_table(table, tmp)
    os.replace(tmp, final)
    return final


def present_chunks(store_dir: str | Path) -> set[tuple[int, int, int]]:
    """The chunks (cell, start, stop) whose file is in place."""
    frames = Path(store_dir) / "frames"
    if not frames.is_dir():
        return set()
    out: set[tuple[int, int, int]] = set()
    for p in frames.iterdir():
        m = _CHUNK.match(p.name)
        if m:
            cell, start, stop = (int(g) for g in m.groups())
            out.add((cell, start, stop))
    return out


def remove_temporary(store_dir: str | Path) -> int:
    """Delete half-written chunk files left by killed workers; returns how many."""
    frames = Path(store_dir) / "frames"
    stale = list(frames.glob(".*.tmp")) if frames.is_dir() else []
    for p in stale:
        p.unlink(missing_ok=True)
    return len(stale)


def read_frames(store_dir: str | Path, spec: StudySpec) -> pa.Table:
    """Every stored row of the spec's chunks, sorted by (cell, frame); ``StudyStoreError``
    when a chunk file is unreadable (names it)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    frames = Path(store_dir) / "frames"
    tables = []
    for cell, start, stop in spec.chunks():
        p = frames / chunk_name(cell, start, stop)
        if not p.exists():
            continue
        try:
            tables.append(pq.read_table(p))
        except (OSError, pa.ArrowInvalid) as exc:
            raise StudyStoreError(f"{p}: unreadable chunk ({exc})") from exc
    if not tables:
        from tofpose.study.columns import COLUMNS

        return COLUMNS.empty_table()
    table = pa.concat_tables(tables)
    return table.sort_by([("cell", "ascending"), ("frame", "ascending")])


def open_store(store_dir: str | Path, spec: StudySpec) -> dict:
    """Create the directory for ``spec``, or take up one a run of the same spec left
    (its chunks are kept: the study resumes); ``StudyStoreError`` when it holds another
    study. Returns the manifest."""
    root = Path(store_dir)
    path = root / MANIFEST
    if path.exists():
        manifest = read_manifest(root)
        if StudySpec.from_dict(manifest["spec"], limits=None) != spec:
            raise StudyStoreError(
                f"{root} holds the results of another study spec "
                f"({manifest['spec'].get('name')!r}); choose another --out or delete it"
            )
        return manifest
    if root.exists() and any(root.iterdir()):
        raise StudyStoreError(f"{root} is not empty and holds no study; choose another --out")
    root.mkdir(parents=True, exist_ok=True)
    manifest = {
        "format": "tofpose-study",
        "version": 1,
        "spec": spec.to_dict(),
        "status": "created",
        "chunks": spec.n_chunks,
        "chunks_done": 0,
    }
    write_manifest(root, manifest)
    return manifest


def read_manifest(store_dir: str | Path) -> dict:
    path = Path(store_dir) / MANIFEST
    try:
        manifest = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise StudyStoreError(f"{path}: not a readable study manifest ({exc})") from exc
    if manifest.get("format") != "tofpose-study":
        raise StudyStoreError(f"{path}: not a tofpose study manifest")
    return manifest


def write_manifest(store_dir: str | Path, manifest: dict) -> None:
    """Replace ``study.json`` atomically."""
    root = Path(store_dir)
    tmp = root / f".{MANIFEST}.{uuid.uuid4().hex}.tmp"
    tmp.write_text(json.dumps(manifest, indent=2))
    os.replace(tmp, root / MANIFEST)
