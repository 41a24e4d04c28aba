"""The audit trail's service on an SQLite file: body summaries (redacted, cut), the writer
thread (batches, order, flush at stop), a full queue that drops instead of blocking, a
failing database that does not take the writer down, and paging newest first."""

from __future__ import annotations

import json
import threading
from datetime import UTC, datetime

import pytest

from backend.db.engine import make_engine, make_session_factory, upgrade_database
from backend.services.audit import (
    REDACTED,
    SUMMARY_CHARS,
    AuditEntry,
    AuditService,
    body_summary,
)


@pytest.fixture
def sessions(tmp_path):
    engine = make_engine(f"sqlite:///{tmp_path / 'db.sqlite'}")
    upgrade_database(engine)
    yield make_session_factory(engine)
    engine.dispose()


def _entry(i: int, body: bytes = b"", status: int = 200) -> AuditEntry:
    return AuditEntry(
        at=datetime(2026, 12, 1, 12, 0, i % 60, tzinfo=UTC),
        key_name=f"k{i}",
        client="10.0.0.7",
        method="POST",
        path=f"/api/things/{i}",
        status=status,
        body=body,
        body_size=len(body),
    )


@pytest.mark.parametrize(
    ("body", "summary"),
    [
        (b"", ""),
        (b'{"yaw_deg": 10.5}', '{"yaw_deg":10.5}'),
        (
            b'{"name": "x", "api_key": "s3cret", "Token": 1, "nested": [{"password": "p"}]}',
            f'{{"name":"x","api_key":"{REDACTED}","Token":"{REDACTED}",'
            f'"nested":[{{"password":"{REDACTED}"}}]}}',
        ),
        (
            b'{"client_secret": {"a": 1}, "keys": ["k"]}',
            f'{{"client_secret":"{REDACTED}","keys":"{REDACTED}"}}',
        ),
        (b"not json at all", "<15 bytes, not JSON>"),
        (b"\xff\xfe", "<2 bytes, not JSON>"),
    ],
)
def test_body_summary_redacts_every_secret_looking_field(body, summary):
    assert body_summary(body) == summary


def test_a_long_body_is_cut_and_a_huge_one_only_sized():
    doc = {"name": "grid", "setpoints": [{"yaw_deg": float(i)} for i in range(200)]}
    text = body_summary(json.dumps(doc).encode())
    assert len(text) == SUMMARY_CHARS and text.endswith("...")
    assert text.startswith('{"name":"grid","setpoints":[{"yaw_deg":0.0}')
    assert body_summary(b'{"a": 1', size=2_000_000) == "<2000000 bytes, not shown>"


def test_entries_are_written_in_order_and_read_newest_first(sessions):
    audit = AuditService(sessions, batch=7)
    audit.start()
    for i in range(1, 31):
        audit.record(_entry(i, b'{"token": "abc", "yaw_deg": 1}', status=200 + i))
    audit.stop()  # writes what is queued first
    assert audit.written == 30 and audit.dropped == 0
    page = audit.entries(limit=10)
    assert [e.path for e in page] == [f"/api/things/{i}" for i in range(30, 20, -1)]
    assert page[0].body == f'{{"token":"{REDACTED}","yaw_deg":1}}'
    assert (page[0].key_name, page[0].client, page[0].method, page[0].status) == (
        "k30",
        "10.0.0.7",
        "POST",
        230,
    )
    older = audit.entries(limit=10, before_id=page[-1].id)
    assert [e.path for e in older] == [f"/api/things/{i}" for i in range(20, 10, -1)]
    assert [e.id for e in audit.entries(limit=1000)] == list(range(30, 0, -1))


def test_a_full_queue_drops_entries_instead_of_blocking(sessions):
    """The writer is not started: the queue fills and ``record`` returns at once,
    counting what it could not keep."""
    audit = AuditService(sessions, max_queue=5)
    done = threading.Event()

    def flood():
        for i in range(50):
            audit.record(_entry(i))
        done.set()

    threading.Thread(target=flood).start()
    assert done.wait(30.0)
    assert audit.dropped == 45
    audit.start()
    audit.stop()
    assert audit.written == 5


def test_a_database_that_fails_loses_those_entries_not_the_writer(sessions, tmp_path):
    audit = AuditService(sessions)
    audit.start()
    good = sessions.kw["bind"]
    sessions.configure(bind=make_engine("sqlite:////nonexistent/dir/db.sqlite"))
    audit.record(_entry(1))
    assert audit.flush()
    assert audit.dropped == 1
    sessions.configure(bind=good)
    audit.record(_entry(2))
    audit.stop()
    assert [e.path for e in audit.entries()] == ["/api/things/2"]


def test_keys_and_audit_entries_round_trip_on_every_database(tmp_path, database_url):
    """On SQLite and on PostgreSQL (the migration's tables, timezone-aware times)."""
    from backend.services.keys import KeyService, Scope

    engine = make_engine(database_url or f"sqlite:///{tmp_path / 'rt.db'}")
    upgrade_database(engine)
    sessions = make_session_factory(engine)
    keys = KeyService(sessions)
    assert keys.bootstrap(tmp_path, "configured-0123456789").source == "configured"
    key = keys.create("ops", "operate")
    assert KeyService(sessions).bootstrap(tmp_path, None).source == "database"
    fresh = KeyService(sessions)
    fresh.reload()
    assert fresh.verify(key).scope is Scope.OPERATE
    assert fresh.verify("configured-0123456789").name == "admin"
    audit = AuditService(sessions)
    audit.start()
    audit.record(_entry(5, b'{"password": "x"}', status=403))
    audit.stop()
    (got,) = audit.entries()
    assert (got.key_name, got.status, got.body) == ("k5", 403, f'{{"password":"{REDACTED}"}}')
    at = got.at if got.at.tzinfo else got.at.replace(tzinfo=UTC)  # SQLite: naive, in UTC
    assert at == datetime(2026, 12, 1, 12, 0, 5, tzinfo=UTC)
    engine.dispose()


def test_a_body_nested_too_deep_or_with_nul_is_summarised_not_fatal():
    """A keyless client's hostile bodies: JSON nested deeper than Python recurses, and NUL
    characters (PostgreSQL's text refuses them), are summarised without raising."""
    from backend.services.audit import body_summary

    deep = b"[" * 3000 + b"]" * 3000
    assert body_summary(deep) == f"<{len(deep)} bytes, not JSON>"
    assert "\x00" not in body_summary(b'{"name": "a\\u0000b"}')
    assert body_summary(b'{"name": "a\\u0000b"}') == '{"name":"a\\u0000b"}'
