"""The app factory. Nothing is built at import time: ``create_app(settings)`` returns an
app whose lifespan opens the database (migrating it), starts the devices and the
acquisition loop, and tears them down again."""

from __future__ import annotations

import asyncio
import logging
import math
import re
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import fields, replace

from fastapi import FastAPI, Request
from fastapi.exception_handlers import http_exception_handler
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, Response
from fastapi_offline import FastAPIOffline
from sqlalchemy.exc import IntegrityError
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.middleware.trustedhost import TrustedHostMiddleware

import backend
from backend.api.contract import complete_openapi, operation_id
from backend.api.deps import located
from backend.api.field_hints import fields_at, unknown_field_message
from backend.api.routes import audit as audit_route
from backend.api.routes import (
    calibrations,
    camera,
    campaigns,
    catalogs,
    dashboard,
    foxglove,
    frames,
    health,
    live,
    motion,
    pose,
    reference,
    scene,
)
from backend.api.routes import devices as devices_route
from backend.api.routes import recordings as recordings_route
from backend.api.routes import reprocessings as reprocessings_route
from backend.api.routes import studies as studies_route
from backend.api.routes import viewers as viewers_route
from backend.audit_middleware import AuditMiddleware
from backend.db.engine import make_engine, make_session_factory, upgrade_database
from backend.drivers.base import CameraSettings
from backend.drivers.factory import Devices, build_devices
from backend.file_modes import restrict_data_dir
from backend.limits import BodySizeLimit
from backend.services.audit import AuditService
from backend.services.campaigns.campaign_repository import CampaignNotFoundError
from backend.services.campaigns.campaign_states import CampaignConflictError
from backend.services.campaigns.campaigns import CampaignService
from backend.services.campaigns.mcap_files import ExportSpaceError
from backend.services.heavy_work import HeavyWorkBusyError
from backend.services.jobs.batch_queue import BatchQueue
from backend.services.jobs.reprocessing import (
    ReprocessRequestError,
    ReprocessService,
    UnknownReprocessingError,
)
from backend.services.jobs.studies import StudyService, TooManyStudiesError, UnknownStudyError
from backend.services.keys import KeyNameTakenError, KeyNotFoundError, KeyService
from backend.services.live.acquisition import AcquisitionService
from backend.services.live.hub import LiveHub
from backend.services.live.kernel_warmup import KernelWarmup
from backend.services.motion import (
    MotionConflictError,
    MotionDeviceError,
    MotionLimitError,
    MotionService,
)
from backend.services.recordings import (
    InsufficientSpaceError,
    RecordingConflictError,
    RecordingNotFoundError,
    RecordingService,
)
from backend.services.store import NameTakenError, find_catalog, load_device_settings
from backend.settings import Settings
from backend.state import AppState
from tofpose.config import PixelFitConfig, TrackingConfig
from tofpose.core.catalog import Catalog
from tofpose.lab.relative_state import RelativeStateConfig
from tofpose.pipeline import PipelineConfig

log = logging.getLogger("tofpose.server")


def _initial_catalog(state_sessions, settings: Settings, devices: Devices) -> tuple[str, Catalog]:
    """Stored choice > the replayed recording's own catalog > ``settings.catalog``."""
    with state_sessions() as session:
        stored = load_device_settings(session, "pipeline") or {}
        name = stored.get("catalog")
        if name and (cat := find_catalog(session, name)) is not None:
            return name, cat
        if devices.catalog_hint is not None:
            return f"recording:{devices.catalog_hint.name}", devices.catalog_hint
        cat = find_catalog(session, settings.catalog)
    if cat is None:
        raise ValueError(f"catalog {settings.catalog!r} is neither built in nor stored")
    return settings.catalog, cat


