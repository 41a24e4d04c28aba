"""Camera driver for the ESPROS TOFcam-660 (EPC660 chip, the paper's sensor) through the
vendor's client ``epc.tofCam660`` (PyPI ``epc-tofcam-toolkit``; install
``tofpose[espros]``).

The vendor client connects (TCP commands on port 50660, images over UDP to port 45454)
and speaks the protocol; this driver adds what a server needs around it:

- settings: modulation frequency (the supported one nearest to the request), ROI (given
  at connect time; the camera model's principal point follows it), integration time
  clamped to the camera's range, and an auto-exposure loop of its own (the camera has
  none): after each frame the integration time is scaled so that the brightest pixel
  sits at ``auto_exposure_fill`` of the amplitude full scale, halved on saturation;
- frames: one distance + amplitude acquisition per ``read`` (the two images are of the
  same exposure, so they agree pixel for pixel); the amplitude is the gray image; the
  camera's invalid-pixel codes (>= 64000: low amplitude, ADC overflow, saturation)
  become NaN distances, and saturated or overflowing amplitudes become the frame's full
  scale (so a saturated reflector core stays the brightest part of its blob);
- stamps (docs/server.md, "Latency and dropped frames"): the camera stamps no time in
  its frames, so a frame's ``capture_ns`` is the host's monotonic clock when the
  acquisition command went out (the exposure follows it by the command's way over the
  link and lasts the integration time); its ``sequence`` is the measurement id of the
  image's UDP packets (a 16-bit counter the camera advances per acquisition),
  unwrapped, so an image the camera took and the network lost shows as a gap; its
  ``time_s`` (the instant its pose is of) is that clock at the middle of the
  acquisition's four phase sub-frames (``capture_ns`` + 2 integration times + 1.5
  ``SUBFRAME_READOUT_S``, the simulator's read-out, since the vendor documents none; the
  command's way over the link is not in it), not the arrival, which is later by the
  camera's processing and the transfer. The emulator renders at the command's
  receipt, so on it the stamp is that much after the rendered pose;
- time-outs of its own (the vendor client retries for up to half a minute) and
  reconnection: a command-link error drops the link, ``read`` raises ``CameraError`` and
  the next ``read`` reconnects after a back-off, while the server shows the camera
  degraded.
"""

from __future__ import annotations

import contextlib
import logging
import math
import socket
import struct
import threading
import time
from dataclasses import replace
from typing import Any

import numpy as np

from backend.drivers.base import CameraError, CameraFrame, CameraLimits, CameraSettings
from backend.drivers.pacing import FramePacer
from tofpose.core.camera import CameraModel

log = logging.getLogger(__name__)

MODULATION_MHZ = (24.0, 12.0, 6.0, 3.0, 1.5, 0.75)
INTEGRATION_LIMITS_US = (1.0, 4000.0)
INVALID_CODE_MIN = 64000
SATURATION_CODES = (64002, 64003)  # ADC overflow, saturation
SENSOR_SIZE = (320, 240)
#: read-out after each of the four phase exposures, s: the simulator's model
#: (``SensorModel.subframe_readout_us``); the vendor documents none
SUBFRAME_READOUT_S = 1.5e-3
COMMAND_PORT = 50660


def _vendor() -> Any:
    root = logging.getLogger()
    handlers, level = list(root.handlers), root.level
    try:
        from epc.tofCam660 import Command, TOFcam660
        from epc.tofCam660.parser import DistanceAndAmplitudeParser
        from epc.tofCam660.tofCam660 import DEFAULT_MAX_AMP
    except ImportError as exc:  # pragma: no cover - the extra is part of dev installs
        raise CameraError(
            "the tofcam660 driver needs ESPROS's client: pip install 'tofpose[espros]'"
        ) from exc
    # Importing ``epc`` configures the root logger (a coloured handler at INFO): undo
    # that, the server configures its own logging; keep the client's chatter to warnings.
    root.handlers[:] = handlers
    root.setLevel(level)
    logging.getLogger("TOFcam660").setLevel(logging.WARNING)
    return TOFcam660, Command, DistanceAndAmplitudeParser, DEFAULT_MAX_AMP


def decode_distance_amplitude(
    distance: np.ndarray, amplitude: np.ndarray, full_scale_counts: float
) -> tuple[np.ndarray, np.ndarray, int]:
    """Camera codes to the pipeline's images.

    distance, amplitude : (H, W) uint16 as the camera sends them.
    Returns gray (H, W) uint16, distance_mm (H, W) float32 with NaN for every coded pixel,
    and the number of saturated pixels.
    """
    dist = distance.astype(np.float32)
    dist[distance >= INVALID_CODE_MIN] = np.nan
    saturated = np.isin(amplitude, SATURATION_CODES)
    valid_amp = amplitude[amplitude < INVALID_CODE_MIN]
    top = max(float(full_scale_counts), float(valid_amp.max()) if valid_amp.size else 0.0)
    gray = np.where(amplitude >= INVALID_CODE_MIN, 0, amplitude).astype(np.uint16)
    gray[saturated] = min(int(top), 65535)
    return gray, dist, int(saturated.sum())


