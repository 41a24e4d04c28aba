"""Scoped API keys: created, listed and revoked in the database, verified in memory.

A key is ``secrets.token_urlsafe(32)`` (256 random bits), shown once when it is created;
the database keeps its SHA-256 only. A slow password hash (bcrypt, scrypt, Argon2) is
made for low-entropy secrets that an attacker holding the hashes could guess; nobody can
enumerate 2**256 keys, so a plain SHA-256 is as strong here and costs microseconds.

Scopes are ordered, each including the ones below it: ``read`` (live data, reports),
``operate`` (every state change: moves, campaigns, camera settings, ...), ``admin``
(keys, the audit trail, deletions).

``verify`` never touches the database: it compares the key's hash with every active
key's in constant time (no early exit) against a copy of the table held in memory. The
copy is refreshed after each change made through this service and, for changes made by
another process (``tofpose keys`` next to a running server), every ``refresh_s`` by a
background thread (``start``/``stop``).
"""

from __future__ import annotations

import hashlib
import logging
import re
import secrets
import threading
from dataclasses import dataclass
from datetime import datetime
from enum import IntEnum
from pathlib import Path

from sqlalchemy import select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session, sessionmaker

from backend.auth import load_or_create_token
from backend.db.models import ApiKeyRow, utcnow

log = logging.getLogger("tofpose.keys")

BOOTSTRAP_NAME = "admin"
"""The key the first start stores: the configured token, or the one in data/api_token."""
CONFIGURED_NAME = "TOFPOSE_API_TOKEN"
"""How a configured token is named when it is not (or no longer) a stored key."""
KEY_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._@-]{0,63}")


class Scope(IntEnum):
    """What a key may do; a higher scope includes every lower one."""

    READ = 1
    OPERATE = 2
    ADMIN = 3

    @property
    def label(self) -> str:
        return self.name.lower()

    @classmethod
    def parse(cls, text: str) -> Scope:
        try:
            return cls[text.upper()]
        except KeyError:
            raise ValueError(f"scope must be read, operate or admin, got {text!r}") from None


SCOPE_NAMES = tuple(s.label for s in Scope)


@dataclass(frozen=True)
class ApiKey:
    """A key as the server knows it (never the key itself)."""

    name: str
    scope: Scope
    created_at: datetime | None
    revoked_at: datetime | None = None

    def allows(self, needed: Scope) -> bool:
        return self.revoked_at is None and self.scope >= needed


class KeyNameTakenError(ValueError):
    """A key (active or revoked) already has this name."""


class KeyNotFoundError(LookupError):
    """No active key has this name."""


def key_hash(key: str) -> str:
    """The SHA-256 of a key, hex (what the database stores)."""
    return hashlib.sha256(key.encode()).hexdigest()


def _record(row: ApiKeyRow) -> ApiKey:
    return ApiKey(row.name, Scope.parse(row.scope), row.created_at, row.revoked_at)


@dataclass(frozen=True)
class Bootstrap:
    """What the first key check at start found.

    shown : the key to print in the start banner (one generated now), else None.
    source : where the bootstrap admin key comes from: "generated" (now, into
        ``data_dir/api_token``), "file" (``data_dir/api_token``), "configured"
        (TOFPOSE_API_TOKEN) or "database" (keys exist already; none was added).
    """

    shown: str | None
    source: str