def _restore_camera_settings(sessions, devices: Devices) -> None:
    with sessions() as session:
        stored = load_device_settings(session, "camera")
    if not stored:
        return
    known = {f.name for f in fields(CameraSettings)}
    try:
        wanted = CameraSettings(**{k: v for k, v in stored.items() if k in known})
        devices.camera.apply_settings(wanted)
    except Exception as exc:  # a stale stored setting must not stop the server
        log.warning("stored camera settings not applied: %s", exc)


def _pipeline_config(devices: Devices, settings: Settings) -> PipelineConfig:
    """The pipeline's defaults, but for a camera that states its common range bias (the
    ideal simulated sensor has none), whose 1-sigma need not carry the default prior, and
    with tracking mode (a live stream: on by default) and the pixel-level fit (off by
    default) as the settings say."""
    cfg = PipelineConfig(
        tracking=TrackingConfig(enabled=settings.tracking),
        pixel_fit=PixelFitConfig(enabled=settings.pixel_fit),
    )
    bias = getattr(devices.camera, "range_bias_sigma_mm", None)
    return cfg if bias is None else replace(cfg, range_bias_sigma_mm=bias)


def _filter_config(settings: Settings) -> RelativeStateConfig:
    """The relative-state filter the settings ask for (docs/algorithm.md, "Relative
    state"): constant angular acceleration with their jerk density, or constant twist."""
    if settings.filter_model == "twist":
        return RelativeStateConfig()
    return RelativeStateConfig.constant_acceleration(
        angular_jerk_psd=math.radians(settings.filter_jerk_deg) ** 2
    )


def _start_scene(state: AppState) -> None:
    """Start the viser 3-D scene unless the settings refuse it; a scene that cannot start
    (port trouble) is logged and reported by ``GET /api/scene``, never fatal."""
    refusal = state.settings.scene_refusal
    if refusal is not None:
        state.scene_reason = refusal
        return
    from backend.services.live.scene import LiveScene

    rail = state.motion.axes.get("rail")
    s = state.settings
    try:
        # The scene's port answers the main port's names and origins only (its Host and
        # Origin check, backend/services/live/scene.py); the dashboard, on s.port, frames it.
        state.scene = LiveScene(
            state.hub,
            state.acquisition,
            host=s.host,
            port=s.viser_port,
            rail_length_mm=rail.max_pos if rail else None,
            trusted_hosts=s.trusted_hosts,
            allowed_origins=s.allowed_origins,
            dashboard_port=s.port or None,
        )
    except Exception as exc:  # noqa: BLE001 - any failure leaves the API running
        log.error("3-D scene not started: %s", exc)
        state.scene_reason = f"3-D scene failed to start: {exc}"


def _start_foxglove(state: AppState) -> None:
    """Start the live Foxglove server when the settings ask for it; one that cannot start
    (a taken port) is logged and reported by ``GET /api/foxglove``, never fatal."""
    refusal, port = state.settings.foxglove_refusal, state.settings.foxglove_port
    if refusal is not None:
        state.foxglove_reason = refusal
        return
    assert port is not None  # without one, foxglove_refusal says "off"
    from backend.services.live.foxglove_live import LiveFoxglove

    try:
        state.foxglove = LiveFoxglove(
            state.hub,
            state.acquisition,
            host=state.settings.host,
            port=port,
        )
    except Exception as exc:  # noqa: BLE001 - any failure leaves the API running
        log.error("Foxglove server not started: %s", exc)
        state.foxglove_reason = f"Foxglove server failed to start: {exc}"


HTTP_METHODS = {"get", "put", "post", "delete", "patch", "head", "options"}
AXIS_FIELDS = {"yaw": "yaw_deg", "pitch": "pitch_deg", "roll": "roll_deg", "rail": "rail_mm"}


def _soft_limits(app: FastAPI) -> dict[str, tuple[float, float]] | None:
    """Soft limits by request field once the app runs (None before: nothing known yet)."""
    state = getattr(app.state, "tofpose", None)
    if state is None:
        return None
    axes = state.motion.axes.values()
    return {AXIS_FIELDS[a.name]: (a.min_pos, a.max_pos) for a in axes if a.name in AXIS_FIELDS}