def next_integration_time_us(
    current_us: float,
    peak_counts: float,
    n_saturated: int,
    full_scale_counts: float,
    fill: float = 0.6,
    limits_us: tuple[float, float] = INTEGRATION_LIMITS_US,
) -> float:
    """The auto-exposure step: scale the integration time so that the brightest pixel
    reaches ``fill`` of full scale (at most x2 / x0.5 a step); halve it on saturation.
    Within 15 % of the goal the time is kept (no hunting)."""
    if n_saturated > 0:
        proposed = current_us * 0.5
    elif peak_counts <= 0:
        proposed = current_us * 2.0
    else:
        ratio = fill * full_scale_counts / peak_counts
        if abs(math.log(ratio)) < math.log(1.15):
            return current_us
        proposed = current_us * min(max(ratio, 0.5), 2.0)
    return float(min(max(proposed, limits_us[0]), limits_us[1]))


class TofCam660Driver:
    """An ESPROS TOFcam-660 on the network (implements ``CameraDriver``).

    address : the camera's IP address (the emulator's: a loopback address such as
        127.0.0.2). model : intrinsics of the full sensor (default: the paper's EPC660
        lens); with a ``roi`` the driver's ``model`` is the ROI's. io_timeout_s : per
        command and per image. reconnect_backoff_s : (first, max) wait between
        reconnection attempts.
    """

    name = "tofcam660"

    def __init__(
        self,
        address: str,
        *,
        model: CameraModel | None = None,
        settings: CameraSettings | None = None,
        roi: tuple[int, int, int, int] | None = None,
        min_amplitude: int = 10,
        auto_exposure_fill: float = 0.6,
        io_timeout_s: float = 1.0,
        reconnect_backoff_s: tuple[float, float] = (0.2, 5.0),
        connect_now: bool = True,
    ) -> None:
        self.address = address
        self.roi = roi or (0, 0, *SENSOR_SIZE)
        left, top, right, bottom = self.roi
        full = model or CameraModel()
        self.model = replace(
            full, width=right - left, height=bottom - top, cx=full.cx - left, cy=full.cy - top
        )
        self.min_amplitude = min_amplitude
        self.auto_exposure_fill = auto_exposure_fill
        self.io_timeout_s = io_timeout_s
        self.backoff_s = reconnect_backoff_s
        self._vendor = _vendor()
        self.full_scale_counts = float(self._vendor[3])
        self._settings = settings or CameraSettings()
        self._pacer = FramePacer(self._settings.frame_rate_hz)
        self._cam: Any = None
        self._lock = threading.Lock()
        self._next_attempt = 0.0
        self._backoff = reconnect_backoff_s[0]
        self._index = 0
        self._sequence = MeasurementIdUnwrap()
        self._integration_us = self._settings.integration_time_us
        self.firmware = ""
        self.serial = ""
        self.link_changes = 0
        if connect_now:
            self._connect()  # a camera that is not there is an error here
        else:  # the server: start degraded, connect on the first read
            self._next_attempt = 0.0

    # -- link ---------------------------------------------------------------------------
    def _connect(self) -> None:
        TOFcam660 = self._vendor[0]
        try:
            # Our own time-out first: the vendor's connect has none (minutes on a network
            # where the address does not answer), and a failed vendor constructor leaves
            # a half-built object behind.
            socket.create_connection((self.address, COMMAND_PORT), self.io_timeout_s).close()
            cam = TOFcam660(self.address)
        except Exception as exc:
            raise CameraError(f"tofcam660 {self.address}: cannot connect: {exc}") from exc
        try:
            cam.tcpInterface.socket.settimeout(self.io_timeout_s)
            cam.rxInterface.udpSocket.settimeout(self.io_timeout_s)
            cam.rxInterface.udpSocket = MeasurementIdTap(cam.rxInterface.udpSocket, self.address)
            self._sequence = MeasurementIdUnwrap()  # counted afresh on a new link
            self.firmware = cam._version
            self._cam = cam
            chip = self._transceive(self._vendor[1].create("readChipInformation")).data
            self.serial = f"wafer {chip['waferid']} chip {chip['chipid']}"
            self._push_settings(self._settings)
        except Exception as exc:
            self._cam = None
            self._close_cam(cam)
            raise CameraError(f"tofcam660 {self.address}: setup failed: {exc}") from exc
        self._backoff = self.backoff_s[0]
        self.link_changes += 1
        log.info("tofcam660 %s connected (firmware %s)", self.address, self.firmware)

    @staticmethod
    def _close_cam(cam: Any) -> None:
        for closer in (cam.tcpInterface.close, cam.rxInterface.close):
            with contextlib.suppress(Exception):  # a dead link may fail to close
                closer()

    def _drop(self, why: str) -> None:
        if self._cam is not None:
            self._close_cam(self._cam)
            self._cam = None
            self.link_changes += 1
            log.warning("tofcam660 %s: link dropped: %s", self.address, why)
        self._next_attempt = time.monotonic() + self._backoff
        self._backoff = min(self._backoff * 2, self.backoff_s[1])

    def _ensure(self) -> Any:
        if self._cam is None:
            wait = self._next_attempt - time.monotonic()
            if wait > 0:
                raise CameraError(
                    f"tofcam660 {self.address}: link down, reconnecting in {wait:.1f} s"
                )
            try:
                self._connect()
            except CameraError:
                self._drop("reconnect failed")
                raise
        return self._cam

    def _transceive(self, command: Any) -> Any:
        """One command and its answer, once (no vendor retries), under the vendor lock."""
        iface = self._cam.tcpInterface
        with iface.lock:
            iface.transmit(command)
            response = iface.receive()
        if response.isError():
            raise CameraError(f"tofcam660 {self.address}: the camera refused {command}: {response}")
        return response

    # -- settings -----------------------------------------------------------------------
    def _push_settings(self, s: CameraSettings) -> None:
        Command = self._vendor[1]
        left, top, right, bottom = self.roi
        mhz = min(MODULATION_MHZ, key=lambda f: abs(f - s.modulation_frequency_mhz))
        code = {12.0: 0, 24.0: 1, 6.0: 2, 3.0: 3, 1.5: 4, 0.75: 5}[mhz]
        self._transceive(
            Command.create("setModulationFrequency", {"frequencyCode": code, "channel": 0})
        )
        roi = {"leftColumn": left, "topRow": top, "rightColumn": right, "bottomRow": bottom}
        self._transceive(Command.create("setRoi", roi))
        self._transceive(Command.create("setHdr", 0))
        self._transceive(Command.create("setMinAmplitude", self.min_amplitude))
        self._set_integration(self._integration_us)

    def _set_integration(self, t_us: float) -> None:
        Command = self._vendor[1]
        lo, hi = INTEGRATION_LIMITS_US
        t = int(round(min(max(t_us, lo), hi)))
        self._transceive(
            Command.create(
                "setIntTimes",
                {"lowIntTime": t, "midIntTime": 0, "highIntTime": 0, "grayscaleIntTime": 50},
            )
        )
        self._integration_us = float(t)

    def get_settings(self) -> CameraSettings:
        return replace(self._settings, integration_time_us=self._integration_us)

    def limits(self) -> CameraLimits:
        """The EPC660's integration range and its six modulation frequencies."""
        return CameraLimits(
            integration_time_us=INTEGRATION_LIMITS_US, modulation_frequencies_mhz=MODULATION_MHZ
        )

    def apply_settings(self, settings: CameraSettings) -> CameraSettings:
        mhz = min(MODULATION_MHZ, key=lambda f: abs(f - settings.modulation_frequency_mhz))
        lo, hi = INTEGRATION_LIMITS_US
        applied = replace(
            settings,
            modulation_frequency_mhz=mhz,
            integration_time_us=float(round(min(max(settings.integration_time_us, lo), hi))),
        )
        with self._lock:
            self._settings = applied
            # the model the live pipeline measures with: its distances wrap at c / (2 f)
            # (a new model only for a new frequency: the live loop rebuilds its pipeline)
            if mhz * 1e6 != self.model.modulation_frequency_hz:
                self.model = replace(self.model, modulation_frequency_hz=mhz * 1e6)
            if not applied.auto_exposure or self._integration_us <= 0:
                self._integration_us = applied.integration_time_us
            if self._cam is not None:
                try:
                    self._push_settings(applied)
                except (OSError, EOFError, ValueError, CameraError) as exc:
                    self._drop(str(exc))
                    raise CameraError(f"tofcam660 {self.address}: settings: {exc}") from exc
        self._pacer.set_rate(applied.frame_rate_hz)
        return self.get_settings()

    # -- frames -------------------------------------------------------------------------
    def read(self, timeout_s: float) -> CameraFrame:
        """One distance + amplitude image; ``CameraError`` when the command link fails
        (the link is dropped and re-opened later) or the image does not arrive within
        ``io_timeout_s`` (a lost UDP image fails only this frame)."""
        skipped = self._pacer.wait(timeout_s)
        with self._lock:
            cam = self._ensure()
            _, Command, Parser, _ = self._vendor
            tap: MeasurementIdTap = cam.rxInterface.udpSocket
            try:
                _flush_datagrams(tap)  # no stale packets of a lost frame
                tap.last_id = None
                capture_ns = time.monotonic_ns()
                self._transceive(Command.create("getDistanceAndAmplitude", 0))
            except (OSError, EOFError, ValueError, RuntimeError) as exc:
                self._drop(str(exc) or type(exc).__name__)
                raise CameraError(f"tofcam660 {self.address}: command link: {exc}") from exc
            try:
                raw, _ = cam.rxInterface.receiveFrame()
                frame = Parser().parse(raw)
            except (OSError, TimeoutError, ValueError) as exc:
                # The command link answered; the image was lost on its way (UDP).
                raise CameraError(f"tofcam660 {self.address}: image lost: {exc}") from exc
            gray, dist, n_sat = decode_distance_amplitude(
                frame.distance, frame.amplitude, self.full_scale_counts
            )
            used_us = float(frame.lowIntTime)
            if self._settings.auto_exposure:
                self._auto_expose(gray, dist, n_sat)
            self._index += 1
            return CameraFrame(
                gray=gray,
                distance_mm=dist,
                # the pose's instant: the middle of the four phase sub-frames after the
                # command went out (two exposures and one and a half read-outs)
                time_s=capture_ns * 1e-9 + 2.0 * used_us * 1e-6 + 1.5 * SUBFRAME_READOUT_S,
                index=self._index,
                meta={
                    "integration_time_us": used_us,
                    "temperature_c": float(frame.temperature),
                    "saturated_px": n_sat,
                },
                capture_ns=capture_ns,
                sequence=self._sequence.unwrap(tap.last_id),
                slots_skipped=skipped,
            )

    def _auto_expose(self, gray: np.ndarray, dist: np.ndarray, n_saturated: int) -> None:
        peak = float(gray[np.isfinite(dist)].max()) if np.isfinite(dist).any() else 0.0
        t = next_integration_time_us(
            self._integration_us, peak, n_saturated, self.full_scale_counts, self.auto_exposure_fill
        )
        if t != self._integration_us:
            try:
                self._set_integration(t)
            except (OSError, EOFError, ValueError, CameraError) as exc:
                self._drop(str(exc))

    # -- status -------------------------------------------------------------------------
    def describe(self) -> dict[str, str]:
        """Model, firmware and link state for GET /api/devices."""
        return {
            "model": "ESPROS TOFcam-660",
            "firmware": self.firmware,
            "serial": self.serial,
            "link": "up" if self._cam is not None else "down",
            "address": self.address,
        }

    def close(self) -> None:
        self._pacer.close()
        with self._lock:
            if self._cam is not None:
                self._close_cam(self._cam)
                self._cam = None


