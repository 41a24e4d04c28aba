"""The live stream for Foxglove: a ``foxglove-sdk`` WebSocket server in this process.

It publishes the channels of an exported MCAP file (``tofpose.io.interop.topics``, see
docs/interop.md) for every live frame: the gray and distance images, the camera model,
the overlay, the estimate (transform, pose, reflectors, JSON with its covariance), the
lab reference (``/tofpose/reference``: the reference the live error is measured against)
and, where the source knows it (the simulator, a replayed recording's ``/truth``), the
truth: the pose the simulator rendered (``CameraFrame.T_camera_target_exact``). Log
times are the frames' arrival times (unix ns).

The camera loop never waits for it: one thread takes the newest sample from a one-deep
hub subscription (older ones are dropped and counted, never queued), converts each
channel's message only when a client subscribes to that channel, and hands it to the
SDK, which keeps at most ``backlog_messages`` per client and drops the oldest for a
client that reads too slowly.

Clients connect to the public port through ``foxglove_relay``, which serves both the
SDK's subprotocol (``foxglove.sdk.v1``) and the open protocol's (``foxglove.websocket.v1``)
on that port; the SDK server itself listens on a free loopback port.
"""

from __future__ import annotations

import logging
import threading

from backend.services.live.acquisition import AcquisitionService, LiveSample
from backend.services.live.foxglove_relay import SERVED_SUBPROTOCOLS, FoxgloveRelay
from backend.services.live.hub import LiveHub

log = logging.getLogger("tofpose.foxglove")


class LiveFoxglove:
    """Owns a Foxglove WebSocket server fed by the live hub."""

    def __init__(
        self,
        hub: LiveHub,
        acquisition: AcquisitionService,
        *,
        host: str,
        port: int,
        backlog_messages: int = 64,
    ) -> None:
        import foxglove  # imported here: the server runs without it when it is off

        from tofpose.io.interop.channels import ToFChannels

        self._hub = hub
        self.context = foxglove.Context()
        # the reference channels are advertised whether or not the source has them (the
        # simulator knows the exact truth, a real lab only its reference)
        self.channels = ToFChannels(
            self.context, acquisition.camera.model, truth=True, reference=True
        )
        self.server = foxglove.start_server(
            name="tofpose",
            host="127.0.0.1",
            port=0,
            context=self.context,
            message_backlog_size=backlog_messages,
        )
        try:
            self.relay = FoxgloveRelay(
                host=host, port=port, upstream_url=f"ws://127.0.0.1:{self.server.port}"
            )
        except BaseException:
            self.server.stop()
            self.channels.close()
            raise
        self.host = host
        self.published = 0
        self._stop = threading.Event()
        self._sub = hub.subscribe(maxsize=1)
        self._thread = threading.Thread(target=self._run, name="tofpose-foxglove", daemon=True)
        self._thread.start()

    @property
    def port(self) -> int:
        return self.relay.port

    @property
    def subprotocols(self) -> tuple[str, ...]:
        """The WebSocket subprotocols a client may offer."""
        return SERVED_SUBPROTOCOLS

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"ws://{host}:{self.port}"

    @property
    def dropped(self) -> int:
        """Samples the hub dropped because this publisher was still busy with one."""
        return self._sub.dropped

    def close(self) -> None:
        self._stop.set()
        self._hub.unsubscribe(self._sub)
        self._thread.join(timeout=2.0)
        self.relay.close()
        self.server.stop()
        self.channels.close()

    def _run(self) -> None:
        while not self._stop.is_set():
            sample = self._sub.get(timeout_s=0.5)
            if sample is None or not self.channels.has_sinks():
                continue
            try:
                self.publish(sample)
            except Exception:  # noqa: BLE001 - a bad sample must not end the stream
                log.exception("Foxglove: frame %s not published", sample.frame.index)

    def publish(self, sample: LiveSample) -> None:
        """Log one live sample on every channel."""
        f = sample.frame
        exact = f.T_camera_target_exact
        lab = sample.reference.pose(f)
        self.channels.log_frame(
            f.index,
            f.gray,
            f.distance_mm,
            float(f.time_s),
            int(round(sample.captured_unix_s * 1e9)),
            sample.result if sample.measured else None,
            (exact.R, exact.t_mm) if exact is not None else None,
            (lab.R, lab.t_mm) if lab is not None else None,
        )
        self.published += 1