def methods_for_path(app: FastAPI, path: str) -> list[str]:
    """Every HTTP method the API document lists for this request path (sorted)."""
    methods: set[str] = set()
    for template, item in app.openapi().get("paths", {}).items():
        pattern = re.sub(r"\\\{[^}]+\\\}", "[^/]+", re.escape(template))
        if re.fullmatch(pattern, path):
            methods |= {m.upper() for m in item if m in HTTP_METHODS}
    return sorted(methods)


def _lifespan(settings: Settings, devices: Devices | None):
    """The app's lifespan: open the database (upgraded), the devices and every service,
    start them, and on shutdown stop them in order (a running campaign is left
    interrupted, a running batch job queued again)."""

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        settings.data_dir.mkdir(parents=True, exist_ok=True)
        restrict_data_dir(settings.data_dir)
        engine = make_engine(settings.resolved_database_url)
        upgrade_database(engine)
        sessions = make_session_factory(engine)
        # the API keys: the first start stores the configured token, or data/api_token's,
        # as the admin key (backend/services/keys.py)
        keys = KeyService(sessions)
        app.state.key_bootstrap = await asyncio.to_thread(
            keys.bootstrap,
            settings.data_dir,
            settings.api_token.get_secret_value() if settings.api_token else None,
        )
        keys.start()
        audit = AuditService(sessions)
        audit.start()
        devs = devices or build_devices(settings)
        _restore_camera_settings(sessions, devs)
        cat_name, cat = _initial_catalog(sessions, settings, devs)
        hub = LiveHub(settings.subscriber_queue)
        kernels = KernelWarmup()
        acq = AcquisitionService(
            devs.camera,
            cat,
            cat_name,
            hub,
            history_size=settings.history_size,
            timeout_s=settings.camera_timeout_s,
            backoff_s=settings.retry_backoff_s,
            pipeline_config=_pipeline_config(devs, settings),
            kernels=kernels,
            state_config=_filter_config(settings),
        )
        motion_service = MotionService(devs.motion)
        campaigns = CampaignService(
            sessions,
            acq,
            hub,
            motion_service,
            recordings_dir=settings.data_dir / "campaigns",
            lab_geometry=devs.lab_geometry,
        )
        interrupted, held = campaigns.recover()
        if interrupted or held:
            log.warning(
                "%d campaign(s) were running when the server stopped (interrupted) "
                "and %d were queued (paused): nothing moves until a person resumes "
                "them",
                interrupted,
                held,
            )
        # studies and re-processing share one queue: one batch job at a time on the cluster
        batch_jobs = BatchQueue()
        studies = StudyService(
            settings.data_dir / "studies",
            settings.dask_scheduler or None,
            settings.study_workers,
            jobs=batch_jobs,
        )
        reprocessings = ReprocessService(
            settings.data_dir / "reprocessings",
            settings.dask_scheduler or None,
            settings.study_workers,
            jobs=batch_jobs,
        )
        # recordings on demand: the live stream to HDF5 files, while a person wants it
        recordings = RecordingService(
            settings.data_dir / "recordings",
            hub,
            lambda: devs.camera.model,  # it follows the camera's settings
            lambda: acq.catalog,
            motion_service,
            min_free_mb=settings.recording_min_free_mb,
        )
        app.state.tofpose = AppState(
            settings,
            keys,
            audit,
            engine,
            sessions,
            devs,
            hub,
            acq,
            campaigns,
            studies,
            reprocessings,
            motion_service,
            recordings=recordings,
        )
        # the pipeline's compiled kernels (tofpose.warmup): in the background while frames
        # already stream (backend/services/live/kernel_warmup.py), or before the first frame
        if settings.kernels_in_background:
            kernels.start()
        else:
            await asyncio.to_thread(kernels.run)
        acq.start()
        campaigns.start()
        if studies.start():
            log.warning("studies queued or running when the server stopped: queued again")
        if reprocessings.start():
            log.warning("re-processings queued or running when the server stopped: queued again")
        batch_jobs.start()
        _start_scene(app.state.tofpose)
        _start_foxglove(app.state.tofpose)
        try:
            yield
        finally:
            if app.state.tofpose.scene is not None:
                app.state.tofpose.scene.close()
            if app.state.tofpose.foxglove is not None:
                app.state.tofpose.foxglove.close()
            campaigns.stop()  # a running campaign is left interrupted (resumable)
            recordings.stop_all()  # every recording's file closed, its entry saying why
            batch_jobs.stop()  # a running study or re-processing is queued again at the next start
            app.state.tofpose.renderer.close()
            acq.stop()
            devs.close()
            audit.stop()  # what is queued is written first
            keys.stop()
            engine.dispose()

    return lifespan


