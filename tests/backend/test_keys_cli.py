"""``tofpose keys create|list|revoke`` on a data directory's database: the key is printed
once and works with its scope in a server on that directory; bad input is refused with a
message and exit code 2."""

from __future__ import annotations

import pytest

from backend.services.keys import Scope
from tests.backend.conftest import make_settings, running_app
from tofpose.cli import main


def _key_from(out: str) -> str:
    lines = out.strip().splitlines()
    assert "shown this once" in lines[0]
    return lines[-1]


def test_create_list_revoke_on_the_servers_database(tmp_path, capsys):
    data = tmp_path / "data"
    assert main(["keys", "--data-dir", str(data), "create", "ops-1", "--scope", "operate"]) == 0
    key = _key_from(capsys.readouterr().out)
    assert len(key) == 43
    assert main(["keys", "--data-dir", str(data), "list"]) == 0
    listing = capsys.readouterr().out
    assert key not in listing
    header, row = listing.strip().splitlines()
    assert header.split()[:2] == ["NAME", "SCOPE"]
    assert row.split()[:2] == ["ops-1", "operate"] and row.rstrip().endswith("-")
    assert oct((data / "tofpose.db").stat().st_mode & 0o777) == "0o600"

    settings = make_settings(data, api_token=None)
    with running_app(settings) as c:
        auth = {"Authorization": f"Bearer {key}"}
        assert c.post("/api/motion/stop", headers=auth).status_code == 200
        assert c.get("/api/keys", headers=auth).status_code == 403
        # the first start still made the admin key (data/api_token)
        admin = (data / "api_token").read_text().strip()
        assert c.app.state.tofpose.keys.verify(admin).scope is Scope.ADMIN

        assert main(["keys", "--data-dir", str(data), "revoke", "ops-1"]) == 0
        assert "revoked" in capsys.readouterr().out
        c.app.state.tofpose.keys.reload()  # what the refresh thread does every few seconds
        assert c.post("/api/motion/stop", headers=auth).status_code == 401
    assert main(["keys", "--data-dir", str(data), "list"]) == 0
    rows = capsys.readouterr().out.strip().splitlines()[1:]
    assert [r.split()[:2] for r in rows] == [["ops-1", "operate"], ["admin", "admin"]]
    assert not rows[0].rstrip().endswith("-")  # a revocation time


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["create", "bad name", "--scope", "read"], "key name must be 1-64 letters"),
        (["revoke", "nobody"], "no active key named 'nobody'"),
    ],
)
def test_bad_requests_are_refused_with_a_message(tmp_path, capsys, argv, message):
    assert main(["keys", "--data-dir", str(tmp_path), *argv]) == 2
    assert message in capsys.readouterr().err


def test_a_taken_name_and_an_unreachable_database_are_refused(tmp_path, capsys):
    args = ["keys", "--data-dir", str(tmp_path), "create", "twin", "--scope", "read"]
    assert main(args) == 0
    capsys.readouterr()
    assert main(args) == 2
    assert "a key named 'twin' exists already" in capsys.readouterr().err
    bad_db = "sqlite:////nonexistent/dir/x.db"
    assert main(["keys", "--data-dir", str(tmp_path), "--db", bad_db, "list"]) == 2
    assert f"cannot use the database {bad_db}" in capsys.readouterr().err
    with pytest.raises(SystemExit):  # argparse: the scope is one of three
        main(["keys", "--data-dir", str(tmp_path), "create", "x", "--scope", "root"])
