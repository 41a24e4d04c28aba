"""API keys on an SQLite file: scopes and their order, what is stored (a hash, never the
key), verification without the database, revocation, unique names, the first start's
admin key, and a second process's changes reaching a running service."""

from __future__ import annotations

import hashlib

import pytest
from sqlalchemy import select

from backend.db.engine import make_engine, make_session_factory, upgrade_database
from backend.db.models import ApiKeyRow
from backend.services.keys import (
    KeyNameTakenError,
    KeyNotFoundError,
    KeyService,
    Scope,
    key_hash,
)
from tests.backend.conftest import wait_for


@pytest.fixture
def sessions(tmp_path):
    engine = make_engine(f"sqlite:///{tmp_path / 'db.sqlite'}")
    upgrade_database(engine)
    yield make_session_factory(engine)
    engine.dispose()


@pytest.fixture
def keys(sessions) -> KeyService:
    return KeyService(sessions)


def test_scopes_include_the_ones_below():
    assert Scope.READ < Scope.OPERATE < Scope.ADMIN
    assert [s.label for s in Scope] == ["read", "operate", "admin"]
    assert Scope.parse("Operate") is Scope.OPERATE
    with pytest.raises(ValueError, match="scope must be read, operate or admin, got 'root'"):
        Scope.parse("root")


def test_a_created_key_verifies_with_its_scope_and_only_its_hash_is_stored(keys, sessions):
    key = keys.create("alice", "operate")
    assert len(key) == 43  # token_urlsafe(32): 256 random bits
    record = keys.verify(key)
    assert (record.name, record.scope) == ("alice", Scope.OPERATE)
    assert record.allows(Scope.READ) and record.allows(Scope.OPERATE)
    assert not record.allows(Scope.ADMIN)
    with sessions() as s:
        row = s.scalar(select(ApiKeyRow).where(ApiKeyRow.name == "alice"))
    assert row.key_sha256 == hashlib.sha256(key.encode()).hexdigest() == key_hash(key)
    assert key not in (row.key_sha256, row.name, row.scope)
    for wrong in (None, "", key[:-1], key + "x", key.upper()):
        assert keys.verify(wrong) is None, wrong


def test_verification_needs_no_database(keys, sessions):
    """After the keys are loaded, verify runs on the copy in memory: it still answers
    with the database gone."""
    key = keys.create("bob", "read")
    sessions.kw["bind"].dispose()
    sessions.configure(bind=make_engine("sqlite:////nonexistent/dir/db.sqlite"))
    assert keys.verify(key).name == "bob"


def test_revoked_keys_stop_working_and_keep_their_names(keys):
    key = keys.create("carol", "admin")
    revoked = keys.revoke("carol")
    assert revoked.revoked_at is not None and not revoked.allows(Scope.READ)
    assert keys.verify(key) is None
    with pytest.raises(KeyNotFoundError, match="no active key named 'carol'"):
        keys.revoke("carol")
    with pytest.raises(KeyNameTakenError, match="a key named 'carol' exists already"):
        keys.create("carol", "read")
    listed = {k.name: k for k in keys.list()}
    assert listed["carol"].revoked_at is not None and listed["carol"].scope is Scope.ADMIN


@pytest.mark.parametrize(
    ("name", "scope", "message"),
    [
        ("", "read", "key name must be 1-64 letters"),
        ("-dash-first", "read", "key name must be"),
        ("a" * 65, "read", "key name must be"),
        ("has space", "read", "key name must be"),
        ("dave", "superuser", "scope must be read, operate or admin, got 'superuser'"),
    ],
)
def test_bad_names_and_scopes_are_refused_naming_the_problem(keys, name, scope, message):
    with pytest.raises(ValueError, match=message):
        keys.create(name, scope)
    assert keys.list() == []


def test_names_are_unique(keys):
    keys.create("erin", "read")
    with pytest.raises(KeyNameTakenError):
        keys.create("erin", "admin")
    assert [(k.name, k.scope) for k in keys.list()] == [("erin", Scope.READ)]


def test_the_first_start_stores_data_dirs_token_as_the_admin_key(keys, sessions, tmp_path):
    boot = keys.bootstrap(tmp_path, None)
    token = (tmp_path / "api_token").read_text().strip()
    assert (boot.source, boot.shown) == ("generated", token)
    assert keys.verify(token).name == "admin" and keys.verify(token).scope is Scope.ADMIN
    # a second start adds nothing and shows nothing
    again = KeyService(sessions).bootstrap(tmp_path, None)
    assert (again.source, again.shown) == ("database", None)
    assert [k.name for k in keys.list()] == ["admin"]


def test_an_existing_token_file_becomes_the_admin_key_unprinted(keys, tmp_path):
    (tmp_path / "api_token").write_text("old-token-of-a-release-before-keys\n")
    boot = keys.bootstrap(tmp_path, None)
    assert (boot.source, boot.shown) == ("file", None)
    assert keys.verify("old-token-of-a-release-before-keys").scope is Scope.ADMIN


def test_a_configured_token_is_the_admin_key_and_stays_one(keys, sessions, tmp_path):
    boot = keys.bootstrap(tmp_path, "configured-token-0123456789")
    assert (boot.source, boot.shown) == ("configured", None)
    assert not (tmp_path / "api_token").exists()
    assert keys.verify("configured-token-0123456789").name == "admin"
    keys.revoke("admin")
    # still configured (TOFPOSE_API_TOKEN): still an admin key, under that name
    record = keys.verify("configured-token-0123456789")
    assert (record.name, record.scope) == ("TOFPOSE_API_TOKEN", Scope.ADMIN)
    # without it, a revoked admin key stays revoked: a restart does not bring it back
    later = KeyService(sessions)
    assert later.bootstrap(tmp_path, None).source == "database"
    assert later.verify("configured-token-0123456789") is None
    assert not (tmp_path / "api_token").exists()


def test_keys_made_before_the_first_start_do_not_replace_the_admin_key(keys, tmp_path):
    """``tofpose keys create`` on a fresh data directory: the server's first start
    still makes the admin key."""
    keys.create("viewer", "read")
    assert keys.bootstrap(tmp_path, None).source == "generated"
    assert {k.name: k.scope for k in keys.list()} == {"viewer": Scope.READ, "admin": Scope.ADMIN}


def test_another_processs_changes_reach_a_running_service(sessions, tmp_path):
    """The CLI beside a running server: the server's copy follows after a reload (its
    refresh thread calls reload every refresh_s)."""
    server = KeyService(sessions)
    server.bootstrap(tmp_path, None)
    cli = KeyService(sessions)
    key = cli.create("frank", "operate")
    assert server.verify(key) is None  # not yet reloaded
    server.reload()
    assert server.verify(key).name == "frank"
    cli.revoke("frank")
    server.reload()
    assert server.verify(key) is None


def test_the_refresh_thread_reloads(sessions, tmp_path):
    server = KeyService(sessions, refresh_s=0.01)
    server.bootstrap(tmp_path, None)
    server.start()
    try:
        key = KeyService(sessions).create("grace", "read")
        wait_for(lambda: server.verify(key) is not None, what="the refresh thread")
    finally:
        server.stop()
