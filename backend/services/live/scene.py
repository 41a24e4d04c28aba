"""The live 3-D scene: a viser server inside the backend process, fed by the live hub.

Nodes (names are part of the contract: tests and docs use them), in the lab frame in
metres (``scene_model``):

- ``/turntable``: the gimbal's axes at the encoder positions (a frame per axis set);
  ``/rail``: the rail the turntable rides on.
- ``/camera``: the camera's pose in the lab; children ``/camera/frustum``,
  ``/camera/cloud`` (the back-projected distance image, downsampled to
  ``max_cloud_points``) and ``/camera/reflectors`` (the measured reflector points,
  coloured matched / unmatched).
- ``/estimate``: the target model at the estimated pose, ``.../plate`` and
  ``.../reflector_<id>``, each reflector coloured matched / unmatched / out of view
  (``scene_model.STATE_COLOURS``).
- ``/reference``: the same model, wireframe, at the lab's reference (encoders + nominal
  geometry or a calibration's; a recording's ``/reference``), shown when the source has
  one; ``/truth``: at the pose the simulator rendered (a recording's ``/truth``), shown
  only when the source knows it (docs/interop.md, "Names: truth and reference").
- ``/ground/grid``: a grid on the ground plane (``scene_model.GROUND_DROP_M`` below
  the lab origin; lab y points down), cells of one scale step; ``/ground/scale``: rulers
  along the lab's x and z axes on it, ticked every step, with ``/ground/scale/label_<k>``
  reading the distance in metres and ``/ground/scale/axis_x``, ``.../axis_z`` naming the
  axes. Grid and rulers reach past the farthest of camera and target, and grow when
  either goes beyond them.
- ``/trail``: the estimated target origin over the last ``scene_model.TRAIL_POSES``
  poses, a polyline in the lab frame; emptied by the GUI's "Clear trail" button
  (``LiveScene.clear_trail``).
- GUI: a "Pause scene" checkbox (freezes the scene; the pipeline keeps running), a
  "Clear trail" button and a status line.

One thread takes the newest sample from a one-deep hub subscription (older ones are
dropped, never queued) and updates the nodes at most ``max_rate_hz`` times a second.

Who may use the scene's port (``SceneAccess``): the same Host and Origin rules as the
main server. Viser serves its page and its WebSocket on one port without looking at
either header, so any web page the lab user visits could open ``ws://127.0.0.1:8080``
and read the live pose, around the Origin check of ``/ws/live``; and a hostile domain
re-resolved to 127.0.0.1 (DNS rebinding) could read it as its own origin. Here, every
request to the port, HTTP or WebSocket, is checked before viser sees it:

- its ``Host`` must name a trusted host (``Settings.trusted_hosts``: the bind address,
  the loopback names on loopback, ``TOFPOSE_ALLOWED_HOSTS``; ``*`` = any, ``*.lab`` = a
  domain), else 400;
- its ``Origin``, when it sends one (browsers do, on every WebSocket), must be the
  scene's own origin (the page viser serves, in the dashboard's frame or a tab of its
  own), the dashboard's (the same host name at the main server's port,
  ``dashboard_port``) or one of ``TOFPOSE_ALLOWED_ORIGINS``, else 403. Clients without an
  Origin (scripts, not browsers) pass, as on ``/ws/live``.

A refused WebSocket gets its HTTP answer instead of the 101: it is never opened, so no
scene message is ever sent on it. Every HTTP answer of the port carries
``frame-ancestors`` naming the dashboard's origins (only the dashboard may show the
scene in a frame), ``nosniff`` and ``no-referrer`` (``backend.security_headers``).

How it hooks into viser (1.1 here): ``ViserServer`` starts a thread that listens with
``websockets.asyncio.server.serve(handler, ..., process_request=<its HTTP file server>)``
and does not keep the server object nor take hooks of its own. The ``websockets``
library calls ``process_request`` for every connection before the handshake (the
documented place to refuse one: return a response instead of None) and
``process_response`` for every answer. So, for as long as ``ViserServer.__init__`` runs
(it returns once the port listens), ``_guarded_serve`` puts a wrapper in the place of
``websockets.asyncio.server.serve`` that hands viser's call our ``process_request``
(check, then viser's own) and ``process_response`` (the headers); the original is back
before the constructor returns. The listening socket never exists without the check
(wrapping the server object after the start would leave a moment with none). The
replacement is process-wide while it lasts, so it runs under a lock and only while a
scene starts; nothing else in the server calls ``serve`` (uvicorn drives its WebSockets
through the protocol classes). Should a later viser start its server some other way,
the wrapper is never called and ``LiveScene`` stops the server and raises rather than
run the scene unchecked (``_start_scene`` then reports the scene as not running).
"""