def _install_error_answers(app: FastAPI) -> None:
    """The answers to a bad body (422 without the echoed input), a method not allowed
    (405 listing every method of the path) and a conflict with stored data (409)."""

    @app.exception_handler(RequestValidationError)
    async def _validation_error(request: Request, exc: RequestValidationError) -> JSONResponse:
        # FastAPI's default, minus the echoed input (which can be a huge body); an unknown
        # field of the body names the closest valid one (api/field_hints.py)
        errors = [{k: v for k, v in e.items() if k in ("loc", "msg", "type")} for e in exc.errors()]
        route = request.scope.get("route")
        body = getattr(getattr(route, "body_field", None), "field_info", None)
        for e in errors:
            loc = list(e.get("loc") or [])
            if e.get("type") == "extra_forbidden" and body is not None and loc[:1] == ["body"]:
                valid = fields_at(body.annotation, loc[1:-1])
                e["msg"] = unknown_field_message(str(loc[-1]), valid)
        return JSONResponse({"detail": errors}, status_code=422)

    @app.exception_handler(StarletteHTTPException)
    async def _http_error(request: Request, exc: StarletteHTTPException) -> Response:
        if exc.status_code == 405:
            # Starlette's Allow lists the methods of the first route that matched the path
            # only; a path served by several routes (GET + PUT) must list them all.
            allowed = methods_for_path(app, request.url.path)
            headers = {**(exc.headers or {}), "Allow": ", ".join(allowed)}
            return JSONResponse({"detail": exc.detail}, status_code=405, headers=headers)
        return await http_exception_handler(request, exc)

    @app.exception_handler(IntegrityError)
    async def _conflict(_request: Request, exc: IntegrityError) -> JSONResponse:
        # Safety net for any unique-constraint race a route did not translate itself:
        # the request conflicts with stored state (409), it is not a server fault (500).
        log.warning("integrity error answered with 409: %s", exc.orig)
        return JSONResponse(
            {
                "detail": "the request conflicts with stored data (a unique name or key is "
                "already taken)"
            },
            status_code=409,
        )


#: the services' refusals a route lets through, and the status each is answered with; the
#: answer's ``detail`` is the error's own sentence (``_install_service_errors``)
SERVICE_ERRORS: dict[type[Exception], int] = {
    CampaignNotFoundError: 404,
    CampaignConflictError: 409,  # a command the state does not allow, STOP latched, ...
    NameTakenError: 409,  # a campaign's, a calibration's or a catalog's name
    KeyNameTakenError: 409,
    KeyNotFoundError: 404,
    MotionConflictError: 409,
    RecordingNotFoundError: 404,
    RecordingConflictError: 409,
    InsufficientSpaceError: 507,
    ExportSpaceError: 507,
    UnknownStudyError: 404,
    TooManyStudiesError: 409,
    UnknownReprocessingError: 404,
}