class MeasurementIdTap:
    """The vendor client's UDP socket, keeping the measurement id (the first uint16 of a
    packet's ``!HIHIII`` header) of the last packet from the camera's ``address``: the
    vendor's ``receiveFrame`` reads it and drops it. Everything else is the socket's."""

    def __init__(self, sock: socket.socket, address: str) -> None:
        self._sock = sock
        self._address = address
        self.last_id: int | None = None

    def recvfrom(self, bufsize: int) -> tuple[bytes, Any]:
        data, peer = self._sock.recvfrom(bufsize)
        if peer[0] == self._address and len(data) >= 2:
            (self.last_id,) = struct.unpack_from("!H", data)
        return data, peer

    def __getattr__(self, name: str) -> Any:
        return getattr(self._sock, name)


class MeasurementIdUnwrap:
    """The camera's 16-bit measurement ids as a running count: each id adds its
    distance from the previous one modulo 2**16 (None: the frame brought no id)."""

    def __init__(self) -> None:
        self._last: int | None = None
        self._count = 0

    def unwrap(self, measurement_id: int | None) -> int | None:
        if measurement_id is None:
            return None
        if self._last is not None:
            self._count += (measurement_id - self._last) & 0xFFFF
        self._last = measurement_id
        return self._count


def _flush_datagrams(sock) -> None:
    """Discard every datagram waiting on ``sock`` and keep its time-out. (The vendor's
    ``clearInputBuffer`` restores blocking mode with ``setblocking(True)``, which clears
    the time-out: a lost image would then block the read, and the server's shutdown,
    for ever.)"""
    timeout = sock.gettimeout()
    sock.setblocking(False)
    try:
        while True:
            try:
                sock.recvfrom(65536)
            except (BlockingIOError, InterruptedError):
                break
    finally:
        sock.settimeout(timeout)
