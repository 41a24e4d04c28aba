"""``tofpose keys create NAME --scope read|operate|admin``, ``tofpose keys list``,
``tofpose keys revoke NAME``: the API keys of a data directory's database, with the
settings ``tofpose serve`` reads (``TOFPOSE_*``, ``--data-dir``, ``--db``).

Works beside a running server: it re-reads the keys every few seconds
(``KeyService.refresh_s``), so a key made or revoked here counts there within that time.
"""

from __future__ import annotations

import sys
from datetime import UTC, datetime

from pydantic import ValidationError
from sqlalchemy.exc import SQLAlchemyError

from backend.db.engine import make_engine, make_session_factory, upgrade_database
from backend.file_modes import restrict_data_dir
from backend.services.keys import ApiKey, KeyNameTakenError, KeyNotFoundError, KeyService
from backend.settings import Settings


def _when(t: datetime | None) -> str:
    if t is None:
        return "-"
    t = t if t.tzinfo is not None else t.replace(tzinfo=UTC)  # SQLite: stored in UTC
    return t.astimezone(UTC).strftime("%Y-%m-%d %H:%M:%SZ")


def key_table(keys: list[ApiKey]) -> str:
    """The keys as a text table: name, scope, created, revoked."""
    rows = [("NAME", "SCOPE", "CREATED (UTC)", "REVOKED (UTC)")]
    rows += [(k.name, k.scope.label, _when(k.created_at), _when(k.revoked_at)) for k in keys]
    widths = [max(len(r[i]) for r in rows) for i in range(4)]
    return "\n".join(
        "  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in rows
    )


def _command(service: KeyService, opts: dict) -> int:
    action = opts["action"]
    if action == "create":
        key = service.create(opts["name"], opts["scope"])
        print(
            f"key {opts['name']!r} created, scope {opts['scope']}. The key, shown this once "
            "(only its hash is stored):"
        )
        print(key)
    elif action == "list":
        keys = service.list()
        print(key_table(keys) if keys else "no keys yet (the server's first start makes one)")
    else:
        service.revoke(opts["name"])
        print(
            f"key {opts['name']!r} revoked (a running server stops taking it within "
            f"{service.refresh_s:g} s)"
        )
    return 0


def run(opts: dict) -> int:
    """Run ``opts["action"]`` (create, list or revoke); returns a process exit code."""
    overrides = {k: opts.get(k) for k in ("data_dir", "database_url")}
    try:
        settings = Settings(**{k: v for k, v in overrides.items() if v is not None})
    except ValidationError as exc:
        msgs = "; ".join(f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in exc.errors())
        print(f"tofpose keys: bad settings: {msgs}", file=sys.stderr)
        return 2
    url = settings.resolved_database_url
    try:
        settings.data_dir.mkdir(parents=True, exist_ok=True)
        restrict_data_dir(settings.data_dir)
        engine = make_engine(url)
        try:
            upgrade_database(engine)
            return _command(KeyService(make_session_factory(engine)), opts)
        finally:
            engine.dispose()
    except (ValueError, KeyNameTakenError, KeyNotFoundError) as exc:
        print(f"tofpose keys: {exc}", file=sys.stderr)
        return 2
    except (SQLAlchemyError, OSError) as exc:
        print(
            f"tofpose keys: cannot use the database {url}: {exc.__class__.__name__}: "
            f"{str(exc).splitlines()[0]}",
            file=sys.stderr,
        )
        return 2