def _install_service_errors(app: FastAPI) -> None:
    """The services' errors as HTTP answers, in one place: each of ``SERVICE_ERRORS``
    with its status, and four that say more: a busy report or export pool (503 with
    Retry-After), a motion device failure (503 with what was refused), a set-point, jog
    or profile beyond the limits (422 at each request field that sets the limit) and a
    re-processing request that cannot run (422 at its field)."""

    def answer(status_code: int):
        async def handler(_request: Request, exc: Exception) -> JSONResponse:
            return JSONResponse({"detail": str(exc)}, status_code=status_code)

        return handler

    for error, status_code in SERVICE_ERRORS.items():
        app.add_exception_handler(error, answer(status_code))

    @app.exception_handler(HeavyWorkBusyError)
    async def _busy(_request: Request, exc: HeavyWorkBusyError) -> JSONResponse:
        headers = {"Retry-After": str(exc.retry_after_s)}
        return JSONResponse({"detail": str(exc)}, status_code=503, headers=headers)

    @app.exception_handler(MotionDeviceError)
    async def _motion_device(_request: Request, exc: MotionDeviceError) -> JSONResponse:
        return JSONResponse({"detail": exc.detail}, status_code=503)

    @app.exception_handler(MotionLimitError)
    async def _motion_limits(_request: Request, exc: MotionLimitError) -> JSONResponse:
        problems = [(["body", p.field] if p.field else ["body"], p.message) for p in exc.problems]
        return JSONResponse({"detail": located(problems)}, status_code=422)

    @app.exception_handler(ReprocessRequestError)
    async def _reprocess_request(_request: Request, exc: ReprocessRequestError) -> JSONResponse:
        where = "path" if exc.field == "campaign_id" else "body"
        return JSONResponse({"detail": located([([where, exc.field], str(exc))])}, status_code=422)


def _audit_service(app: FastAPI) -> AuditService | None:
    """The running app's audit writer (None before the lifespan built it)."""
    state = getattr(app.state, "tofpose", None)
    return state.audit if state is not None else None


def _include_routes(app: FastAPI) -> None:
    """Every resource's router."""
    routers = (
        health,
        devices_route,
        camera,
        pose,
        frames,
        motion,
        catalogs,
        campaigns,
        calibrations,
        reference,
        scene,
        foxglove,
        live,
        studies_route,
        reprocessings_route,
        recordings_route,
        viewers_route,
        audit_route,
    )
    for module in routers:
        app.include_router(module.router)


def create_app(settings: Settings | None = None, devices: Devices | None = None) -> FastAPI:
    """Build the app. ``devices`` overrides the drivers named in ``settings`` (tests)."""
    settings = settings or Settings()
    lifespan = _lifespan(settings, devices)

    # Swagger UI and ReDoc from files shipped in the fastapi-offline package, not a CDN:
    # a lab machine without internet still gets its API docs (no page fetches off-host).
    app = FastAPIOffline(
        title="tofpose",
        version=backend.__version__,
        summary="Pose of a cooperative target from a ToF camera, live, with a turntable.",
        lifespan=lifespan,
        swagger_ui_parameters={"validatorUrl": None},  # no badge from validator.swagger.io
        generate_unique_id_function=operation_id,
    )
    app.openapi = lambda: complete_openapi(app, _soft_limits(app))  # type: ignore[method-assign]
    app.add_middleware(BodySizeLimit, max_bytes=settings.max_body_bytes)
    # Outermost: a request naming a host we do not serve (DNS rebinding) gets 400 before
    # anything else runs. Origin is checked on the WebSocket itself (routes/live.py).
    app.add_middleware(TrustedHostMiddleware, allowed_hosts=settings.trusted_hosts)
    # Outside even that: every POST/PUT/PATCH/DELETE is recorded, the refused ones too
    # (backend/audit_middleware.py; the writer runs on a thread of its own).
    app.add_middleware(AuditMiddleware, audit=lambda: _audit_service(app))

    _install_error_answers(app)
    _install_service_errors(app)
    _include_routes(app)

    # The dashboard at / (its assets under /assets), or a page saying how to build it.
    dashboard.install(app, settings.frontend_dist)
    return app
