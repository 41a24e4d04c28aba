"""``tofpose record`` against a live server (uvicorn on loopback): it starts a recording,
shows its progress, stops it and downloads an HDF5 recording that ``tofpose.io.recording``
reads; the key comes from --key, $TOFPOSE_API_KEY or the key file, in that order; a read
key, an unreachable server and a missing key each end with one line saying so."""

from __future__ import annotations

import io

import httpx
import pytest

from backend import record_cli
from backend.record_cli import RecordError, resolve_key
from tests.backend.conftest import AUTH, TOKEN, LiveServer, make_settings
from tests.backend.serve_process import free_port
from tofpose.cli import main as tofpose_main
from tofpose.io.recording import open_recording


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    data = tmp_path_factory.mktemp("record-cli") / "data"
    with LiveServer(make_settings(data, recording_min_free_mb=100)) as srv:
        yield srv


def _opts(server, **kw) -> dict:
    return {
        "duration": 1.5,
        "name": None,
        "url": server.base_url,
        "key": TOKEN,
        "key_file": None,
        "out": None,
        "download": True,
        **kw,
    }


def test_it_records_shows_progress_stops_and_downloads_a_readable_recording(server, tmp_path):
    out, err = io.StringIO(), io.StringIO()
    target = tmp_path / "bench.h5"
    code = record_cli.run(_opts(server, name="bench check", out=str(target)), out, err)
    assert code == 0, err.getvalue()
    progress = err.getvalue().splitlines()
    assert progress and all("'bench check'" in line and " frames, " in line for line in progress)
    lines = out.getvalue().splitlines()
    assert lines[-1] == f"wrote {target}"
    with open_recording(target) as rec:
        assert rec.n_frames > 0
        assert f"{rec.n_frames} frames" in lines[0]
    listing = httpx.get(server.base_url + "/api/recordings").json()["recordings"]
    entry = next(e for e in listing if e["name"] == "bench check")
    assert entry["state"] == "stopped" and entry["frames"] == rec.n_frames
    assert entry["elapsed_s"] >= 1.5 and entry["stop_reason"] in ("requested", "duration")


def test_through_tofpose_record_without_download_it_prints_the_url(server, capsys):
    code = tofpose_main(
        ["record", "--duration", "0.5", "--url", server.base_url, "--key", TOKEN, "--no-download"]
    )
    captured = capsys.readouterr()
    assert code == 0, captured.err
    url = captured.out.splitlines()[-1]
    assert url.startswith(server.base_url + "/api/recordings/") and url.endswith("/recording.h5")
    assert "'tofpose record " in captured.out  # the default name: the command and the time


def test_a_read_key_is_refused_with_the_servers_reason(server):
    r = httpx.post(
        server.base_url + "/api/keys", json={"name": "cli-viewer", "scope": "read"}, headers=AUTH
    )
    err = io.StringIO()
    code = record_cli.run(_opts(server, key=r.json()["key"]), io.StringIO(), err)
    assert code == 2
    refused = "tofpose record: the server refused to start the recording: 403"
    assert err.getvalue().startswith(refused)
    assert "'operate'" in err.getvalue()


def test_an_unreachable_server_is_named():
    url = f"http://127.0.0.1:{free_port()}"
    err = io.StringIO()
    opts = {"duration": 1.0, "url": url, "key": "k", "key_file": None, "download": True}
    assert record_cli.run(opts, io.StringIO(), err) == 2
    assert f"cannot reach the server at {url}" in err.getvalue()


def test_the_key_comes_from_the_option_then_the_environment_then_the_file(tmp_path):
    f = tmp_path / "api_token"
    f.write_text("from-file\n")
    env = {"TOFPOSE_API_KEY": "from-env"}
    assert resolve_key("from-option", f, env) == "from-option"
    assert resolve_key(None, f, env) == "from-env"
    assert resolve_key(None, f, {}) == "from-file"
    with pytest.raises(RecordError, match=r"no API key: pass --key, set TOFPOSE_API_KEY"):
        resolve_key(None, tmp_path / "missing", {})


def test_a_duration_that_is_not_positive_is_refused_before_any_request():
    err = io.StringIO()
    assert record_cli.run({"duration": 0.0, "url": "http://127.0.0.1:9"}, io.StringIO(), err) == 2
    assert err.getvalue() == "tofpose record: --duration must be > 0 s, got 0\n"