class KeyService:
    """API keys in the ``api_keys`` table, verified against an in-memory copy."""

    def __init__(self, sessions: sessionmaker[Session], *, refresh_s: float = 5.0) -> None:
        self._sessions = sessions
        self.refresh_s = refresh_s
        self._active: tuple[tuple[bytes, ApiKey], ...] = ()
        self._configured: tuple[bytes, ApiKey] | None = None
        self._lock = threading.Lock()  # one reload at a time
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # -- start-up ----------------------------------------------------------------------

    def bootstrap(self, data_dir: Path, configured: str | None) -> Bootstrap:
        """Make sure an admin key exists: when the table has never held one (the first
        start, or the first since keys came in), store the configured token, or else the
        one in ``data_dir/api_token`` (generated there if missing), as the admin key named
        ``admin``. A revoked admin key counts: revoking every admin key and restarting
        does not bring the old token back. A configured token also stays an admin key
        while it is configured, even if the stored one was revoked (the operator who sets
        the environment has the machine anyway); to retire it, unset TOFPOSE_API_TOKEN."""
        source = "database"
        shown = None
        with self._sessions() as session:
            empty = (
                session.scalar(
                    select(ApiKeyRow.id).where(ApiKeyRow.scope == Scope.ADMIN.label).limit(1)
                )
                is None
            )
        if empty:
            if configured:
                token, source = configured, "configured"
            else:
                token, created = load_or_create_token(data_dir, None)
                source = "generated" if created else "file"
                shown = token if created else None
            with self._sessions() as session:
                session.add(
                    ApiKeyRow(
                        name=BOOTSTRAP_NAME, scope=Scope.ADMIN.label, key_sha256=key_hash(token)
                    )
                )
                try:
                    session.commit()
                except IntegrityError:  # another process bootstrapped at the same moment
                    session.rollback()
        if configured:
            self._configured = (
                key_hash(configured).encode(),
                ApiKey(CONFIGURED_NAME, Scope.ADMIN, None),
            )
        self.reload()
        return Bootstrap(shown, source)

    def start(self) -> None:
        """Refresh the in-memory copy every ``refresh_s`` (changes by other processes)."""
        self._stop.clear()
        self._thread = threading.Thread(target=self._refresh_loop, name="api-keys", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)
            self._thread = None

    def _refresh_loop(self) -> None:
        while not self._stop.wait(self.refresh_s):
            try:
                self.reload()
            except Exception as exc:  # noqa: BLE001 - the last good copy stays in use
                log.warning("API keys not reloaded: %s", exc)

    def reload(self) -> None:
        """Read the active keys into memory."""
        with self._lock, self._sessions() as session:
            rows = session.scalars(select(ApiKeyRow).where(ApiKeyRow.revoked_at.is_(None))).all()
            self._active = tuple((r.key_sha256.encode(), _record(r)) for r in rows)

    # -- verification (no database, no blocking) ---------------------------------------

    def verify(self, key: str | None) -> ApiKey | None:
        """The active key ``key`` is, or None. Compares its hash with every active key's
        hash in constant time and without an early exit."""
        if not key:
            return None
        given = key_hash(key).encode()
        found = None
        for stored, record in self._active:
            if secrets.compare_digest(stored, given):
                found = record
        if found is None and self._configured is not None:
            stored, record = self._configured
            if secrets.compare_digest(stored, given):
                found = record
        return found

    # -- management ---------------------------------------------------------------------

    def create(self, name: str, scope: Scope | str) -> str:
        """Store a new key named ``name`` with ``scope``; returns the key itself (shown
        once: only its hash is kept). ValueError for a bad name or scope,
        KeyNameTakenError when the name is taken (also by a revoked key)."""
        scope = scope if isinstance(scope, Scope) else Scope.parse(scope)
        if not KEY_NAME.fullmatch(name):
            raise ValueError(
                f"key name must be 1-64 letters, digits, '.', '_', '@' or '-' (starting with "
                f"a letter or digit), got {name!r}"
            )
        if name == CONFIGURED_NAME:  # the audit trail's name for the configured token
            raise KeyNameTakenError(
                f"the key name {name!r} is reserved for the token set in the server's environment"
            )
        key = secrets.token_urlsafe(32)
        with self._sessions() as session:
            if session.scalar(select(ApiKeyRow.id).where(ApiKeyRow.name == name)) is not None:
                raise KeyNameTakenError(_taken(name))
            session.add(ApiKeyRow(name=name, scope=scope.label, key_sha256=key_hash(key)))
            try:
                session.commit()
            except IntegrityError:  # a concurrent create took the name first
                session.rollback()
                raise KeyNameTakenError(_taken(name)) from None
        self.reload()
        return key

    def list(self) -> list[ApiKey]:
        """Every key, active and revoked, oldest first."""
        with self._sessions() as session:
            rows = session.scalars(select(ApiKeyRow).order_by(ApiKeyRow.id)).all()
            return [_record(r) for r in rows]

    def revoke(self, name: str) -> ApiKey:
        """Revoke the active key ``name`` (it stops working at once in this process, within
        ``refresh_s`` in a server that runs beside). KeyNotFoundError if there is none."""
        with self._sessions() as session:
            row = session.scalar(
                select(ApiKeyRow).where(ApiKeyRow.name == name, ApiKeyRow.revoked_at.is_(None))
            )
            if row is None:
                raise KeyNotFoundError(f"no active key named {name!r}")
            row.revoked_at = utcnow()
            session.commit()
            record = _record(row)
        self.reload()
        return record


def _taken(name: str) -> str:
    return (
        f"a key named {name!r} exists already (revoked keys keep their names, so that "
        "the audit trail's names stay unambiguous): choose another name"
    )
