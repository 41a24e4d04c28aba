"""``tofpose serve``: build the app from settings + command-line overrides and run it;
``tofpose report`` and ``tofpose keys`` (backend/keys_cli.py) on the same settings;
``tofpose record`` (backend/record_cli.py) against a running server."""

from __future__ import annotations

import logging
import re
import sys

from pydantic import SecretStr, ValidationError

from backend.auth import TOKEN_FILE
from backend.services.keys import Bootstrap
from backend.settings import Settings
from tofpose.io.recording import RecordingError

SECRET_QUERY = re.compile(r"([?&][^=&\s]*(?:token|key|ticket)[^=&\s]*=)[^&\s\"']*", re.IGNORECASE)
REDACTED = "***"


class RedactSecretQuery(logging.Filter):
    """Redact the value of every query parameter whose name contains token, key or ticket
    (``token``, ``api_key``, ...) in a log record (uvicorn's access log and its WebSocket
    lines print the path with its query string). Defence in depth: the server takes no
    key in a URL, but a client may still send one."""

    def filter(self, record: logging.LogRecord) -> bool:
        if isinstance(record.msg, str):
            record.msg = SECRET_QUERY.sub(rf"\g<1>{REDACTED}", record.msg)
        if isinstance(record.args, tuple):
            record.args = tuple(
                SECRET_QUERY.sub(rf"\g<1>{REDACTED}", a) if isinstance(a, str) else a
                for a in record.args
            )
        return True


def install_log_redaction() -> None:
    """The filter on uvicorn's loggers: ``uvicorn.access`` (HTTP requests) and
    ``uvicorn.error`` (which logs each WebSocket handshake with its URL)."""
    for name in ("uvicorn.access", "uvicorn.error"):
        logger = logging.getLogger(name)
        if not any(isinstance(f, RedactSecretQuery) for f in logger.filters):
            logger.addFilter(RedactSecretQuery())


def token_line(settings: Settings, boot: Bootstrap) -> str:
    """How the banner names the admin key: in clear only on the start that generated it,
    so that the key of a long-lived data directory does not land in every log."""
    path = settings.data_dir / TOKEN_FILE
    if boot.source == "generated":
        return f"{boot.shown}   (admin; generated now and stored in {path}; printed only this once)"
    if boot.source == "configured" or (boot.source == "database" and settings.api_token):
        return "admin key from TOFPOSE_API_TOKEN (not printed)"
    if boot.source == "file" or path.exists():
        return f"admin key of the first start in {path} (not printed: cat it); tofpose keys list"
    return "in the database (not printed): tofpose keys list / tofpose keys create"


def scene_line(settings: Settings, host: str) -> str:
    if settings.scene_refusal is not None:
        return settings.scene_refusal
    if settings.viser_port == 0:
        return "viser on any free port (GET /api/scene names it)"
    return (
        f"http://{host}:{settings.viser_port}/   (viser; if the port is taken, the next "
        "free one: GET /api/scene)"
    )


def foxglove_line(settings: Settings, host: str) -> str:
    if settings.foxglove_refusal is not None:
        return settings.foxglove_refusal
    if settings.foxglove_port == 0:
        return "Foxglove WebSocket on any free port (GET /api/foxglove names it)"
    return f"ws://{host}:{settings.foxglove_port}   (Foxglove app: Open connection)"


def banner(settings: Settings, boot: Bootstrap) -> str:
    host = settings.host if ":" not in settings.host else f"[{settings.host}]"
    base = f"http://{host}:{settings.port}"
    camera = "simulated ToF camera" if settings.camera == "sim" else settings.camera
    motion = {"sim": "simulated turntable + rail", "none": "no motion system"}.get(
        settings.motion, settings.motion
    )
    reads = "open (loopback)" if settings.reads_are_open else "API key (any scope) required"
    return "\n".join(
        [
            f"tofpose server: {camera}, {motion}",
            f"  dashboard      {base}/"
            + (
                ""
                if (settings.frontend_dist / "index.html").exists()
                else "   (not built: make run)"
            ),
            f"  API docs       {base}/docs   (OpenAPI: {base}/openapi.json)",
            f"  live pose      ws://{host}:{settings.port}/ws/live",
            f"  health         {base}/api/health",
            f"  3-D scene      {scene_line(settings, host)}",
            f"  Foxglove       {foxglove_line(settings, host)}",
            f"  database       {settings.resolved_database_url}",
            f"  API key        {token_line(settings, boot)}",
            f"  reads          {reads}; moves and changes need 'Authorization: Bearer <key>' "
            "(scope operate or admin)",
        ]
    )


