"""An emulator of the ESPROS TOFcam-660 network protocol, backed by ``tofpose.sim``.

Wire format (as the vendor's ``epc.tofCam660`` client speaks it; docs/devices.md,
"Camera protocol"):

- Commands on TCP port 50660: ``0xFFFFAA55``, a big-endian uint32 payload length, the
  payload (uint16 command id, then parameters, zero-padded to 34 bytes), ``0xFFFF55AA``.
  Answers use the same framing; their payload is a response id byte (0 acknowledge,
  1 error + uint16 code, 2 firmware release, 3 chip information, 4 temperature,
  6 register value, 9 calibration data, 10 integration times, 11 data transfer protocol,
  255 not-acknowledge) and its data.
- Images over UDP to port 45454 of the data IP (the client's address unless set with
  command 38), sent from the camera's own address: packets of a 20-byte header
  (``!HIHIII``: measurement id, total size, payload size, offset, packet count, packet
  number) and up to ``UDP_PAYLOAD_BYTES`` of the frame. A frame is a 25-byte header
  (``!BHHHHHHHHHHhH``: version, data type, columns, rows, ROI left/top/right/bottom,
  three integration times, temperature x 100, data offset) and little-endian uint16
  pixels; distance + amplitude frames interleave the two per pixel.
- Distance codes: 64001 low amplitude, 64002 ADC overflow, 64003 saturation.

What it does not model: streaming capture (capture mode 1 is answered with an error),
DCS images, HDR, binning, filters and compensations (accepted and stored, no effect),
TCP image transfer, firmware update and the USB interface.
"""

from __future__ import annotations

import contextlib
import logging
import socket
import struct
import threading
import time
from dataclasses import dataclass, field

import numpy as np

from backend.drivers.sim import SimWorld
from backend.emulators.tcp import ServedEmulator, TrackedHandler, TrackedTCPServer
from tofpose.core.tof import unambiguous_range_mm

log = logging.getLogger(__name__)

COMMAND_PORT = 50660
DATA_PORT = 45454
MARKER_START = 0xFFFFAA55
MARKER_END = 0xFFFF55AA
UDP_PAYLOAD_BYTES = 1400
FRAME_HEADER = struct.Struct("!BHHHHHHHHHHhH")
PACKET_HEADER = struct.Struct("!HIHIII")
HEADER_VERSION = 4
FIRMWARE = (3, 59)
CHIP = (1234, 56)  # wafer id, chip id
MAX_PAYLOAD_BYTES = 4096
READ_TIMEOUT_S = 1.0  # a message must arrive whole within this

# Distance codes of the EPC660 firmware.
LOW_AMPLITUDE = 64001
ADC_OVERFLOW = 64002
SATURATION = 64003

# Response ids.
ACK, ERROR, FIRMWARE_RELEASE, CHIP_INFORMATION, TEMPERATURE = 0, 1, 2, 3, 4
READ_REGISTER, CALIBRATION_DATA, INTEGRATION_TIME, DATA_TRANSFER, NAK = 6, 9, 10, 11, 255

# Error codes sent with response 1 (the emulator's own numbering, see docs/devices.md).
ERR_BAD_PARAMETER = 1
ERR_NOT_SUPPORTED = 2

# Modulation frequency codes (command 23) and their MHz.
MODULATION_MHZ = {0: 12.0, 1: 24.0, 2: 6.0, 3: 3.0, 4: 1.5, 5: 0.75}
# Data types of image commands -> frame data type id.
IMAGE_COMMANDS = {2: 0, 3: 1, 5: 3}  # distance+amplitude, distance, grayscale
SENSOR_WIDTH, SENSOR_HEIGHT = 320, 240
FULL_SCALE_COUNTS = 4095


class ProtocolError(Exception):
    """The bytes on the wire are not a message (answered with NAK)."""


@dataclass
class CameraState:
    """What the camera's firmware holds between commands."""

    roi: tuple[int, int, int, int] = (0, 0, SENSOR_WIDTH, SENSOR_HEIGHT)
    int_times_us: tuple[int, int, int, int] = (500, 0, 0, 50)  # low, mid, high, grayscale
    modulation_code: int = 2
    channel: int = 0
    min_amplitude: int = 100
    hdr: int = 0
    binning: int = 0
    data_ip: str | None = None
    temperature_c: float = 42.0
    registers: dict[int, int] = field(default_factory=dict)
    measurement_id: int = 0