from __future__ import annotations

import contextlib
import inspect
import logging
import re
import socket
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any
from urllib.parse import urlsplit

import numpy as np

from backend.drivers.base import CameraFrame
from backend.security_headers import SCENE_HEADERS
from backend.services.live.acquisition import AcquisitionService, LiveSample
from backend.services.live.hub import LiveHub
from backend.services.live.scene_model import (
    GROUND_DROP_M,
    MATCHED,
    STATE_COLOURS,
    UNMATCHED,
    PoseTrail,
    distance_cloud,
    lab_camera_pose,
    reflector_states,
    scale_marks,
    scale_segments,
    scene_extent_m,
)
from backend.settings import LOOPBACK_HOST_HEADERS
from tofpose.core.catalog import Catalog
from tofpose.core.geometry import RigidTransform, quaternion_wxyz_from_rotation

if TYPE_CHECKING:  # viser is imported when a scene starts (LiveScene)
    from viser import FrameHandle, IcosphereHandle

log = logging.getLogger("tofpose.scene")
REFERENCE_COLOUR = (70, 120, 230)
TRUTH_COLOUR = (20, 150, 150)
PLATE_COLOUR = (200, 200, 205)
TRAIL_COLOUR = (170, 60, 200)
SCALE_COLOUR = (60, 60, 60)


def _known_pose(frame: CameraFrame) -> RigidTransform | None:
    """The pose the scene aims at and judges reflectors in view by when there is no
    estimate (``T_camera_target``): the lab's reference, else the truth (a replayed
    recording with ``/truth`` alone); None when the frame has neither."""
    if frame.T_camera_target_lab is not None:
        return frame.T_camera_target_lab
    return frame.T_camera_target_exact


def _lab(T_lab_cam: RigidTransform, T_cam: RigidTransform | None) -> RigidTransform | None:
    return T_lab_cam.compose(T_cam) if T_cam is not None else None


def _place(handle, T: RigidTransform) -> None:
    """Set a viser node's pose from a transform in millimetres."""
    handle.wxyz = quaternion_wxyz_from_rotation(T.R)
    handle.position = np.asarray(T.t_mm, float) / 1000.0


# -- who may use the scene's port ---------------------------------------------------------
_HOST_HEADER = re.compile(r"(?P<name>\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9._-]+)(?::(?P<port>\d{1,5}))?")
DEFAULT_PORTS = {"http": 80, "https": 443}


def split_host(value: str) -> tuple[str, int | None] | None:
    """``Host`` header (or an origin's ``host[:port]``) -> (lower-case name, port), the
    brackets of an IPv6 literal kept (``[::1]``, as in ``Settings.trusted_hosts``);
    None when it is not a host name."""
    m = _HOST_HEADER.fullmatch(value.strip())
    if m is None:
        return None
    return m["name"].lower(), int(m["port"]) if m["port"] else None


@dataclass(frozen=True)
class Refusal:
    """Why a request to the scene's port is refused, and with which HTTP status."""

    status: int
    reason: str


