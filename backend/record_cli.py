"""``tofpose record --duration S [--name N] [--url URL] [--key KEY] [--out FILE]``: record
the live stream of a running server (``POST /api/recordings``), show its progress, stop
it and download the HDF5 recording (or print its URL with ``--no-download``).

A client of the REST API only (httpx): it works against any server it can reach with a
key of scope ``operate`` or ``admin``, taken from ``--key``, else ``$TOFPOSE_API_KEY``,
else the server's key file (``--key-file``, default ``data/api_token``: the admin key of
the first start, on the server's own machine). The duration also goes to the server, so
a recording whose client dies stops on time anyway; Ctrl-C stops it early and still
downloads what was recorded.
"""

from __future__ import annotations

import os
import re
import sys
import time
from collections.abc import Mapping
from datetime import UTC, datetime
from pathlib import Path
from typing import TextIO

import httpx

KEY_ENV = "TOFPOSE_API_KEY"
POLL_S = 0.5
MB = 1_000_000


class RecordError(RuntimeError):
    """What went wrong, as the one line the command prints."""


def resolve_key(
    key: str | None, key_file: str | Path | None, environ: Mapping[str, str] | None = None
) -> str:
    """The API key: ``key`` if given, else ``$TOFPOSE_API_KEY``, else the first line of
    ``key_file``; ``RecordError`` naming the three places when none has one."""
    env: Mapping[str, str] = os.environ if environ is None else environ
    if key:
        return key
    if env.get(KEY_ENV):
        return env[KEY_ENV]
    if key_file is not None and Path(key_file).is_file():
        text = Path(key_file).read_text().strip()
        if text:
            return text.splitlines()[0].strip()
    raise RecordError(
        f"no API key: pass --key, set {KEY_ENV}, or run where the server's key file is "
        f"({key_file}); a key of scope operate or admin (tofpose keys create NAME --scope "
        "operate)"
    )


def _detail(r: httpx.Response) -> str:
    """The server's reason for a refusal, as text (a 422's fields joined)."""
    try:
        detail = r.json().get("detail")
    except ValueError:
        return r.text.strip()[:300] or r.reason_phrase
    if isinstance(detail, list):
        return "; ".join(
            f"{'.'.join(map(str, e.get('loc', [])[1:]))}: {e.get('msg')}" for e in detail
        )
    return str(detail)


def _check(r: httpx.Response, what: str) -> dict:
    if r.status_code >= 400:
        raise RecordError(f"{what}: {r.status_code} {_detail(r)}")
    return r.json() if r.content else {}


def progress_line(rec: dict, duration_s: float) -> str:
    """``recording 3 'name': 12.0 / 30 s, 240 frames, 48.2 MB``."""
    return (
        f"recording {rec['id']} {rec['name']!r}: {rec['elapsed_s']:.1f} / {duration_s:g} s, "
        f"{rec['frames']} frames, {rec['size_bytes'] / MB:.1f} MB"
    )


def _filename(r: httpx.Response, rid: int) -> str:
    m = re.search(r'filename="?([^";]+)"?', r.headers.get("content-disposition", ""))
    name = Path(m.group(1)).name if m else ""
    return name or f"recording-{rid}.h5"


def record(
    client: httpx.Client,
    name: str,
    duration_s: float,
    *,
    out: str | None,
    download: bool,
    err: TextIO,
) -> tuple[dict, Path | str]:
    """Start, follow, stop, download. Returns the final entry and the file written (or
    the download URL when ``download`` is False)."""
    rec = _check(
        client.post("/api/recordings", json={"name": name, "duration_s": duration_s}),
        "the server refused to start the recording",
    )
    rid = rec["id"]
    end = time.monotonic() + duration_s
    interactive = err.isatty()
    try:
        while rec["state"] == "recording":
            if time.monotonic() >= end:
                rec = _check(client.post(f"/api/recordings/{rid}/stop"), "stopping it failed")
                break
            time.sleep(min(POLL_S, max(0.0, end - time.monotonic())))
            rec = _check(client.get(f"/api/recordings/{rid}"), "reading its progress failed")
            print(
                ("\r" if interactive else "") + progress_line(rec, duration_s),
                end="" if interactive else "\n",
                file=err,
                flush=True,
            )
    except KeyboardInterrupt:
        print("\ninterrupted: stopping the recording", file=err)
        rec = _check(client.post(f"/api/recordings/{rid}/stop"), "stopping it failed")
    if interactive:
        print(file=err)
    url = f"{client.base_url}/api/recordings/{rid}/recording.h5"
    if not download:
        return rec, url
    with client.stream("GET", f"/api/recordings/{rid}/recording.h5") as r:
        if r.status_code >= 400:
            r.read()
            _check(r, "downloading it failed")
        path = Path(out) if out else Path(_filename(r, rid))
        tmp = path.with_name(f".{path.name}.part")
        with open(tmp, "wb") as fh:
            for chunk in r.iter_bytes(1 << 20):
                fh.write(chunk)
        tmp.replace(path)
    return rec, path


def run(opts: dict, out: TextIO | None = None, err: TextIO | None = None) -> int:
    """``tofpose record``; returns a process exit code (2: refused or unreachable).
    ``out``, ``err``: where the result and the progress go (default stdout, stderr)."""
    out, err = out or sys.stdout, err or sys.stderr
    duration = opts["duration"]
    if not duration > 0:
        print(f"tofpose record: --duration must be > 0 s, got {duration:g}", file=err)
        return 2
    name = opts.get("name") or f"tofpose record {datetime.now(UTC):%Y-%m-%d %H:%M:%SZ}"
    url = opts.get("url") or "http://127.0.0.1:8000"
    try:
        key = resolve_key(opts.get("key"), opts.get("key_file"))
        headers = {"Authorization": f"Bearer {key}"}
        with httpx.Client(base_url=url.rstrip("/"), headers=headers, timeout=60.0) as client:
            rec, where = record(
                client,
                name,
                duration,
                out=opts.get("out"),
                download=opts.get("download", True),
                err=err,
            )
    except RecordError as exc:
        print(f"tofpose record: {exc}", file=err)
        return 2
    except httpx.HTTPError as exc:
        print(f"tofpose record: cannot reach the server at {url}: {exc}", file=err)
        return 2
    except OSError as exc:
        print(f"tofpose record: cannot write the recording: {exc}", file=err)
        return 2
    why = f"{rec['stop_reason']}: {rec['stop_detail']}" if rec.get("stop_reason") else ""
    size_mb = rec["size_bytes"] / MB
    print(
        f"recording {rec['id']} {rec['name']!r}: {rec['frames']} frames, {size_mb:.1f} MB, "
        f"{rec['elapsed_s']:.1f} s ({why})",
        file=out,
    )
    print(f"wrote {where}" if isinstance(where, Path) else where, file=out)
    return 0
