"""``tofpose serve``: build the app from settings + command-line overrides and run it."""

from __future__ import annotations

import sys

from pydantic import SecretStr, ValidationError

from backend.auth import TOKEN_FILE, load_or_create_token
from backend.settings import Settings
from tofpose.recording import RecordingError


def token_line(settings: Settings, token: str, created: bool) -> str:
    """How the banner names the API token: in clear only on the start that generated it,
    so that the token of a long-lived data directory does not land in every log."""
    path = settings.data_dir / TOKEN_FILE
    if created:
        return f"{token}   (generated now and stored in {path}; printed only this once)"
    if settings.api_token:
        return "from TOFPOSE_API_TOKEN (not printed)"
    return f"stored in {path} (not printed: cat it)"


def scene_line(settings: Settings, host: str) -> str:
    if settings.scene_refusal is not None:
        return settings.scene_refusal
    if settings.viser_port == 0:
        return "viser on any free port (GET /api/scene names it)"
    return (f"http://{host}:{settings.viser_port}/   (viser; if the port is taken, the next "
            "free one: GET /api/scene)")  # fmt: skip


def foxglove_line(settings: Settings, host: str) -> str:
    if settings.foxglove_refusal is not None:
        return settings.foxglove_refusal
    if settings.foxglove_port == 0:
        return "Foxglove WebSocket on any free port (GET /api/foxglove names it)"
    return f"ws://{host}:{settings.foxglove_port}   (Foxglove app: Open connection)"


def banner(settings: Settings, token: str, created: bool) -> str:
    host = settings.host if ":" not in settings.host else f"[{settings.host}]"
    base = f"http://{host}:{settings.port}"
    camera = "simulated ToF camera" if settings.camera == "sim" else settings.camera
    motion = {"sim": "simulated turntable + rail", "none": "no motion system"}.get(
        settings.motion, settings.motion
    )
    reads = "open (loopback)" if settings.reads_are_open else "token required"
    return "\n".join([
        f"tofpose server: {camera}, {motion}",
        f"  dashboard      {base}/"
        + ("" if (settings.frontend_dist / "index.html").exists() else "   (not built: make run)"),
        f"  API docs       {base}/docs   (OpenAPI: {base}/openapi.json)",
        f"  live pose      ws://{host}:{settings.port}/ws/live",
        f"  health         {base}/api/health",
        f"  3-D scene      {scene_line(settings, host)}",
        f"  Foxglove       {foxglove_line(settings, host)}",
        f"  database       {settings.resolved_database_url}",
        f"  API token      {token_line(settings, token, created)}",
        f"  reads          {reads}; moves and changes need 'Authorization: Bearer <token>'",
    ])  # fmt: skip


def serve(overrides: dict) -> int:
    """Run uvicorn until interrupted; returns a process exit code."""
    import uvicorn

    from backend.app import create_app
    from backend.drivers.base import CameraError, MotionError
    from backend.drivers.factory import build_devices

    try:
        settings = Settings(**{k: v for k, v in overrides.items() if v is not None})
    except ValidationError as exc:
        msgs = "; ".join(f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in exc.errors())
        print(f"tofpose serve: bad settings: {msgs}", file=sys.stderr)
        return 2
    settings.data_dir.mkdir(parents=True, exist_ok=True)
    configured = settings.api_token.get_secret_value() if settings.api_token else None
    token, created = load_or_create_token(settings.data_dir, configured)
    text = banner(settings, token, created)
    settings = settings.model_copy(update={"api_token": SecretStr(token)})
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
    uvicorn.run(
        app, host=settings.host, port=settings.port, log_level="info",
        timeout_graceful_shutdown=settings.shutdown_timeout_s,
    )  # fmt: skip
    return 0


def report(opts: dict) -> int:
    """``tofpose report``: a campaign's report from a database, without a server."""
    from sqlalchemy.exc import SQLAlchemyError

    from backend.db.engine import make_engine, make_session_factory
    from backend.db.models import CampaignRow
    from backend.services.reports import ReportError, build, to_csv, to_html, to_json, to_pdf

    try:
        engine = make_engine(opts["db"])
        with make_session_factory(engine)() as session:
            if session.get(CampaignRow, opts["campaign_id"]) is None:
                print(f"tofpose report: no campaign with id {opts['campaign_id']} in "
                      f"{opts['db']}", file=sys.stderr)  # fmt: skip
                return 2
            rep, rows = build(session, opts["campaign_id"], opts["reference"])
    except ReportError as exc:
        print(f"tofpose report: {exc}", file=sys.stderr)
        return 2
    except SQLAlchemyError as exc:
        print(f"tofpose report: cannot read {opts['db']}: {exc.__class__.__name__}: "
              f"{str(exc).splitlines()[0]}", file=sys.stderr)  # fmt: skip
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
    print(f"campaign {opts['campaign_id']}: {rep['n_frames']} frames, reference "
          f"{opts['reference']} -> {opts['out']}")  # fmt: skip
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
