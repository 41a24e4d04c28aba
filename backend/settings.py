"""Server settings, read from ``TOFPOSE_*`` environment variables (pydantic-settings)."""

from __future__ import annotations

import ipaddress
from pathlib import Path
from typing import Annotated, Literal
from urllib.parse import urlsplit

from pydantic import Field, SecretStr, field_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

PACKAGED_DASHBOARD = Path(__file__).resolve().parent / "dashboard"
"""The built dashboard inside an installed wheel (copied there by setup.py's build step)."""
CHECKOUT_DASHBOARD = Path(__file__).resolve().parents[1] / "frontend" / "dist"
"""The built dashboard of a source checkout (``make frontend``; an editable install)."""

LOOPBACK_NAMES = {"localhost", "localhost.localdomain"}
LOOPBACK_HOST_HEADERS = ("localhost", "127.0.0.1", "[::1]")
WILDCARD_BINDS = {"0.0.0.0", "::", ""}


def is_loopback_host(host: str) -> bool:
    """True for 127.0.0.0/8, ::1 and localhost."""
    if host in LOOPBACK_NAMES:
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def visa_resource(motion: str) -> str | None:
    """The VISA resource of a ``scpi:...`` motion spec: ``scpi:HOST:PORT`` means
    ``TCPIP::HOST::PORT::SOCKET``; anything with ``::`` is a VISA resource as given."""
    rest = motion.removeprefix("scpi:")
    if "::" in rest:
        return rest
    host, _, port = rest.rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        return None
    return f"TCPIP::{host}::{port}::SOCKET"


