"""The audit trail: every state-changing request (POST, PUT, PATCH, DELETE), answered or
refused, stored in the ``audit_log`` table.

The web server's event loop only hands an ``AuditEntry`` (with the raw body bytes) to
``AuditService.record``, which puts it on a bounded queue and never blocks or raises;
a writer thread summarises the bodies (``body_summary``: at most ``SUMMARY_CHARS``
characters of the JSON, every field whose name contains token, key, secret or password
redacted) and inserts the rows in batches. When the queue is full (a flood of requests
faster than the database takes them) entries are dropped and counted (``dropped``,
logged): the audit never delays or fails a request.
"""

from __future__ import annotations

import json
import logging
import queue
import threading
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from backend.db.models import AuditRow

log = logging.getLogger("tofpose.audit")

AUDITED_METHODS = frozenset({"POST", "PUT", "PATCH", "DELETE"})
KEY_NAME_STATE = "tofpose_key_name"
"""Where the auth dependency leaves the name of the key that made a request, in the ASGI
scope's ``state`` (``request.state.tofpose_key_name``), for the audit middleware."""
SUMMARY_CHARS = 300
BODY_BYTES_KEPT = 65_536
"""Bodies longer than this are summarised by their size only (not parsed)."""
SECRET_FIELD_PARTS = ("token", "key", "secret", "password")
REDACTED = "***"
MAX_LIMIT = 1000


@dataclass(frozen=True)
class AuditEntry:
    """One request as the middleware saw it; ``body`` is the raw request body (at most
    ``BODY_BYTES_KEPT`` bytes of it) and ``body_size`` its full length."""

    at: datetime
    key_name: str | None
    client: str
    method: str
    path: str
    status: int
    body: bytes = b""
    body_size: int = 0


@dataclass(frozen=True)
class AuditRecord:
    """A stored audit entry."""

    id: int
    at: datetime
    key_name: str | None
    client: str
    method: str
    path: str
    body: str
    status: int


def _redacted(value: Any) -> Any:
    if isinstance(value, dict):
        return {
            k: REDACTED if any(p in str(k).lower() for p in SECRET_FIELD_PARTS) else _redacted(v)
            for k, v in value.items()
        }
    if isinstance(value, list):
        return [_redacted(v) for v in value]
    return value


def body_summary(body: bytes, size: int | None = None) -> str:
    """What the audit trail keeps of a request body: its JSON with secret-looking fields
    redacted, compact, cut to ``SUMMARY_CHARS`` characters (ending in "..." when cut);
    for a body that is not JSON (or too long to parse) only its size."""
    size = len(body) if size is None else size
    if size == 0:
        return ""
    if size > len(body):
        return f"<{size} bytes, not shown>"
    try:
        doc = json.loads(body)
        text = json.dumps(_redacted(doc), separators=(",", ":"), ensure_ascii=False)
    except (ValueError, RecursionError):  # not JSON, or nested deeper than Python recurses
        return f"<{size} bytes, not JSON>"
    text = _text_safe(text)
    return text if len(text) <= SUMMARY_CHARS else text[: SUMMARY_CHARS - 3] + "..."


def _text_safe(text: str) -> str:
    """Without NUL characters, which PostgreSQL's text type refuses (one such request
    would otherwise fail its whole batch)."""
    return text.replace("\x00", "\\u0000")


def _row(entry: AuditEntry) -> AuditRow:
    return AuditRow(
        at=entry.at,
        key_name=entry.key_name,
        client=_text_safe(entry.client[:64]),
        method=_text_safe(entry.method[:8]),
        path=_text_safe(entry.path),
        body=body_summary(entry.body, entry.body_size),
        status=entry.status,
    )


def _record(row: AuditRow) -> AuditRecord:
    return AuditRecord(
        row.id, row.at, row.key_name, row.client, row.method, row.path, row.body, row.status
    )


_STOP = object()


class AuditService:
    """The audit writer thread and the audit trail's reads."""

    def __init__(
        self, sessions: sessionmaker[Session], *, max_queue: int = 10_000, batch: int = 200
    ) -> None:
        self._sessions = sessions
        self._queue: queue.Queue[Any] = queue.Queue(max_queue)
        self._batch = batch
        self._thread: threading.Thread | None = None
        self.dropped = 0
        self.written = 0

    def start(self) -> None:
        self._thread = threading.Thread(target=self._write_loop, name="audit-writer", daemon=True)
        self._thread.start()

    def stop(self, timeout_s: float = 10.0) -> None:
        """Write what is queued, then end the writer thread."""
        if self._thread is None:
            return
        try:
            self._queue.put(_STOP, timeout=timeout_s)
        except queue.Full:
            log.error("audit queue still full at shutdown: its entries are lost")
        self._thread.join(timeout_s)
        self._thread = None

    def record(self, entry: AuditEntry) -> None:
        """Queue an entry for the writer; never blocks, never raises."""
        try:
            self._queue.put_nowait(entry)
        except queue.Full:
            self.dropped += 1
            if self.dropped in (1, 10, 100) or self.dropped % 1000 == 0:
                log.error("audit queue full: %d entries dropped so far", self.dropped)

    def flush(self, timeout_s: float = 10.0) -> bool:
        """Wait until every entry queued so far is stored (tests, shutdown)."""
        done = threading.Event()
        try:
            self._queue.put(done, timeout=timeout_s)
        except queue.Full:
            return False
        return done.wait(timeout_s)

    def _write_loop(self) -> None:
        while True:
            items = [self._queue.get()]
            while len(items) < self._batch:
                try:
                    items.append(self._queue.get_nowait())
                except queue.Empty:
                    break
            entries = [i for i in items if isinstance(i, AuditEntry)]
            if entries:
                self._write(entries)
            for item in items:
                if isinstance(item, threading.Event):
                    item.set()
            if any(item is _STOP for item in items):
                return

    def _write(self, entries: list[AuditEntry]) -> None:
        """Store a batch; when the batch fails, each entry alone, so that one entry the
        database refuses costs only itself."""
        try:
            self._store(entries)
        except Exception:  # noqa: BLE001 - the audit must not take the server down
            for entry in entries:
                try:
                    self._store([entry])
                except Exception as exc:  # noqa: BLE001
                    self.dropped += 1
                    log.error(
                        "an audit entry (%s %s) was not stored: %s",
                        entry.method,
                        entry.path[:100],
                        exc,
                    )

    def _store(self, entries: list[AuditEntry]) -> None:
        with self._sessions() as session:
            session.add_all([_row(e) for e in entries])
            session.commit()
        self.written += len(entries)

    def entries(self, limit: int = 100, before_id: int | None = None) -> list[AuditRecord]:
        """Stored entries, newest first: at most ``limit``, with ids below ``before_id``
        when given (the next page: the last id of this one)."""
        limit = max(1, min(limit, MAX_LIMIT))
        query = select(AuditRow).order_by(AuditRow.id.desc()).limit(limit)
        if before_id is not None:
            query = query.where(AuditRow.id < before_id)
        with self._sessions() as session:
            return [_record(r) for r in session.scalars(query).all()]