def encode_frame(
    data_type: int,
    distance_mm: np.ndarray,
    gray: np.ndarray,
    state: CameraState,
) -> bytes:
    """One frame in the camera's format.

    distance_mm : (H, W) float, NaN invalid; gray : (H, W) uint16 counts (full scale 4095:
    saturated). Both already cropped to the ROI.
    """
    rows, cols = gray.shape
    saturated = gray >= FULL_SCALE_COUNTS
    dist = np.where(np.isfinite(distance_mm), np.rint(distance_mm), LOW_AMPLITUDE)
    dist = np.clip(dist, 0, 63999).astype(np.uint16)
    dist[~np.isfinite(distance_mm)] = LOW_AMPLITUDE
    dist[saturated & ~np.isfinite(distance_mm)] = SATURATION
    amp = gray.astype(np.uint16)
    amp[saturated] = SATURATION
    if data_type == 0:
        pixels = np.empty((rows, cols, 2), "<u2")
        pixels[..., 0], pixels[..., 1] = dist, amp
    elif data_type == 1:
        pixels = dist.astype("<u2")
    else:
        pixels = np.minimum(gray, FULL_SCALE_COUNTS).astype("<u2")
    left, top, right, bottom = state.roi
    low, mid, high, _ = state.int_times_us
    header = FRAME_HEADER.pack(
        HEADER_VERSION,
        data_type,
        cols,
        rows,
        left,
        top,
        right,
        bottom,
        low,
        mid,
        high,
        int(round(state.temperature_c * 100)),
        FRAME_HEADER.size,
    )
    return header + pixels.tobytes()