@dataclass(frozen=True)
class SceneAccess:
    """The Host and Origin rules of the scene's port (see the module docstring).

    trusted_hosts : names accepted in ``Host`` (no port), lower case; ``"*"`` = any,
        ``"*.domain"`` = the domain's names (Starlette's ``TrustedHostMiddleware`` rules,
        which the main server applies to the same list).
    allowed_origins : further browser origins (``scheme://host:port``) beside the scene's
        own and the dashboard's.
    dashboard_port : the main server's port: ``http(s)://<the Host's name>:<port>`` is
        the dashboard's origin. None when it is not known (then only the scene's own
        origin and ``allowed_origins`` pass).
    """

    trusted_hosts: tuple[str, ...] = LOOPBACK_HOST_HEADERS
    allowed_origins: tuple[str, ...] = ()
    dashboard_port: int | None = None

    def host_name(self, hosts: Sequence[str]) -> str | None:
        """The trusted name the request's ``Host`` headers (all of them) give, else None."""
        if len(hosts) != 1 or (parsed := split_host(hosts[0])) is None:
            return None
        name = parsed[0]
        for pattern in self.trusted_hosts:
            if pattern == "*" or name == pattern:
                return name
            if pattern.startswith("*.") and name.endswith(pattern[1:]):
                return name
        return None

    def origin_allowed(self, origin: str, host_header: str, host_name: str) -> bool:
        """Whether a browser page of ``origin`` may use the port reached as ``host_header``
        (whose trusted name is ``host_name``)."""
        try:
            parts = urlsplit(origin)
        except ValueError:  # an unbalanced IPv6 bracket
            return False
        if parts.scheme not in DEFAULT_PORTS or not parts.netloc:
            return False
        netloc = parts.netloc.lower()
        if f"{parts.scheme}://{netloc}" in self.allowed_origins:
            return True
        if host_header and netloc == host_header.strip().lower():
            return True  # the scene's own page
        parsed = split_host(netloc)
        if parsed is None or self.dashboard_port is None:
            return False
        name, port = parsed
        return name == host_name and (port or DEFAULT_PORTS[parts.scheme]) == self.dashboard_port

    def refusal(self, hosts: Sequence[str], origins: Sequence[str]) -> Refusal | None:
        """None when a request with these ``Host`` and ``Origin`` headers (every value of
        each: a repeated header is refused) may be served, else why not."""
        name = self.host_name(hosts)
        if name is None and "*" not in self.trusted_hosts:
            return Refusal(400, "Invalid host header")
        if not origins:
            return None
        host_header = hosts[0] if len(hosts) == 1 else ""
        if len(origins) > 1 or not self.origin_allowed(origins[0], host_header, name or ""):
            return Refusal(
                403, "cross-origin request to the 3-D scene refused (TOFPOSE_ALLOWED_ORIGINS)"
            )
        return None

    def frame_ancestors(self, hosts: Sequence[str]) -> str:
        """The CSP directive for an answer to a request with these ``Host`` headers: the
        dashboard's origins on that host name, and ``allowed_origins``."""
        name = self.host_name(hosts)
        sources = [
            f"{scheme}://{name}:{self.dashboard_port}"
            for scheme in DEFAULT_PORTS
            if name is not None and self.dashboard_port
        ]
        sources += self.allowed_origins
        return "frame-ancestors " + (" ".join(sources) or "'none'")

    def response_headers(self, hosts: Sequence[str]) -> dict[str, str]:
        """What every HTTP answer of the scene's port carries."""
        return {"Content-Security-Policy": self.frame_ancestors(hosts), **SCENE_HEADERS}


Hook = Callable[..., Any]
_SERVE_LOCK = threading.Lock()


def _checked_request(access: SceneAccess, viser_hook: Hook | None) -> Hook:
    """A ``process_request`` that refuses what ``access`` refuses, then asks viser's."""

    async def process_request(connection, request):
        refused = access.refusal(request.headers.get_all("Host"), request.headers.get_all("Origin"))
        if refused is not None:
            hosts, origins = request.headers.get_all("Host"), request.headers.get_all("Origin")
            log.info("3-D scene: %s (Host %.100r, Origin %.100r)", refused.reason, hosts, origins)
            return connection.respond(refused.status, refused.reason + "\n")
        answer = viser_hook(connection, request) if viser_hook is not None else None
        return await answer if inspect.isawaitable(answer) else answer

    return process_request


def _hardened_response(access: SceneAccess, viser_hook: Hook | None) -> Hook:
    """A ``process_response`` that adds ``access.response_headers`` to every HTTP answer
    (not to a WebSocket's 101), after viser's own hook if it has one."""

    async def process_response(connection, request, response):
        if viser_hook is not None:
            replaced = viser_hook(connection, request, response)
            replaced = await replaced if inspect.isawaitable(replaced) else replaced
            response = replaced or response
        if response.status_code != 101:
            for name, value in access.response_headers(request.headers.get_all("Host")).items():
                # a header viser set is kept; a policy is added beside its own (both apply)
                if name == "Content-Security-Policy" or name not in response.headers:
                    response.headers[name] = value
        return response

    return process_response


