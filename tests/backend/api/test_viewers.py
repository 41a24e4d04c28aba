"""GET /api/viewers/...: the Foxglove layout and a Rerun blueprint bound to the name of
an MCAP download (docs/interop.md, "Viewer layouts")."""

from __future__ import annotations

import builtins

import pytest

from tests.backend.conftest import make_settings, running_app
from tofpose.io.interop.viewers import FOXGLOVE_LAYOUT


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    with running_app(make_settings(tmp_path_factory.mktemp("data"))) as c:
        yield c


def test_the_layout_is_the_shipped_one(client):
    r = client.get("/api/viewers/foxglove-layout.json")
    assert r.status_code == 200 and r.headers["content-type"] == "application/json"
    assert r.content == FOXGLOVE_LAYOUT.read_bytes()


def test_the_blueprint_is_bound_to_the_mcap_files_name(client, tmp_path):
    rerun_chunk = pytest.importorskip(
        "rerun.chunk", reason="rerun-sdk is not installed: the server builds no blueprint"
    )
    r = client.get("/api/viewers/rerun-blueprint.rbl", params={"file": "campaign-3.mcap"})
    assert r.status_code == 200
    assert 'filename="campaign-3.rbl"' in r.headers["content-disposition"]
    (tmp_path / "b.rbl").write_bytes(r.content)
    (store,) = rerun_chunk.RrdReader(tmp_path / "b.rbl").blueprints()
    assert store.application_id == "campaign-3"


@pytest.mark.parametrize("file", ["campaign-3", "../x.mcap", "a b.mcap", ""])
def test_a_file_name_that_is_not_an_mcap_file_is_refused_naming_the_parameter(client, file):
    r = client.get("/api/viewers/rerun-blueprint.rbl", params={"file": file})
    assert r.status_code == 422 and "file" in r.text


def test_without_rerun_sdk_the_server_says_what_is_missing(client, monkeypatch):
    real_import = builtins.__import__

    def no_rerun(name, *args, **kwargs):
        if name.startswith("rerun"):
            raise ImportError("No module named 'rerun'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_rerun)
    r = client.get("/api/viewers/rerun-blueprint.rbl", params={"file": "campaign-3.mcap"})
    assert r.status_code == 503 and "rerun-sdk" in r.json()["detail"]