def packetise(frame: bytes, measurement_id: int) -> list[bytes]:
    """The UDP datagrams of one frame (header ``!HIHIII`` + payload)."""
    n = max(1, -(-len(frame) // UDP_PAYLOAD_BYTES))
    out = []
    for i in range(n):
        chunk = frame[i * UDP_PAYLOAD_BYTES : (i + 1) * UDP_PAYLOAD_BYTES]
        out.append(
            PACKET_HEADER.pack(
                measurement_id & 0xFFFF, len(frame), len(chunk), i * UDP_PAYLOAD_BYTES, n, i
            )
            + chunk
        )
    return out


def frame_message(payload: bytes) -> bytes:
    """A TCP message: start marker, length, payload, end marker."""
    return struct.pack("!II", MARKER_START, len(payload)) + payload + struct.pack("!I", MARKER_END)


class TofCam660Camera:
    """The camera's firmware logic (no sockets): ``handle(payload, peer_ip)`` returns the
    response payload and, for image commands, the frame to send over UDP."""

    def __init__(self, world: SimWorld) -> None:
        self.world = world
        self.state = CameraState()
        self._lock = threading.Lock()
        self.frames_sent = 0
        #: (lab time the last image command arrived, lab time its frame shows)
        self.last_capture_lab_s: tuple[float, float] | None = None
        self._apply_sensor()

    def _apply_sensor(self) -> None:
        s = self.state
        self.world.set_sensor(
            modulation_frequency_hz=MODULATION_MHZ[s.modulation_code] * 1e6,
            integration_time_us=float(max(s.int_times_us[0], 1)),
            auto_exposure=False,
            min_amplitude_counts=float(s.min_amplitude),
        )

    def handle(self, payload: bytes) -> tuple[bytes, bytes | None]:
        if len(payload) < 2:
            return bytes([NAK]), None
        (cmd,) = struct.unpack("!H", payload[:2])
        data = payload[2:]
        with self._lock:
            try:
                return self._command(cmd, data)
            except (struct.error, ValueError, IndexError) as exc:
                log.info("tofcam660 emulator: command %d refused: %s", cmd, exc)
                return bytes([ERROR]) + struct.pack("!H", ERR_BAD_PARAMETER), None

    def _command(self, cmd: int, data: bytes) -> tuple[bytes, bytes | None]:
        s = self.state
        ack = bytes([ACK])
        if cmd in IMAGE_COMMANDS:
            if data[0] != 0:
                return bytes([ERROR]) + struct.pack("!H", ERR_NOT_SUPPORTED), None
            return ack, self._capture(IMAGE_COMMANDS[cmd])
        if cmd == 0:  # setRoi
            left, top, right, bottom = struct.unpack("!HHHH", data[:8])
            if not (0 <= left < right <= SENSOR_WIDTH and 0 <= top < bottom <= SENSOR_HEIGHT):
                raise ValueError(f"ROI {left, top, right, bottom} outside the sensor")
            if top != SENSOR_HEIGHT - bottom:
                raise ValueError("ROI rows must be symmetric about the sensor centre")
            s.roi = (left, top, right, bottom)
            return ack, None
        if cmd == 1:  # setIntTimes
            low, mid, high, gray = struct.unpack("!HHHH", data[:8])
            if not 1 <= low <= 4000:
                raise ValueError(f"integration time {low} us outside 1..4000")
            s.int_times_us = (low, mid, high, gray)
            self._apply_sensor()
            return ack, None
        if cmd == 23:  # setModulationFrequency
            code, channel = data[0], data[1]
            if code not in MODULATION_MHZ or channel > 15:
                raise ValueError(f"modulation code {code} / channel {channel}")
            s.modulation_code, s.channel = code, channel
            self._apply_sensor()
            return ack, None
        if cmd == 21:  # setMinAmplitude
            (s.min_amplitude,) = struct.unpack("!H", data[:2])
            self._apply_sensor()
            return ack, None
        if cmd == 25:  # setHdr
            if data[0] not in (0, 1, 2):
                raise ValueError(f"HDR mode {data[0]}")
            s.hdr = data[0]
            return ack, None
        if cmd == 24:  # setBinning
            s.binning = data[0]
            return ack, None
        if cmd == 42:  # writeRegister
            s.registers[data[0]] = data[1]
            return ack, None
        if cmd == 43:  # readRegister
            return bytes([READ_REGISTER, s.registers.get(data[0], 0)]), None
        if cmd == 37:  # readFirmwareRelease
            return bytes([FIRMWARE_RELEASE]) + struct.pack("!HH", *FIRMWARE), None
        if cmd == 36:  # readChipInformation
            return bytes([CHIP_INFORMATION]) + struct.pack("!HH", *CHIP), None
        if cmd == 74:  # getTemperature
            return bytes([TEMPERATURE]) + struct.pack("!h", round(s.temperature_c * 100)), None
        if cmd == 56:  # getIntegrationTime
            low, mid, high, gray = s.int_times_us
            return bytes([INTEGRATION_TIME]) + struct.pack("!HHHH", low, mid, high, gray), None
        if cmd == 53:  # getCalibrationData: (modulation index, temperature mdeg, atan offset)
            entries = b"".join(struct.pack("!BHH", i, 42000, 6250) for i in MODULATION_MHZ)
            return bytes([CALIBRATION_DATA]) + entries, None
        if cmd == 58:  # getDataTransferProtocol
            return bytes([DATA_TRANSFER, 0]), None
        if cmd == 57:  # setDataTransferProtocol: UDP only
            if data[0] != 0:
                return bytes([ERROR]) + struct.pack("!H", ERR_NOT_SUPPORTED), None
            return ack, None
        if cmd == 38:  # setDataIpAddress
            s.data_ip = ".".join(str(b) for b in data[:4])
            return ack, None
        if cmd in (6, 22, 28, 29, 39, 51, 54, 60, 61):
            # stopStream, filters, compensations, DLL step, grayscale illumination,
            # illuminator segments, modulation jitter, rolling mode, eye safety: stored
            # nowhere, no effect on the simulated sensor
            return ack, None
        return bytes([NAK]), None

    def _capture(self, data_type: int) -> bytes:
        # the camera's four phase sub-frames start now; the frame is the scene at their
        # exposures' middle, two integration times and 1.5 read-outs on, the instant the
        # driver stamps (``backend.drivers.tofcam660``): rendered at the command's
        # receipt, the pose was that much older than its stamp (~3-10 ms)
        ahead_s = self.acquisition_middle_s()
        received = self.world.now_s()
        rendered, frame, *_ = self.world.capture(ahead_s)
        self.last_capture_lab_s = (received, rendered)
        left, top, right, bottom = self.state.roi
        crop = np.s_[top:bottom, left:right]
        self.state.measurement_id += 1
        self.frames_sent += 1
        return encode_frame(data_type, frame.distance_mm[crop], frame.gray[crop], self.state)

    def acquisition_middle_s(self) -> float:
        """Seconds from the acquisition command to the middle of its four sub-frames'
        exposures: 2 integration times + 1.5 read-outs (the simulated sensor's)."""
        int_s = max(self.state.int_times_us[0], 1) * 1e-6
        return 2.0 * int_s + 1.5 * self.world.bench.sensor.subframe_readout_us * 1e-6

    @property
    def unambiguous_range_mm(self) -> float:
        return unambiguous_range_mm(MODULATION_MHZ[self.state.modulation_code])


class _Handler(TrackedHandler):
    server: _Server

    def setup(self) -> None:
        super().setup()
        self.request.settimeout(None)

    def _recv_exact(self, n: int, first: bool) -> bytes:
        buf = bytearray()
        while len(buf) < n:
            # Wait for a message's first byte as long as it takes; once a message has
            # begun, the rest must follow within READ_TIMEOUT_S (else it is truncated).
            self.request.settimeout(None if first and not buf else READ_TIMEOUT_S)
            try:
                part = self.request.recv(n - len(buf))
            except TimeoutError:
                raise ProtocolError(f"truncated message: {len(buf)} of {n} bytes") from None
            if not part:
                raise EOFError
            buf += part
        return bytes(buf)

    def _read_message(self) -> bytes:
        start, length = struct.unpack("!II", self._recv_exact(8, first=True))
        if start != MARKER_START:
            raise ProtocolError(f"start marker 0x{start:08x}")
        if length > MAX_PAYLOAD_BYTES:
            raise ProtocolError(f"payload length {length}")
        payload = self._recv_exact(length, first=False)
        (end,) = struct.unpack("!I", self._recv_exact(4, first=False))
        if end != MARKER_END:
            raise ProtocolError(f"end marker 0x{end:08x}")
        return payload

    def handle(self) -> None:
        camera = self.server.camera
        peer_ip = self.client_address[0]
        while True:
            try:
                payload = self._read_message()
            except (EOFError, OSError):
                return
            except ProtocolError as exc:
                log.info("tofcam660 emulator: %s from %s: NAK, input flushed", exc, peer_ip)
                self._flush()
                if not self._send(bytes([NAK])):
                    return
                continue
            response, frame = camera.handle(payload)
            if not self._send(response):
                return
            if frame is not None:
                self.server.send_frame(
                    frame, camera.state.data_ip or peer_ip, camera.state.measurement_id
                )

    def _flush(self) -> None:
        """Drop what is already buffered: framing is lost, start afresh."""
        self.request.settimeout(0.05)
        with contextlib.suppress(OSError):
            while self.request.recv(65536):
                pass

    def _send(self, payload: bytes) -> bool:
        try:
            self.request.sendall(frame_message(payload))
        except OSError:
            return False
        return True


class _Server(TrackedTCPServer):
    def __init__(self, address: tuple[str, int], camera: TofCam660Camera, data_port: int):
        self.camera = camera
        self.data_port = data_port
        self.udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.udp.bind((address[0], 0))  # images come from the camera's own address
        self.udp.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 1 << 20)
        self.lose_images = False  # fault injection: answer image commands, send no image
        super().__init__(address, _Handler)

    def send_frame(self, frame: bytes, ip: str, measurement_id: int) -> None:
        if self.lose_images:
            return
        for packet in packetise(frame, measurement_id):
            try:
                self.udp.sendto(packet, (ip, self.data_port))
            except BlockingIOError:  # send buffer full: let the kernel drain it
                time.sleep(0.001)
                self.udp.sendto(packet, (ip, self.data_port))

    def server_close(self) -> None:
        super().server_close()
        self.udp.close()


class TofCam660Emulator(ServedEmulator):
    """The camera on ``address`` (a loopback address of its own, e.g. 127.0.0.2, since the
    ports are fixed): ``start()`` serves in a thread; ``close()`` also drops clients."""

    thread_name = "tofcam660-emulator"
    _server: _Server

    def __init__(
        self,
        world: SimWorld,
        address: str = "127.0.0.2",
        *,
        command_port: int = COMMAND_PORT,
        data_port: int = DATA_PORT,
    ) -> None:
        self.camera = TofCam660Camera(world)
        self._server = _Server((address, command_port), self.camera, data_port)

    def lose_images(self, lose: bool = True) -> None:
        """Fault injection: acknowledge image commands but send no image (UDP loss)."""
        self._server.lose_images = lose