@contextlib.contextmanager
def _guarded_serve(access: SceneAccess) -> Iterator[list[Hook]]:
    """While open, ``websockets.asyncio.server.serve`` gives every server it starts the
    hooks of ``access`` (around the hooks the caller passes). Yields the list of the
    handlers it started servers for: empty afterwards = the check was never installed."""
    import websockets.asyncio.server as ws_server

    original = ws_server.serve
    guarded: list[Hook] = []

    def serve(handler, *args, process_request=None, process_response=None, **kwargs):
        guarded.append(handler)
        return original(
            handler,
            *args,
            process_request=_checked_request(access, process_request),
            process_response=_hardened_response(access, process_response),
            **kwargs,
        )

    # a patch while viser starts its server: websockets' ``serve`` is a class, for mypy not
    # something to assign a function to
    with _SERVE_LOCK:
        ws_server.serve = serve  # type: ignore[misc, assignment]
        try:
            yield guarded
        finally:
            ws_server.serve = original  # type: ignore[misc]


def free_port_other_than(host: str, avoid: int, attempts: int = 20) -> int:
    """A TCP port free on ``host`` now (the system's pick for port 0) that is not
    ``avoid``; 0 (let the server pick) when ``host`` cannot be bound here or every pick
    was ``avoid``."""
    for _ in range(attempts):
        try:
            family = socket.AF_INET6 if ":" in host else socket.AF_INET
            with socket.socket(family, socket.SOCK_STREAM) as sock:
                sock.bind((host, 0))
                port = int(sock.getsockname()[1])
        except OSError:
            return 0
        if port != avoid:
            return port
    return 0