class Settings(BaseSettings):
    """Everything the app factory needs; every field maps to ``TOFPOSE_<NAME>``.

    camera : "sim" (simulated camera in the simulated lab), "replay:PATH.h5", or
        "tofcam660:ADDRESS" (an ESPROS TOFcam-660 or the emulator, docs/devices.md).
    motion : "sim" (simulated turntable + rail), "none", or "scpi:HOST:PORT" /
        "scpi:VISA-RESOURCE" (an SCPI rate-table controller or the emulator).
    database_url : any SQLAlchemy URL; default ``sqlite:///<data_dir>/tofpose.db``.
    api_token : bearer token for state-changing requests; when unset, one is generated on
        first start and stored in ``<data_dir>/api_token``.
    open_reads : allow unauthenticated reads; default: only when bound to loopback.
    allowed_hosts : extra names the server answers to in the ``Host`` header (comma-separated
        in the environment), beside the bind address and, on loopback, localhost,
        127.0.0.1 and [::1]. A wildcard bind (0.0.0.0, ::) with none given accepts any.
    tracking : the live pipeline's tracking mode (windows around the predicted reflectors
        after a confident pose, full acquisition as fallback; docs/algorithm.md).
    pixel_fit : the live pipeline refines each ok pose on its markers' pixels
        (docs/algorithm.md, "Pixel-level fit"), as ``tofpose estimate`` does: the
        accuracy and covariance of the sensor's model, at tens of ms a frame (a loop
        slower than the camera measures the newest frame each time: fewer poses a
        second; docs/server.md). Campaigns measure with it too.
    filter_model : the relative-state filter's motion model, ``acceleration`` (constant
        angular acceleration) or ``twist`` (constant twist); filter_jerk_deg : the
        acceleration model's white angular jerk, its density's square root in deg
        (density (filter_jerk_deg deg)^2 / s^5; docs/algorithm.md, "Relative state").
    lab_target_distance_mm : with real devices, the target's distance from the turntable
        centre (rail 0): the lab reference pose is computed from the rate table's encoders
        and this nominal geometry, as the simulated lab does with ``sim_target_distance_mm``.
    allowed_origins : extra browser origins (``scheme://host:port``) that may open
        ``/ws/live``, beside the server's own origin.
    frontend_dir : the built dashboard served at ``/``; default: the copy an installed
        wheel carries, else the checkout's ``frontend/dist`` (``frontend_dist``).
    viser : run the 3-D scene (a viser server in this process) on ``viser_port``
        (0 = any free port; a taken port moves to the next free one, see
        ``GET /api/scene``). It has no token check of its own, so on a bind beyond
        loopback it runs only when reads are open.
    foxglove_port : publish the live stream to Foxglove (a ``foxglove-sdk`` WebSocket
        server on this host serving both ``foxglove.sdk.v1`` and the open protocol's
        ``foxglove.websocket.v1``, docs/interop.md); None (the default) = off, 0 = any
        free port. Like the 3-D scene it has no token check: beyond loopback only with open reads.
    dask_scheduler : where accuracy studies (``POST /api/studies``) run: the address of a
        Dask scheduler (``tcp://host:8786``); empty = a LocalCluster on this machine of
        its cores less one (``study_workers`` to override), workers at a lower priority
        so that the live camera loop keeps its frame rate (docs/scaleout.md).
    """

    model_config = SettingsConfigDict(env_prefix="TOFPOSE_", extra="ignore")

    host: str = "127.0.0.1"
    port: int = Field(default=8000, ge=0, le=65535)
    data_dir: Path = Path("data")
    database_url: str | None = None
    api_token: SecretStr | None = None
    open_reads: bool | None = None
    camera: str = "sim"
    motion: str = "sim"
    replay_rate_hz: float | None = Field(default=None, gt=0, le=1000)
    catalog: str = "paper-target"
    frame_rate_hz: float = Field(default=10.0, gt=0, le=60)
    sim_target_distance_mm: float = Field(default=15000.0, gt=0)
    lab_target_distance_mm: float = Field(default=15000.0, gt=0)
    sim_start_rail_mm: float = Field(default=13000.0, ge=0)
    sim_seed: int = 0
    sim_time_scale: float = Field(default=1.0, ge=0.01, le=1000.0)
    history_size: int = Field(default=600, ge=1, le=100_000)
    subscriber_queue: int = Field(default=8, ge=1, le=1000)
    # /ws/live connections: at most this many from one client address and in all (more
    # are refused with close code 1013, "try again later"); a client whose socket has not
    # taken a message within live_send_timeout_s is let go (its slot freed).
    live_max_clients_per_address: int = Field(default=16, ge=1, le=10_000)
    live_max_clients: int = Field(default=64, ge=1, le=10_000)
    live_send_timeout_s: float = Field(default=5.0, gt=0, le=600)
    camera_timeout_s: float = Field(default=2.0, gt=0)
    kernels_in_background: bool = Field(
        default=True,
        description="compile the pipeline's kernels in a background thread while "
        "frames already stream (poses follow when the compile is done); False waits for "
        "them before the camera loop starts",
    )
    retry_backoff_s: tuple[float, float] = (0.05, 2.0)
    max_body_bytes: int = Field(default=1_000_000, ge=1024)
    shutdown_timeout_s: float = Field(default=3.0, gt=0, le=60)
    frontend_dir: Path | None = None
    tracking: bool = True
    pixel_fit: bool = False
    filter_model: Literal["acceleration", "twist"] = "acceleration"
    filter_jerk_deg: float = Field(default=30.0, gt=0, le=10_000)
    dask_scheduler: str = ""
    study_workers: int | None = Field(default=None, ge=1, le=1024)
    # How large an accepted study may be, and how many may wait (docs/scaleout.md). The
    # defaults suit a 2-core lab PC, whose LocalCluster is 1 worker at ~28 frames/s: 10^6
    # frames is ~10 h (a night), 10^4 cells keeps summary.json to ~20 MB (1.7 kB a cell),
    # and 4 studies queued or running is up to ~2 days of that worker's time. Raise them
    # for a cluster (TOFPOSE_DASK_SCHEDULER).
    study_max_cells: int = Field(default=10_000, ge=1)
    study_max_frames: int = Field(default=1_000_000, ge=1)
    studies_max_active: int = Field(default=4, ge=1, le=10_000)
    # Recordings on demand (docs/server.md): refused to start below this much free space
    # (MB) on the data directory's disk; a running one stops, file closed, when it falls below.
    recording_min_free_mb: float = Field(default=1000.0, ge=0)
    viser: bool = True
    viser_port: int = Field(default=8080, ge=0, le=65535)
    foxglove_port: int | None = Field(default=None, ge=0, le=65535)
    allowed_hosts: Annotated[list[str], NoDecode] = Field(default_factory=list)
    allowed_origins: Annotated[list[str], NoDecode] = Field(default_factory=list)

    @field_validator("allowed_hosts", "allowed_origins", mode="before")
    @classmethod
    def _comma_list(cls, v: object) -> object:
        if isinstance(v, str):
            return [item.strip() for item in v.split(",") if item.strip()]
        return v

    @field_validator("allowed_origins")
    @classmethod
    def _origins(cls, v: list[str]) -> list[str]:
        out = []
        for origin in v:
            parts = urlsplit(origin)
            if (
                parts.scheme not in ("http", "https")
                or not parts.netloc
                or parts.path
                not in (
                    "",
                    "/",
                )
            ):
                raise ValueError(f"allowed origin must look like http://host:port, got {origin!r}")
            out.append(f"{parts.scheme}://{parts.netloc}".lower())
        return out

    @field_validator("camera")
    @classmethod
    def _camera_spec(cls, v: str) -> str:
        kind, _, rest = v.partition(":")
        if v != "sim" and not (kind in ("replay", "tofcam660") and rest):
            raise ValueError(
                f"camera must be 'sim', 'replay:PATH.h5' or 'tofcam660:ADDRESS', got {v!r}"
            )
        if kind == "tofcam660":
            try:
                ipaddress.IPv4Address(rest)
            except ValueError:
                raise ValueError(f"tofcam660 camera needs an IPv4 address, got {rest!r}") from None
        return v

    @field_validator("motion")
    @classmethod
    def _motion_spec(cls, v: str) -> str:
        if v in ("sim", "none"):
            return v
        if v.startswith("scpi:") and (visa_resource(v) is not None):
            return v
        raise ValueError(
            f"motion must be 'sim', 'none', 'scpi:HOST:PORT' or 'scpi:VISA-RESOURCE', got {v!r}"
        )

    @property
    def resolved_database_url(self) -> str:
        if self.database_url:
            return self.database_url
        return f"sqlite:///{(self.data_dir / 'tofpose.db').resolve()}"

    @property
    def frontend_dist(self) -> Path:
        """The built dashboard's directory (it may be missing: then ``/`` says so):
        ``frontend_dir`` if set, else the installed wheel's copy, else, in a source
        checkout without one, the checkout's ``frontend/dist`` (``make frontend``)."""
        if self.frontend_dir is not None:
            return self.frontend_dir
        in_checkout = (CHECKOUT_DASHBOARD.parent / "package.json").is_file()
        if in_checkout and not (PACKAGED_DASHBOARD / "index.html").is_file():
            return CHECKOUT_DASHBOARD
        return PACKAGED_DASHBOARD

    @property
    def trusted_hosts(self) -> list[str]:
        """Names accepted in the ``Host`` header (DNS-rebinding defence); ["*"] = any."""
        if self.host in WILDCARD_BINDS and not self.allowed_hosts:
            return ["*"]
        bind = f"[{self.host}]" if ":" in self.host else self.host
        names = [bind, *self.allowed_hosts]
        if is_loopback_host(self.host) or self.host in WILDCARD_BINDS:
            names += LOOPBACK_HOST_HEADERS
        return list(dict.fromkeys(n.lower() for n in names))

    @property
    def scene_refusal(self) -> str | None:
        """Why the 3-D scene does not run with these settings, or None when it does."""
        if not self.viser:
            return "3-D scene switched off (--no-viser / TOFPOSE_VISER=false)"
        if not self.reads_are_open:
            return (
                "3-D scene off: it has no token check and the server is bound beyond "
                "loopback with closed reads (set TOFPOSE_OPEN_READS=true to serve it)"
            )
        return None

    @property
    def foxglove_refusal(self) -> str | None:
        """Why the live Foxglove server does not run with these settings, or None."""
        if self.foxglove_port is None:
            return "Foxglove server off (--foxglove-port / TOFPOSE_FOXGLOVE_PORT to start it)"
        if not self.reads_are_open:
            return (
                "Foxglove server off: it has no token check and the server is bound beyond "
                "loopback with closed reads (set TOFPOSE_OPEN_READS=true to serve it)"
            )
        return None

    @property
    def reads_are_open(self) -> bool:
        return self.open_reads if self.open_reads is not None else is_loopback_host(self.host)