def serve(overrides: dict) -> int:
    """Run uvicorn until interrupted; returns a process exit code."""
    import uvicorn
    from sqlalchemy.exc import SQLAlchemyError

    from backend.app import create_app
    from backend.drivers.base import CameraError, MotionError
    from backend.drivers.factory import build_devices

    try:
        settings = Settings(**{k: v for k, v in overrides.items() if v is not None})
    except ValidationError as exc:
        msgs = "; ".join(f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in exc.errors())
        print(f"tofpose serve: bad settings: {msgs}", file=sys.stderr)
        return 2
    try:
        boot = bootstrap_keys(settings)
    except SQLAlchemyError as exc:
        print(
            f"tofpose serve: cannot open the database {settings.resolved_database_url}: "
            f"{exc.__class__.__name__}: {str(exc).splitlines()[0]}",
            file=sys.stderr,
        )
        return 2
    text = banner(settings, boot)
    try:
        devices = build_devices(settings)
    except RecordingError as exc:
        print(f"tofpose serve: cannot replay: {exc}", file=sys.stderr)
        return 2
    except (CameraError, MotionError) as exc:
        print(f"tofpose serve: {exc}", file=sys.stderr)
        return 2
    app = create_app(settings, devices)
    print(text, flush=True)
    # After SIGTERM/SIGINT, connections get shutdown_timeout_s to close; then their tasks
    # are cancelled and the app shuts down anyway (a WebSocket client that never reads
    # cannot keep the server alive: its socket's write buffer never drains).
    # No permessage-deflate on WebSockets: it compresses every message once per client,
    # on the event loop (15 ms for a full-size raw frame, 40 us for a pose), so that a
    # few dashboards would delay STOP; uncompressed, a frame's bytes are built once for
    # all clients (LiveSample.cached) and each send is a copy into the socket.
    install_log_redaction()  # uvicorn's logging set-up keeps a logger's filters
    uvicorn.run(
        app,
        host=settings.host,
        port=settings.port,
        log_level="info",
        # typed int by uvicorn, which waits with asyncio.wait_for: seconds as a float work
        timeout_graceful_shutdown=settings.shutdown_timeout_s,  # type: ignore[arg-type]
        ws_per_message_deflate=False,
    )
    return 0


def bootstrap_keys(settings: Settings) -> Bootstrap:
    """Before the server starts: the database migrated and, on its first start, the
    admin key stored (backend/services/keys.py), so that the banner can say where the key
    is. The app's lifespan runs the same bootstrap again (then a no-op)."""
    from backend.db.engine import make_engine, make_session_factory, upgrade_database
    from backend.file_modes import restrict_data_dir
    from backend.services.keys import KeyService

    settings.data_dir.mkdir(parents=True, exist_ok=True)
    restrict_data_dir(settings.data_dir)
    engine = make_engine(settings.resolved_database_url)
    try:
        upgrade_database(engine)
        configured = settings.api_token.get_secret_value() if settings.api_token else None
        return KeyService(make_session_factory(engine)).bootstrap(settings.data_dir, configured)
    finally:
        engine.dispose()


def keys(opts: dict) -> int:
    """``tofpose keys create|list|revoke`` (backend/keys_cli.py)."""
    from backend import keys_cli

    return keys_cli.run(opts)


def record(opts: dict) -> int:
    """``tofpose record`` against a running server (backend/record_cli.py)."""
    from backend import record_cli

    return record_cli.run(opts)


def report(opts: dict) -> int:
    """``tofpose report``: a campaign's report from a database, without a server."""
    from sqlalchemy.exc import SQLAlchemyError

    from backend.db.engine import make_engine, make_session_factory
    from backend.db.models import CampaignRow
    from backend.services.calibrations import get_calibration
    from backend.services.reports.reports import (
        ReportError,
        build,
        to_csv,
        to_html,
        to_json,
        to_pdf,
    )

    try:
        engine = make_engine(opts["db"])
        with make_session_factory(engine)() as session:
            if session.get(CampaignRow, opts["campaign_id"]) is None:
                print(
                    f"tofpose report: no campaign with id {opts['campaign_id']} in {opts['db']}",
                    file=sys.stderr,
                )
                return 2
            cal = None
            if (cal_id := opts.get("calibration")) is not None:
                cal = get_calibration(session, cal_id)
                if cal is None:
                    print(
                        f"tofpose report: no calibration with id {cal_id} in {opts['db']} "
                        "(GET /api/calibrations lists them)",
                        file=sys.stderr,
                    )
                    return 2
            rep, rows = build(session, opts["campaign_id"], opts["reference"], cal)
    except ReportError as exc:
        print(f"tofpose report: {exc}", file=sys.stderr)
        return 2
    except SQLAlchemyError as exc:
        print(
            f"tofpose report: cannot read {opts['db']}: {exc.__class__.__name__}: "
            f"{str(exc).splitlines()[0]}",
            file=sys.stderr,
        )
        return 2
    fmt = opts["format"]
    writers = {
        "csv": lambda: to_csv(rows),
        "json": lambda: to_json(rep),
        "html": lambda: to_html(rep, rows),
        "pdf": lambda: to_pdf(rep, rows),
    }
    body = writers[fmt]()
    mode = "wb" if isinstance(body, bytes) else "w"
    with open(opts["out"], mode) as fh:
        fh.write(body)
    ref = (
        f"calibration {opts['calibration']}"
        if opts.get("calibration") is not None
        else opts["reference"]
    )
    print(
        f"campaign {opts['campaign_id']}: {rep['n_frames']} frames, reference {ref} -> "
        f"{opts['out']}"
    )
    return 0


def openapi_document() -> dict:
    """The OpenAPI document of a server on the simulated devices (what the dashboard's
    TypeScript types are generated from; soft limits are the simulated lab's)."""
    import asyncio
    import tempfile
    from concurrent.futures import ThreadPoolExecutor
    from pathlib import Path

    from backend.app import create_app

    async def run() -> dict:
        with tempfile.TemporaryDirectory() as tmp:
            settings = Settings(data_dir=Path(tmp), api_token=SecretStr("x" * 32), viser=False)
            app = create_app(settings)
            async with app.router.lifespan_context(app):
                return app.openapi()

    # In a thread of its own: the caller may already run an event loop (a test session
    # with a browser open, a notebook), where asyncio.run would refuse.
    with ThreadPoolExecutor(1) as pool:
        return pool.submit(asyncio.run, run()).result()


def write_openapi(out: str) -> int:
    """``tofpose openapi --out FILE``."""
    import json

    doc = openapi_document()
    with open(out, "w") as fh:
        json.dump(doc, fh, indent=1, sort_keys=True)
        fh.write("\n")
    print(f"{len(doc['paths'])} paths -> {out}")
    return 0