class LiveScene:
    """Owns a ``viser.ViserServer`` and keeps its scene in step with the live results.

    ``trusted_hosts``, ``allowed_origins`` and ``dashboard_port`` say who may use its
    port (``SceneAccess``; by default the loopback names and the scene's own origin)."""

    def __init__(
        self,
        hub: LiveHub,
        acquisition: AcquisitionService,
        *,
        host: str,
        port: int,
        max_rate_hz: float = 10.0,
        max_cloud_points: int = 12_000,
        rail_length_mm: float | None = None,
        trusted_hosts: Sequence[str] = LOOPBACK_HOST_HEADERS,
        allowed_origins: Sequence[str] = (),
        dashboard_port: int | None = None,
    ) -> None:
        import viser  # imported here: the pipeline and the CLI do not need it

        self._hub = hub
        self._acq = acquisition
        self._camera = acquisition.camera.model
        self._min_period_s = 1.0 / max_rate_hz
        self._max_cloud_points = max_cloud_points
        self.access = SceneAccess(
            trusted_hosts=tuple(h.lower() for h in trusted_hosts),
            allowed_origins=tuple(o.lower().rstrip("/") for o in allowed_origins),
            dashboard_port=dashboard_port or None,
        )
        if port == 0 and dashboard_port:
            # the main server binds its port only once the app has started: "any free
            # port" could be that one (seen once: the dashboard then failed to bind)
            port = free_port_other_than(host, dashboard_port)
        with _guarded_serve(self.access) as guarded:
            self.server = viser.ViserServer(host=host, port=port, label="tofpose", verbose=False)
        if not guarded:
            self.server.stop()
            raise RuntimeError(
                f"viser {viser.__version__} did not start its server through "
                "websockets.asyncio.server.serve: the 3-D scene would have no Host/Origin "
                "check, so it is not served"
            )
        self.updates = 0
        self.last_frame_index: int | None = None
        self._catalog_name: str | None = None
        self._stop = threading.Event()
        self._build_static(rail_length_mm)
        self._sub = hub.subscribe(maxsize=1)
        self._thread = threading.Thread(target=self._run, name="tofpose-scene", daemon=True)
        self._thread.start()

    # -- lifecycle ------------------------------------------------------------------------
    @property
    def port(self) -> int:
        return self.server.get_port()

    @property
    def paused(self) -> bool:
        return bool(self._pause.value)

    def set_paused(self, paused: bool) -> None:
        # viser's setter takes ``T | ndarray``, unlike its getter: mypy reads no setter
        self._pause.value = paused  # type: ignore[misc]

    def close(self) -> None:
        self._stop.set()
        self._hub.unsubscribe(self._sub)
        self._thread.join(timeout=2.0)
        self.server.stop()

    # -- scene construction ---------------------------------------------------------------
    def _build_static(self, rail_length_mm: float | None) -> None:
        s = self.server.scene
        s.set_up_direction("-y")  # the lab's y axis points down
        s.configure_environment_map(hdri=None)
        s.add_light_ambient("/light/ambient", intensity=1.2)
        s.add_light_directional("/light/key", intensity=1.5, wxyz=(0.92, -0.38, 0.0, 0.0))
        self.server.initial_camera.up = (0.0, -1.0, 0.0)
        self._aimed = False
        s.add_frame("/lab", axes_length=0.25, axes_radius=0.008)
        self._extent_m = 0.0
        self._ground_nodes: list[Any] = []
        reach = [[0.0, 0.0, (rail_length_mm or 0.0) / 1000.0]]
        self._build_ground(scene_extent_m(np.asarray(reach)))
        self.trail = PoseTrail()
        self._trail_lock = threading.Lock()
        self.trail_node = s.add_line_segments(
            "/trail",
            np.zeros((1, 2, 3)),
            TRAIL_COLOUR,
            thickness=3.0,
            thickness_units="screen",
            visible=False,
        )
        if rail_length_mm:
            end = (0.0, 0.0, rail_length_mm / 1000.0)
            s.add_line_segments("/rail", np.array([[(0.0, 0.0, 0.0), end]]), colors=(90, 90, 90))
        self.turntable = s.add_frame("/turntable", axes_length=0.4, axes_radius=0.012)
        self.camera_node = s.add_frame("/camera", show_axes=False)
        m = self._camera
        fov_v = 2.0 * np.arctan(m.height / 2.0 / m.fy)
        self.frustum = s.add_camera_frustum(
            "/camera/frustum",
            fov=float(fov_v),
            aspect=m.width / m.height,
            scale=0.35,
            color=(30, 30, 30),
        )
        self.cloud = s.add_point_cloud(
            "/camera/cloud", np.zeros((1, 3), np.float32), (150, 150, 150), point_size=0.007
        )
        self.measured = s.add_point_cloud(
            "/camera/reflectors",
            np.zeros((1, 3), np.float32),
            (0, 0, 0),
            point_size=0.05,
            point_shape="circle",
            visible=False,
        )
        self._pause = self.server.gui.add_checkbox("Pause scene", initial_value=False)
        self._clear = self.server.gui.add_button("Clear trail")
        self._clear.on_click(lambda _event: self.clear_trail())
        self.status = self.server.gui.add_markdown("waiting for the first frame")
        self.estimate: FrameHandle | None = None
        self.reference: FrameHandle | None = None
        self.truth: FrameHandle | None = None
        self.estimate_reflectors: dict[int, IcosphereHandle] = {}
        self.reference_reflectors: dict[int, IcosphereHandle] = {}
        self.truth_reflectors: dict[int, IcosphereHandle] = {}

    def _build_ground(self, extent_m: float) -> None:
        """(Re)build the ground grid and the rulers out to ``extent_m`` from the origin."""
        s = self.server.scene
        for node in self._ground_nodes:
            node.remove()
        marks, step = scale_marks(extent_m)
        self._ground_nodes = [
            s.add_grid(
                "/ground/grid",
                width=extent_m,
                height=extent_m,
                plane="xz",
                cell_size=step,
                cell_color=(175, 175, 175),
                section_size=step * 5,
                section_color=(110, 110, 110),
                position=(0.0, GROUND_DROP_M, extent_m / 2.0),
            ),
            s.add_line_segments(
                "/ground/scale",
                scale_segments(marks, extent_m),
                SCALE_COLOUR,
                thickness=2.0,
                thickness_units="screen",
            ),
        ]
        for k, mark in enumerate(marks):
            self._ground_nodes.append(
                s.add_label(f"/ground/scale/label_{k}", mark.text, position=mark.position_m)
            )
        for axis, position in (
            ("x", (extent_m / 2.0 + step / 2.0, GROUND_DROP_M, 0.0)),
            ("z", (0.0, GROUND_DROP_M, extent_m + step / 2.0)),
        ):
            self._ground_nodes.append(
                s.add_label(f"/ground/scale/axis_{axis}", f"lab {axis} (m)", position=position)
            )
        self._extent_m = extent_m

    def clear_trail(self) -> None:
        """Forget the trail's poses (the GUI's "Clear trail"); it grows again from the
        next pose."""
        with self._trail_lock:
            # hidden before emptied: whoever sees the trail empty (a reader without the
            # lock, the browser test) sees the node hidden too
            self.trail_node.visible = False
            self.trail.clear()

    def _update_trail(self, position_m: np.ndarray | None) -> None:
        with self._trail_lock:
            if position_m is not None:
                self.trail.add(position_m)
            if len(self.trail) >= 2:
                segments = self.trail.segments_m()
                self.trail_node.points = segments.astype(np.float32)
                self.trail_node.colors = np.broadcast_to(
                    np.asarray(TRAIL_COLOUR, np.uint8), segments.shape
                ).copy()
            self.trail_node.visible = len(self.trail) >= 2

    def _build_target(self, catalog: Catalog) -> None:
        """(Re)build the three target models for the active catalog."""
        s = self.server.scene
        for node in (self.estimate, self.reference, self.truth):
            if node is not None:
                node.remove()
        self.estimate = s.add_frame("/estimate", axes_length=0.15, axes_radius=0.006)
        w, h = catalog.plate_size_mm
        dims = (w / 1000.0, h / 1000.0, 0.01)
        s.add_box("/estimate/plate", PLATE_COLOUR, dims, position=(0.0, 0.0, -0.005))
        self.estimate_reflectors = {}
        for r in catalog.reflectors:
            pos = np.asarray(r.position_mm, float) / 1000.0
            self.estimate_reflectors[r.id] = s.add_icosphere(
                f"/estimate/reflector_{r.id}",
                r.diameter_mm / 2000.0,
                STATE_COLOURS[UNMATCHED],
                position=pos,
            )
        s.add_label("/estimate/label", "estimate", position=(-w / 2000.0, h / 2000.0, 0.0))
        self.reference, self.reference_reflectors = self._wireframe_target(
            catalog, "/reference", REFERENCE_COLOUR, label_at=(w / 2000.0, -h / 2000.0, 0.0)
        )
        self.truth, self.truth_reflectors = self._wireframe_target(
            catalog, "/truth", TRUTH_COLOUR, label_at=(-w / 2000.0, -h / 2000.0, 0.0)
        )

    def _wireframe_target(
        self, catalog: Catalog, name: str, colour: tuple[int, int, int], label_at
    ) -> tuple[FrameHandle, dict[int, IcosphereHandle]]:
        """A hidden wireframe target model at node ``name`` (plate, reflectors and a label
        reading the node's name at ``label_at``, m in the target frame)."""
        s = self.server.scene
        node = s.add_frame(name, axes_length=0.15, axes_radius=0.006, visible=False)
        w, h = catalog.plate_size_mm
        dims = (w / 1000.0, h / 1000.0, 0.01)
        s.add_box(f"{name}/plate", colour, dims, wireframe=True, position=(0, 0, -0.005))
        reflectors = {
            r.id: s.add_icosphere(
                f"{name}/reflector_{r.id}",
                r.diameter_mm / 2000.0,
                colour,
                position=np.asarray(r.position_mm, float) / 1000.0,
                wireframe=True,
            )
            for r in catalog.reflectors
        }
        s.add_label(f"{name}/label", name.lstrip("/"), position=label_at)
        return node, reflectors

    # -- live updates ----------------------------------------------------------------------
    def _run(self) -> None:
        last = 0.0
        while not self._stop.is_set():
            sample = self._sub.get(timeout_s=0.2)
            if sample is None or self.paused:
                continue
            wait = self._min_period_s - (time.monotonic() - last)
            if wait > 0 and self._stop.wait(wait):
                return
            newer = self._sub.get(timeout_s=0)  # whatever arrived while we waited
            sample = newer or sample
            try:
                self.update(sample)
            except Exception:  # a scene glitch must never take the server down
                log.exception("3-D scene update failed")
            last = time.monotonic()

    def update(self, sample: LiveSample) -> None:
        """Move every live node to what ``sample`` shows (called by the scene thread;
        tests call it directly)."""
        catalog = self._acq.catalog
        if catalog.name != self._catalog_name or self.estimate is None:
            self._build_target(catalog)
            self._catalog_name = catalog.name
        estimate, reference, truth = self.estimate, self.reference, self.truth
        assert estimate is not None and reference is not None and truth is not None
        res, frame = sample.result, sample.frame
        T_lab_cam = lab_camera_pose(frame.meta.get("encoders"))
        T_shown = _known_pose(frame)  # the lab reference; the truth only without one
        T_reference, T_truth = frame.T_camera_target_lab, frame.T_camera_target_exact
        if not self._aimed:
            self._aim_view(T_lab_cam, res, T_shown)
        with self.server.atomic():
            _place(self.turntable, T_lab_cam)
            _place(self.camera_node, T_lab_cam)
            T_est = (
                RigidTransform(res.R, res.t_mm)
                if res.ok and res.R is not None and res.t_mm is not None
                else None
            )
            states = reflector_states(catalog, res, self._camera, T_est or T_shown)
            for r, state in zip(catalog.reflectors, states, strict=True):
                self.estimate_reflectors[r.id].color = STATE_COLOURS[state]
            estimate.visible = T_est is not None
            T_lab_est = T_lab_cam.compose(T_est) if T_est is not None else None
            if T_lab_est is not None:
                _place(estimate, T_lab_est)
            self._update_trail(T_lab_est.t_mm / 1000.0 if T_lab_est is not None else None)
            reach = [T_lab_cam.t_mm / 1000.0]
            reach += [
                T.t_mm / 1000.0
                for T in (T_lab_est, _lab(T_lab_cam, T_reference), _lab(T_lab_cam, T_truth))
                if T is not None
            ]
            if (needed := scene_extent_m(np.asarray(reach))) > self._extent_m:
                self._build_ground(needed)
            for node, T in ((reference, T_reference), (truth, T_truth)):
                node.visible = T is not None
                if T is not None:
                    _place(node, T_lab_cam.compose(T))
            if sample.has_images:
                cloud = distance_cloud(
                    self._camera, frame.gray, frame.distance_mm, self._max_cloud_points
                )
                if len(cloud.points_m):
                    self.cloud.points = cloud.points_m
                    self.cloud.colors = cloud.colours
            self._update_measured(res)
            self.status.content = self._status_text(res, frame.index)
        self.updates += 1
        self.last_frame_index = frame.index

    def _aim_view(self, T_lab_cam: RigidTransform, res, T_shown) -> None:
        """Point the initial view (new browser tabs) at the camera and the target: from
        above and to the side of the camera, at the middle of the line of sight."""
        if res.ok:
            range_m = float(np.linalg.norm(res.t_mm)) / 1000.0
        elif T_shown is not None:
            range_m = float(np.linalg.norm(T_shown.t_mm)) / 1000.0
        else:
            return  # wait for a frame that says where the target is
        cam = T_lab_cam.t_mm / 1000.0
        ahead = T_lab_cam.R[:, 2]
        look_at = cam + ahead * range_m / 2.0
        position = cam + T_lab_cam.R @ np.array([-1.1 * range_m, -0.6 * range_m, -0.15 * range_m])
        self.server.initial_camera.look_at = look_at
        self.server.initial_camera.position = position
        # a browser that connected before the first pose (the dashboard's frame, loaded
        # with the page) keeps the default view unless it is aimed too
        for client in self.server.get_clients().values():
            client.camera.look_at = look_at
            client.camera.position = position
        self._aimed = True

    def _update_measured(self, res) -> None:
        pts = [np.asarray(m.point_mm, float) for m in res.matched]
        cols = [STATE_COLOURS[MATCHED]] * len(pts)
        for u, v, d in res.unmatched:
            if np.isfinite(d):
                pts.append(self._camera.back_project(np.array([[u, v]]), np.array([d]))[0])
                cols.append(STATE_COLOURS[UNMATCHED])
        self.measured.visible = bool(pts)
        if pts:
            self.measured.points = (np.asarray(pts) / 1000.0).astype(np.float32)
            self.measured.colors = np.asarray(cols, np.uint8)

    @staticmethod
    def _status_text(res, frame_index: int) -> str:
        if not res.ok:
            return f"frame {frame_index}: **no pose**: {res.reason}"
        x, y, z = res.t_mm
        p, yw, r = res.euler_deg
        return (
            f"frame {frame_index}: {res.n_matched} matched, residual "
            f"{res.residual_mm:.2f} mm  \nx {x:.1f} mm, y {y:.1f} mm, z {z:.1f} mm  \n"
            f"pitch {p:.2f} deg, yaw {yw:.2f} deg, roll {r:.2f} deg"
        )
